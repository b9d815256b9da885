//! The image's envelope policy section (issue 50 item 3) from a fit file's
//! evidence ([`crate::fit::envelope`] computes it at fit time).

use thermocomp_core::float::FloatModel;
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy};
use thermocomp_core::limits::MAX_DIRECTIONS;

use crate::fit::envelope::DEFAULT_MARGIN_RAW;
use crate::fit::model::ModelFile;

/// The image's policy per direction from a fit file's evidence, and a line
/// per direction saying which and why; `None` (no section: every direction
/// holds, margin 0, as before) when the fit file carries no evidence.
pub fn policies(
    file: &ModelFile,
    float: &FloatModel,
) -> (Option<[EnvelopePolicy; MAX_DIRECTIONS]>, Vec<String>) {
    if file.envelope.is_empty() {
        return (
            None,
            vec!["envelope: the fit file has no envelope evidence (fitted before issue 50): every direction holds its inputs at the edge, no policy section".into()],
        );
    }
    let mut out = [EnvelopePolicy::default(); MAX_DIRECTIONS];
    let mut lines = Vec::new();
    for (p, d) in out.iter_mut().zip(&float.directions) {
        let ch = format!("d{}_um", d.name);
        match file.envelope.get(&ch) {
            Some(ev) => {
                *p = EnvelopePolicy {
                    mode: mode(&ev.policy),
                    margin: ev.margin_raw,
                };
                lines.push(format!("envelope {ch}: {}", ev.why()));
            }
            None => {
                *p = EnvelopePolicy {
                    mode: EnvelopeMode::Hold,
                    margin: DEFAULT_MARGIN_RAW,
                };
                lines.push(format!(
                    "envelope {ch}: hold (no evidence for this channel)"
                ));
            }
        }
    }
    (Some(out), lines)
}

/// The fit file's policy name → the image's mode: "extrapolate" and
/// "fallback" as named, anything else hold (the rule of images without a
/// policy).
pub fn mode(policy: &str) -> EnvelopeMode {
    match policy {
        "extrapolate" => EnvelopeMode::Extrapolate,
        "fallback" => EnvelopeMode::Fallback,
        _ => EnvelopeMode::Hold,
    }
}

//! The image's envelope policy section (issue 50 item 3) from a fit file's
//! evidence ([`crate::fit::envelope`] computes it at fit time).

use thermocomp_core::float::{FloatModel, FloatTerm};
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy};
use thermocomp_core::limits::MAX_DIRECTIONS;

use crate::fit::envelope::DEFAULT_MARGIN_RAW;
use crate::fit::model::ModelFile;

/// The image's policy per direction from a fit file's evidence, and a line
/// per direction saying which and why; `None` (no section: every direction
/// holds, margin 0, as before) when the fit file carries no evidence.
/// Whether an `extrapolate` direction is linear enough for it is judged by
/// [`super::build_image`] on the fallbacks the image keeps (it holds one
/// that is not, and says so).
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

/// Whether every model that can serve `direction` is linear in its inputs,
/// as the image parser requires of a direction under `extrapolate`: no
/// network, no table bound to an axis, every term of its tables and
/// fallbacks of input power ≤ 1 and position power 0.
pub fn linear(float: &FloatModel, direction: u8) -> bool {
    let terms_linear = |t: &[FloatTerm]| {
        t.iter()
            .all(|t| t.input_power <= 1 && t.position_power == 0)
    };
    !float.nets.iter().any(|n| n.direction == direction)
        && float
            .tables
            .iter()
            .filter(|t| t.direction == direction)
            .all(|t| t.axis.is_none() && terms_linear(&t.terms))
        && float
            .fallbacks
            .iter()
            .filter(|f| f.direction == direction)
            .all(|f| terms_linear(&f.terms))
}

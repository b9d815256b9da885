//! The one place a float model and its sections become the board's image
//! (review of issues 50/51): quantize through the core, set the optional
//! sections, leave fallbacks out from the last until the image fits, judge
//! each `extrapolate` direction's linearity on what remains, refuse what
//! the board cannot hold, encode and parse back. `export` writes (and
//! signs) what this builds; `bench-extrapolation` replays it.

use anyhow::Result;
use thermocomp_core::float::{FloatModel, QuantReport};
use thermocomp_core::image::EnvelopeMode;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;

use super::envelope_policy::linear;

/// A volumetric section to add to the image, with its quantisation report.
pub type GeometrySection = (
    thermocomp_core::volumetric::Volumetric,
    tcomp_geometry::board::QuantisationReport,
);

/// A five-axis section (image section kind 4) with its report.
pub type FiveAxisSection = (
    thermocomp_core::five_axis::FiveAxis,
    tcomp_geometry::rotary_board::FiveAxisReport,
);

/// Per direction, the image's envelope policy (section kind 5, format v3).
pub type EnvelopeSection =
    [thermocomp_core::image::EnvelopePolicy; thermocomp_core::limits::MAX_DIRECTIONS];

/// Per direction, the output low-pass's decay per model step in Q30
/// (section kind 6, format v5; 0: none).
pub type OutputFilterSection = [u32; thermocomp_core::limits::MAX_DIRECTIONS];

/// The optional sections of an image, as the caller asks for them. An
/// `extrapolate` direction of `envelope` whose models in the image are not
/// all linear is served as hold ([`build_image`] says so in its notes).
#[derive(Clone, Default)]
pub struct Sections {
    /// The volumetric section (kind 3), required when given.
    pub geometry: Option<GeometrySection>,
    /// The five-axis section (kind 4); needs `geometry`.
    pub five: Option<FiveAxisSection>,
    /// The envelope policy per direction (kind 5).
    pub envelope: Option<EnvelopeSection>,
    /// The output low-pass decay per direction (kind 6).
    pub output: Option<OutputFilterSection>,
}

/// What [`build_image`] built: the board's model (CRC set), its encoded
/// bytes (parsed back), the quantisation report of the model it holds, how
/// many fallbacks were left out to fit, and one note per thing left out or
/// changed (for stderr).
#[derive(Clone, Debug)]
pub struct Built {
    pub model: Model,
    pub bytes: Vec<u8>,
    pub report: QuantReport,
    pub fallbacks_left_out: usize,
    pub notes: Vec<String>,
}

/// Quantize `model`, set `sections`, drop fallbacks (lowest priority, the
/// last, first) until the image fits MAX_IMAGE_BYTES, demote to hold each
/// `extrapolate` direction not linear in the fallbacks that remain, and
/// encode. Refuses a five-axis section without the volumetric one, a model
/// the quantizer refuses, an image still over MAX_IMAGE_BYTES (naming the
/// volumetric section when there is one) and an image that does not parse.
pub fn build_image(model: &FloatModel, sections: &Sections) -> Result<Built> {
    let Sections {
        geometry,
        five,
        envelope,
        output,
    } = sections;
    if five.is_some() && geometry.is_none() {
        anyhow::bail!("a five-axis section needs the volumetric section (--geometry)");
    }
    // The envelope section's size does not depend on the modes: the trim
    // below is the same whichever direction ends up held.
    let quantize = |m: &FloatModel| -> Result<(Model, QuantReport)> {
        let (mut fixed, report) = m.quantize().map_err(|e| anyhow::anyhow!("{e}"))?;
        fixed.volumetric = geometry.as_ref().map(|(v, _)| v.clone());
        fixed.five_axis = five.as_ref().map(|(f, _)| f.clone());
        fixed.envelope = *envelope;
        fixed.output_decay_q30 = *output;
        Ok((fixed, report))
    };
    let (mut fixed, mut report) = quantize(model)?;
    // Fallbacks are optional: drop the last (lowest priority) until the image fits.
    let mut trimmed = model.clone();
    while fixed.encoded_len() > MAX_IMAGE_BYTES && trimmed.fallbacks.pop().is_some() {
        (fixed, report) = quantize(&trimmed)?;
    }
    let fallbacks_left_out = model.fallbacks.len() - trimmed.fallbacks.len();
    let mut notes = Vec::new();
    if fallbacks_left_out > 0 {
        notes.push(format!(
            "note: {fallbacks_left_out} fallback model(s) left out to keep the image within {MAX_IMAGE_BYTES} bytes"
        ));
    }
    let len = fixed.encoded_len();
    if let (true, Some((v, _))) = (len > MAX_IMAGE_BYTES, geometry) {
        anyhow::bail!(
            "the image with the volumetric section ({} bytes, {} terms) would be {len} bytes; the board's upload staging area holds {MAX_IMAGE_BYTES} (MAX_IMAGE_BYTES)",
            4 + v.encoded_len(),
            v.terms.len(),
        );
    }
    if len > MAX_IMAGE_BYTES {
        anyhow::bail!(
            "the image would be {len} bytes; the board's upload staging area holds {MAX_IMAGE_BYTES} (MAX_IMAGE_BYTES)"
        );
    }
    hold_nonlinear(&mut fixed, &trimmed, &mut notes);
    let bytes = encode(&mut fixed)?;
    Model::parse(&bytes).map_err(|e| anyhow::anyhow!("encoded image does not parse: {e}"))?;
    Ok(Built {
        model: fixed,
        bytes,
        report,
        fallbacks_left_out,
        notes,
    })
}

/// The image parser refuses `extrapolate` on a direction any of whose
/// models (network, tables, the fallbacks the image still holds) is not
/// linear in its inputs: such a direction holds, with a note.
fn hold_nonlinear(fixed: &mut Model, float: &FloatModel, notes: &mut Vec<String>) {
    let Some(policies) = fixed.envelope.as_mut() else {
        return;
    };
    for ((p, d), dir) in policies.iter_mut().zip(&float.directions).zip(0u8..) {
        if p.mode == EnvelopeMode::Extrapolate && !linear(float, dir) {
            p.mode = EnvelopeMode::Hold;
            notes.push(format!(
                "envelope d{}_um: extrapolate needs a linear model (no network, no position term, powers <= 1, fallbacks in the image too) and this channel's is not: the image holds",
                d.name
            ));
        }
    }
}

/// The image's bytes for `model` (sets its CRC).
pub fn encode(model: &mut Model) -> Result<Vec<u8>> {
    let mut bytes = vec![0u8; model.encoded_len()];
    let n = model
        .encode(&mut bytes)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    bytes.truncate(n);
    Ok(bytes)
}

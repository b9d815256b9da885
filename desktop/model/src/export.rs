//! `tcomp export` and `tcomp golden`: quantize a float model through the
//! core's quantizer into the model image the board loads, and write the
//! golden vectors the board must reproduce bit for bit.
//!
//! The fit's parameters become the board's float model in
//! [`float_model`]; what an export produced is reported by [`summary`].

pub mod envelope_policy;
pub mod float_model;
pub mod output_filter;
pub mod summary;

pub use envelope_policy::policies;
pub use float_model::*;
pub use output_filter::decays;
pub use summary::{print_summary, ExportSummary, Wire};

use anyhow::{Context, Result};
use std::path::Path;
use thermocomp_core::float::{FloatModel, QuantReport};
use thermocomp_core::Model;

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

/// Quantize, encode and write an image; the image is parsed back before it
/// is written, so only a valid image reaches the disk.
pub fn export(model: &FloatModel, out: &Path) -> Result<ExportSummary> {
    export_with(model, None, out)
}

/// [`export`] with a volumetric section (`tcomp export --geometry`): the
/// section is required, so when the image would not fit the fallbacks go
/// first (as without it) and then the export is refused, naming the limit.
pub fn export_with(
    model: &FloatModel,
    geometry: Option<GeometrySection>,
    out: &Path,
) -> Result<ExportSummary> {
    export_signed(model, geometry, out, None)
}

/// [`export_with`], signed with `sign` when given (`tcomp export --sign`):
/// the file is the image followed by its signature trailer.
pub fn export_signed(
    model: &FloatModel,
    geometry: Option<GeometrySection>,
    out: &Path,
    sign: Option<&ed25519_compact::SecretKey>,
) -> Result<ExportSummary> {
    export_five(model, geometry, None, out, sign)
}

/// [`export_signed`] with a five-axis section beside the volumetric one
/// (`tcomp export --geometry … --rotary …`).
pub fn export_five(
    model: &FloatModel,
    geometry: Option<GeometrySection>,
    five: Option<FiveAxisSection>,
    out: &Path,
    sign: Option<&ed25519_compact::SecretKey>,
) -> Result<ExportSummary> {
    export_enveloped(model, (geometry, five), None, out, sign)
}

/// Per direction, the image's envelope policy (section kind 5, format v3).
pub type EnvelopeSection =
    [thermocomp_core::image::EnvelopePolicy; thermocomp_core::limits::MAX_DIRECTIONS];

/// Per direction, the output low-pass's decay per model step in Q30
/// (section kind 6, format v5; 0: none).
pub type OutputFilterSection = [u32; thermocomp_core::limits::MAX_DIRECTIONS];

/// [`export_five`] with the envelope policy section when `envelope` is
/// given (`tcomp export` from a fit file with envelope evidence,
/// [`envelope_policy::policies`]).
pub fn export_enveloped(
    model: &FloatModel,
    (geometry, five): (Option<GeometrySection>, Option<FiveAxisSection>),
    envelope: Option<EnvelopeSection>,
    out: &Path,
    sign: Option<&ed25519_compact::SecretKey>,
) -> Result<ExportSummary> {
    export_sections(model, (geometry, five), (envelope, None), out, sign)
}

/// [`export_enveloped`] with the output filter section when `output` is
/// given (`tcomp export` from a fit file with `output_lag_s`,
/// [`output_filter::decays`]).
pub fn export_sections(
    model: &FloatModel,
    (geometry, five): (Option<GeometrySection>, Option<FiveAxisSection>),
    (envelope, output): (Option<EnvelopeSection>, Option<OutputFilterSection>),
    out: &Path,
    sign: Option<&ed25519_compact::SecretKey>,
) -> Result<ExportSummary> {
    if five.is_some() && geometry.is_none() {
        anyhow::bail!("a five-axis section needs the volumetric section (--geometry)");
    }
    let quantize = |m: &FloatModel| -> Result<(Model, QuantReport)> {
        let (mut fixed, report) = m.quantize().map_err(|e| anyhow::anyhow!("{e}"))?;
        fixed.volumetric = geometry.as_ref().map(|(v, _)| v.clone());
        fixed.five_axis = five.as_ref().map(|(f, _)| f.clone());
        fixed.envelope = envelope;
        fixed.output_decay_q30 = output;
        Ok((fixed, report))
    };
    let (mut fixed, mut report) = quantize(model)?;
    // Fallbacks are optional: drop the last (lowest priority) until the image fits.
    let mut trimmed = model.clone();
    while fixed.encoded_len() > thermocomp_core::limits::MAX_IMAGE_BYTES
        && trimmed.fallbacks.pop().is_some()
    {
        (fixed, report) = quantize(&trimmed)?;
    }
    if trimmed.fallbacks.len() < model.fallbacks.len() {
        eprintln!(
            "note: {} fallback model(s) left out to keep the image within {} bytes",
            model.fallbacks.len() - trimmed.fallbacks.len(),
            thermocomp_core::limits::MAX_IMAGE_BYTES
        );
    }
    let len = fixed.encoded_len();
    if let (true, Some((v, _))) = (len > thermocomp_core::limits::MAX_IMAGE_BYTES, &geometry) {
        anyhow::bail!(
            "the image with the volumetric section ({} bytes, {} terms) would be {len} bytes; the board's upload staging area holds {} (MAX_IMAGE_BYTES)",
            4 + v.encoded_len(),
            v.terms.len(),
            thermocomp_core::limits::MAX_IMAGE_BYTES
        );
    }
    if len > thermocomp_core::limits::MAX_IMAGE_BYTES {
        anyhow::bail!(
            "the image would be {len} bytes; the board's upload staging area holds {} (MAX_IMAGE_BYTES)",
            thermocomp_core::limits::MAX_IMAGE_BYTES
        );
    }
    let bytes = encode(&mut fixed)?;
    Model::parse(&bytes).map_err(|e| anyhow::anyhow!("encoded image does not parse: {e}"))?;
    let file = match sign {
        Some(sk) => crate::signing::sign_image(&bytes, sk)?,
        None => bytes.clone(),
    };
    std::fs::write(out, &file).with_context(|| format!("writing {}", out.display()))?;
    let mut s = summary::summary(&fixed, &bytes, &report);
    s.volumetric = geometry.map(|(_, r)| r);
    s.five_axis = five.map(|(_, r)| r);
    s.signed_by = sign.map(|sk| {
        crate::signing::public_of(sk)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    });
    Ok(s)
}

pub fn encode(model: &mut Model) -> Result<Vec<u8>> {
    let mut bytes = vec![0u8; model.encoded_len()];
    let n = model
        .encode(&mut bytes)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    bytes.truncate(n);
    Ok(bytes)
}

/// Write a golden-vector file (the demo model and `steps` steps).
pub fn golden(out: &Path, steps: u32, seed: u64) -> Result<usize> {
    let bytes = thermocomp_core::golden::generate(steps, seed)
        .map_err(|e| anyhow::anyhow!("golden vectors: {e}"))?;
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(bytes.len())
}

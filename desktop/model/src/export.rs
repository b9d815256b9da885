//! `tcomp export` and `tcomp golden`: quantize a float model through the
//! core's quantizer into the model image the board loads, and write the
//! golden vectors the board must reproduce bit for bit.
//!
//! The fit's parameters become the board's float model in
//! [`float_model`]; what an export produced is reported by [`summary`].

pub mod build;
pub mod envelope_policy;
pub mod float_model;
pub mod output_filter;
pub mod summary;

pub use build::{
    build_image, encode, Built, EnvelopeSection, FiveAxisSection, GeometrySection,
    OutputFilterSection, Sections,
};
pub use envelope_policy::policies;
pub use float_model::*;
pub use output_filter::decays;
pub use summary::{print_summary, ExportSummary, Wire};

use anyhow::{Context, Result};
use std::path::Path;
use thermocomp_core::float::FloatModel;

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
/// [`output_filter::decays`]): writes (and signs) the image
/// [`build_image`] builds, its notes on stderr.
pub fn export_sections(
    model: &FloatModel,
    (geometry, five): (Option<GeometrySection>, Option<FiveAxisSection>),
    (envelope, output): (Option<EnvelopeSection>, Option<OutputFilterSection>),
    out: &Path,
    sign: Option<&ed25519_compact::SecretKey>,
) -> Result<ExportSummary> {
    let sections = Sections {
        geometry,
        five,
        envelope,
        output,
    };
    let Built {
        model: fixed,
        bytes,
        report,
        notes,
        ..
    } = build_image(model, &sections)?;
    notes.iter().for_each(|n| eprintln!("{n}"));
    let file = match sign {
        Some(sk) => crate::signing::sign_image(&bytes, sk)?,
        None => bytes.clone(),
    };
    std::fs::write(out, &file).with_context(|| format!("writing {}", out.display()))?;
    let mut s = summary::summary(&fixed, &bytes, &report);
    s.volumetric = sections.geometry.map(|(_, r)| r);
    s.five_axis = sections.five.map(|(_, r)| r);
    s.signed_by = sign.map(|sk| {
        crate::signing::public_of(sk)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    });
    Ok(s)
}

/// Write a golden-vector file (the demo model and `steps` steps).
pub fn golden(out: &Path, steps: u32, seed: u64) -> Result<usize> {
    let bytes = thermocomp_core::golden::generate(steps, seed)
        .map_err(|e| anyhow::anyhow!("golden vectors: {e}"))?;
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(bytes.len())
}

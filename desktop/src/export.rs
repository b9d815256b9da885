//! `tcomp export` and `tcomp golden`: quantize a float model through the
//! core's quantizer into the model image the board loads, and write the
//! golden vectors the board must reproduce bit for bit.

use anyhow::{Context, Result};
use std::path::Path;
use thermocomp_core::float::{FloatModel, QuantReport};
use thermocomp_core::Model;

/// What an export produced, for the report and `--json`.
#[derive(Debug, serde::Serialize)]
pub struct ExportSummary {
    pub bytes: usize,
    pub crc32: String,
    pub model_version: u32,
    pub directions: Vec<String>,
    /// Worst |fixed − float| per direction over the admissible inputs, µm.
    pub max_deviation_um: Vec<f64>,
    pub samples: usize,
}

/// Quantize, encode and write an image; the image is parsed back before it
/// is written, so only a valid image reaches the disk.
pub fn export(model: &FloatModel, out: &Path) -> Result<ExportSummary> {
    let (mut fixed, report) = model.quantize().map_err(|e| anyhow::anyhow!("{e}"))?;
    let bytes = encode(&mut fixed)?;
    Model::parse(&bytes).map_err(|e| anyhow::anyhow!("encoded image does not parse: {e:?}"))?;
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(summary(&fixed, &bytes, &report))
}

pub fn encode(model: &mut Model) -> Result<Vec<u8>> {
    let mut bytes = vec![0u8; model.encoded_len()];
    let n = model
        .encode(&mut bytes)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    bytes.truncate(n);
    Ok(bytes)
}

fn summary(m: &Model, bytes: &[u8], r: &QuantReport) -> ExportSummary {
    ExportSummary {
        bytes: bytes.len(),
        crc32: format!("{:#010x}", m.crc),
        model_version: m.model_version,
        directions: (0..m.directions.len())
            .map(|d| m.direction_name(d).to_string())
            .collect(),
        max_deviation_um: r.max_deviation_um.clone(),
        samples: r.samples,
    }
}

pub fn print_summary(s: &ExportSummary, out: &Path, json: bool) {
    if json {
        println!("{}", serde_json::to_string(s).unwrap_or_default());
        return;
    }
    println!(
        "wrote {} ({} bytes, CRC-32 {}, model version {})",
        out.display(),
        s.bytes,
        s.crc32,
        s.model_version
    );
    for (d, dev) in s.directions.iter().zip(&s.max_deviation_um) {
        println!(
            "  {d}: worst fixed-vs-float deviation {dev:.4} µm over {} admissible input samples",
            s.samples
        );
    }
}

/// Write a golden-vector file (the demo model and `steps` steps).
pub fn golden(out: &Path, steps: u32, seed: u64) -> Result<usize> {
    let bytes = thermocomp_core::golden::generate(steps, seed);
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(bytes.len())
}

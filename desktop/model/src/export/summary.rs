//! What an export produced and how it is reported: the image's size, CRC
//! and version, the worst fixed-vs-float deviation per direction, the
//! fallbacks packed, the wiring (each model sensor → the board channel it is
//! read on, or its 1-Wire ROM code), the geometry sections and the signer;
//! as text or `--json`.

use std::path::Path;

use thermocomp_core::float::QuantReport;
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
    /// Fallback models packed (image format v2 when > 0).
    pub fallbacks: usize,
    /// Sensors the image names by 1-Wire ROM code (the rest by channel).
    pub sensors_by_rom: usize,
    /// The wiring: each model sensor and the board channel it is read on.
    pub wiring: Vec<Wire>,
    /// The volumetric section (`--geometry`) and what its quantisation costs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub volumetric: Option<tcomp_geometry::board::QuantisationReport>,
    /// The five-axis section (`--rotary`) and what its conversion and
    /// quantisation cost.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub five_axis: Option<tcomp_geometry::rotary_board::FiveAxisReport>,
    /// `--sign`: the public key (hex) whose private key signed the image;
    /// the file then carries the 72-byte signature trailer after `bytes`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signed_by: Option<String>,
}

/// One model sensor and where the board reads it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Wire {
    /// The run's temperature column (unknown for the demo model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    /// The board's channel, `T01` … `T20` (the run's T_ column order).
    pub board_channel: String,
    /// The sensor's 1-Wire ROM code when the image names it so (the board
    /// then reads it on whatever channel it is found).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rom: Option<String>,
}

/// The summary of `m`, encoded as `bytes`, and its quantisation report `r`.
pub(super) fn summary(m: &Model, bytes: &[u8], r: &QuantReport) -> ExportSummary {
    ExportSummary {
        bytes: bytes.len(),
        crc32: format!("{:#010x}", m.crc),
        model_version: m.model_version,
        directions: (0..m.directions.len())
            .map(|d| m.direction_name(d).to_string())
            .collect(),
        max_deviation_um: r.max_deviation_um.clone(),
        samples: r.samples,
        fallbacks: m.fallbacks.len(),
        sensors_by_rom: m.sensors.iter().filter(|s| s.rom != [0; 8]).count(),
        wiring: m
            .sensors
            .iter()
            .map(|s| Wire {
                sensor: None,
                board_channel: format!("T{:02}", usize::from(s.channel) + 1),
                rom: (s.rom != [0; 8]).then(|| tcomp_data::runcsv::format_rom(&s.rom)),
            })
            .collect(),
        volumetric: None,
        five_axis: None,
        signed_by: None,
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
    if let Some(k) = &s.signed_by {
        println!("  signed (Ed25519, 72-byte trailer after the image) by public key {k}");
    }
    if s.fallbacks > 0 {
        println!("  {} fallback model(s) for degraded mode", s.fallbacks);
    }
    if s.sensors_by_rom > 0 {
        println!(
            "  {} sensor(s) named by 1-Wire ROM code (the board reads each from its own sensor, whatever its channel)",
            s.sensors_by_rom
        );
    }
    if !s.wiring.is_empty() {
        println!("  wiring (model sensor → board channel):");
        for (i, w) in s.wiring.iter().enumerate() {
            let name = w.sensor.clone().unwrap_or_else(|| format!("sensor {i}"));
            match &w.rom {
                Some(rom) => println!(
                    "    {name} → {} (by ROM {rom}: read on whatever channel that sensor is found)",
                    w.board_channel
                ),
                None => println!("    {name} → {}", w.board_channel),
            }
        }
    }
    for (d, dev) in s.directions.iter().zip(&s.max_deviation_um) {
        println!(
            "  {d}: worst fixed-vs-float deviation {dev:.4} µm over {} admissible input samples",
            s.samples
        );
    }
    if let Some(v) = &s.volumetric {
        println!(
            "  volumetric section: {} terms, {} sensor(s), {} bytes; served (0.1 µm) vs the f64 polynomial over {} grid points: worst {:.4} µm ({:.6} µm before the final rounding; stated bound {:.4} µm)",
            v.terms,
            v.sensors,
            v.section_bytes,
            v.grid_points,
            v.max_error_um,
            v.max_error_before_rounding_um,
            v.bound_um
        );
    }
    if let Some(f) = &s.five_axis {
        println!(
            "  five-axis section: Fourier order {} (the exact rotating-frame series needs {}; dropped RMS {:.4} µm, {:.4} µrad), {} bytes; served rotary part vs the model's f64 first-order prediction over {} poses: worst {:.4} µm (stated bound {:.4} µm)",
            f.order,
            f.order_needed,
            f.truncated_rms_um,
            f.truncated_rms_urad,
            f.section_bytes,
            f.grid_points,
            f.max_error_um,
            f.bound_um
        );
        if f.rtest_location {
            println!(
                "  five-axis location errors in the R-test mode, drifting with {} (served as (I − R(θ))·ξ_L(T); needs firmware that reads the section's flags)",
                f.drift_sensors.join(", ")
            );
        }
    }
}

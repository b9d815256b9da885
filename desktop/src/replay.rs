//! `tcomp replay`: the desktop core's output for a recorded trace, computed
//! by the same fixed-point code the board runs and fed the same integers
//! (temperatures quantized to 1/16 °C exactly as the board's trace parser
//! does). For a trace without sensor faults the board's Modbus registers
//! must equal these rows bit for bit.

use anyhow::{anyhow, Context, Result};
use thermocomp::trace::{TraceHeader, TraceSample};
use thermocomp_core::limits::MAX_SENSORS;
use thermocomp_core::{Compensator, Model, StepInput, StepOutput};

#[derive(Debug, Clone, Copy)]
pub struct ReplayRow {
    pub time_ms: u64,
    pub out: StepOutput,
}

/// Compensate every sample of a run CSV (text) with `model`.
pub fn replay(csv: &str, model: Model) -> Result<Vec<ReplayRow>> {
    let mut lines = csv
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.starts_with('#') && !l.trim().is_empty());
    let (_, head) = lines.next().ok_or_else(|| anyhow!("empty trace"))?;
    let header = TraceHeader::parse(head).map_err(|e| anyhow!("header: {e}"))?;
    let channels: Vec<Option<usize>> = model
        .sensors
        .iter()
        .map(|s| (s.rom == [0; 8]).then_some(usize::from(s.channel)))
        .collect();
    let mut comp = Compensator::new(Some(model));
    let mut rows = Vec::new();
    for (n, line) in lines {
        let s = TraceSample::parse(&header, line).map_err(|e| anyhow!("line {}: {e}", n + 1))?;
        let mut temps = [None; MAX_SENSORS];
        for (t, ch) in temps.iter_mut().zip(&channels) {
            // The board reads i16 from a DS18B20; anything else is no sensor.
            *t = ch
                .and_then(|c| s.temperatures.get(c).copied().flatten())
                .filter(|v| i16::try_from(*v).is_ok());
        }
        let out = comp.step(&StepInput {
            now_ms: s.time_ms,
            temps: &temps[..channels.len()],
            spindle_rpm: s.spindle_rpm.unwrap_or(0),
            positions: &[0; 6],
            stale: s.spindle_rpm.is_none(),
        });
        rows.push(ReplayRow {
            time_ms: s.time_ms,
            out,
        });
    }
    Ok(rows)
}

/// Read a trace file and a model image file and replay.
pub fn replay_files(trace: &std::path::Path, image: &std::path::Path) -> Result<Vec<ReplayRow>> {
    let csv =
        std::fs::read_to_string(trace).with_context(|| format!("reading {}", trace.display()))?;
    let bytes = std::fs::read(image).with_context(|| format!("reading {}", image.display()))?;
    let model = Model::parse(&bytes).map_err(|e| anyhow!("{}: {e}", image.display()))?;
    replay(&csv, model)
}

/// Error figures of the board's served correction against a measured channel.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Residual {
    pub column: String,
    pub rows: usize,
    pub mae_um: f64,
    pub rms_um: f64,
    pub peak_um: f64,
    /// 100 · (1 − RMS(residual) / RMS(measured)).
    pub reduction_pct: f64,
}

/// Compare each direction `<name>` with the run's `d<name>_um` column over
/// rows `[from, to)`: residual = measured − served correction.
pub fn residuals(
    run: &crate::runcsv::Run,
    rows: &[ReplayRow],
    model: &Model,
    from: usize,
    to: usize,
) -> Vec<Residual> {
    let mut out = vec![];
    for d in 0..model.directions.len() {
        let column = format!("d{}_um", model.direction_name(d));
        let Some(measured) = run.col(&column) else {
            continue;
        };
        let (mut n, mut abs, mut sq, mut peak, mut msq) = (0usize, 0.0, 0.0, 0.0f64, 0.0);
        for (row, m) in rows.iter().zip(measured).take(to).skip(from) {
            let Some(m) = m else { continue };
            let r = m - f64::from(row.out.corrections[d]) / 10.0;
            n += 1;
            abs += r.abs();
            sq += r * r;
            msq += m * m;
            peak = peak.max(r.abs());
        }
        if n == 0 {
            continue;
        }
        let nf = n as f64;
        out.push(Residual {
            column,
            rows: n,
            mae_um: abs / nf,
            rms_um: (sq / nf).sqrt(),
            peak_um: peak,
            reduction_pct: 100.0 * (1.0 - (sq / msq.max(f64::MIN_POSITIVE)).sqrt()),
        });
    }
    out
}

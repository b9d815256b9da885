//! `tcomp replay`: the desktop core's output for a recorded trace, computed
//! by the same fixed-point code the board runs and fed the same integers
//! (temperatures quantized to 1/16 °C exactly as the board's trace parser
//! does). For a trace without sensor faults the board's Modbus registers
//! must equal these rows bit for bit.

use anyhow::{anyhow, Context, Result};
use thermocomp_core::limits::MAX_SENSORS;
use thermocomp_core::{Compensator, Model, StepInput, StepOutput};
use thermocomp_protocol::trace::{TraceHeader, TraceSample};

#[derive(Debug, Clone, Copy)]
pub struct ReplayRow {
    pub time_ms: u64,
    pub out: StepOutput,
}

/// A sensor lost from a time on (`tcomp replay --fail-sensor`): the board
/// reads its channel as invalid from `from_ms` (trace time) to the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorFailure {
    /// Temperature channel (the run's T_ column index).
    pub channel: usize,
    pub from_ms: u64,
}

/// Compensate every sample of a run CSV (text) with `model`.
pub fn replay(csv: &str, model: Model) -> Result<Vec<ReplayRow>> {
    replay_failing(csv, model, &[])
}

/// As [`replay`], with sensors lost from given times on.
pub fn replay_failing(
    csv: &str,
    model: Model,
    failures: &[SensorFailure],
) -> Result<Vec<ReplayRow>> {
    let mut lines = csv
        .lines()
        .enumerate()
        .filter(|(_, l)| !thermocomp_protocol::trace::is_comment_or_blank(l));
    let (_, head) = lines.next().ok_or_else(|| anyhow!("empty trace"))?;
    let header = TraceHeader::parse(head).map_err(|e| anyhow!("header: {e}"))?;
    let mut roms = std::collections::BTreeMap::new();
    for line in csv.lines().filter_map(|l| l.strip_prefix('#')) {
        if let Some((k, v)) = line.split_once(':') {
            if let Some(column) = k.trim().strip_prefix(tcomp_data::runcsv::ROM_KEY_PREFIX) {
                let rom = tcomp_data::runcsv::parse_rom(v)
                    .with_context(|| format!("metadata `{}`", k.trim()))?;
                roms.insert(column.to_string(), rom);
            }
        }
    }
    let names: Vec<String> = head
        .split(',')
        .map(str::trim)
        .filter(|c| thermocomp_protocol::trace::is_temperature_column(c))
        .map(str::to_string)
        .collect();
    let channels = sensor_columns(&model, &names, &roms);
    let mut comp = Compensator::new(Some(model));
    let mut rows = Vec::new();
    for (n, line) in lines {
        let s = TraceSample::parse(&header, line).map_err(|e| anyhow!("line {}: {e}", n + 1))?;
        let mut temps = [None; MAX_SENSORS];
        for (t, ch) in temps.iter_mut().zip(&channels) {
            // The board reads i16 from a DS18B20; anything else is no sensor.
            *t = ch
                .filter(|c| {
                    !failures
                        .iter()
                        .any(|f| f.channel == *c && s.time_ms >= f.from_ms)
                })
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

/// The temperature column (index among the run's `T_…` columns) each model
/// sensor reads, as the board resolves it: a sensor named by channel reads
/// that column; a sensor named by ROM code reads the column the run records
/// that ROM for (`# rom.T_…:`), none when the run records ROM codes but not
/// this one (a missing sensor, as on the board), and its training column
/// when the run records no ROM codes at all.
pub fn sensor_columns(
    model: &Model,
    temperature_columns: &[String],
    roms: &std::collections::BTreeMap<String, [u8; 8]>,
) -> Vec<Option<usize>> {
    model
        .sensors
        .iter()
        .map(|s| {
            if s.rom == [0; 8] || roms.is_empty() {
                return Some(usize::from(s.channel));
            }
            let column = roms.iter().find(|(_, r)| **r == s.rom)?.0;
            temperature_columns.iter().position(|c| c == column)
        })
        .collect()
}

/// Read a trace file and a model image file and replay.
pub fn replay_files(trace: &std::path::Path, image: &std::path::Path) -> Result<Vec<ReplayRow>> {
    replay_files_failing(trace, image, &[])
}

/// As [`replay_files`], with sensors lost from given times on.
pub fn replay_files_failing(
    trace: &std::path::Path,
    image: &std::path::Path,
    failures: &[SensorFailure],
) -> Result<Vec<ReplayRow>> {
    let csv =
        std::fs::read_to_string(trace).with_context(|| format!("reading {}", trace.display()))?;
    let bytes = std::fs::read(image).with_context(|| format!("reading {}", image.display()))?;
    let model = Model::parse(&bytes).map_err(|e| anyhow!("{}: {e}", image.display()))?;
    replay_failing(&csv, model, failures)
}

/// Parse `--fail-sensor NAME@TIME`: NAME a temperature column of `run`,
/// TIME seconds of the run's time (`1800`, `1800s`) or a percentage of its
/// rows (`60%`: from the row where `--from 0.6` starts scoring).
pub fn parse_failure(spec: &str, run: &tcomp_data::runcsv::Run) -> Result<SensorFailure> {
    let (name, at) = spec
        .split_once('@')
        .ok_or_else(|| anyhow!("--fail-sensor {spec}: expected NAME@SECONDS or NAME@PERCENT%"))?;
    let columns = run.temperature_columns();
    let channel = columns
        .iter()
        .position(|c| *c == name.trim())
        .ok_or_else(|| {
            anyhow!(
                "--fail-sensor {spec}: no temperature column {name} (columns: {})",
                columns.join(",")
            )
        })?;
    let at = at.trim();
    let from_ms = if let Some(p) = at.strip_suffix('%') {
        let p: f64 = p
            .trim()
            .parse()
            .map_err(|_| anyhow!("--fail-sensor {spec}: {at} is not a percentage"))?;
        if !(0.0..=100.0).contains(&p) {
            anyhow::bail!("--fail-sensor {spec}: percentage outside 0-100");
        }
        let t = run.time_s();
        let row = ((p / 100.0) * t.len() as f64) as usize;
        t.get(row).map_or(u64::MAX, |s| (s * 1000.0).round() as u64)
    } else {
        let s: f64 = at
            .trim_end_matches('s')
            .trim()
            .parse()
            .map_err(|_| anyhow!("--fail-sensor {spec}: {at} is not a time in seconds"))?;
        if !(s >= 0.0 && s.is_finite()) {
            anyhow::bail!("--fail-sensor {spec}: time must be 0 s or later");
        }
        (s * 1000.0).round() as u64
    };
    Ok(SensorFailure { channel, from_ms })
}

/// Error figures of the board's served correction against a measured channel,
/// two ways: about the run's reference (what the board compensates: the
/// measured error is relative to the run's first sample) and about the
/// scored block's own mean (what an operator who re-zeroes the machine at
/// the start of the block would see).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Residual {
    pub column: String,
    pub rows: usize,
    /// Residual (measured − served) about the run's reference.
    pub mae_um: f64,
    pub rms_um: f64,
    pub peak_um: f64,
    /// RMS of the measured error itself (no compensation), about the reference.
    pub uncompensated_rms_um: f64,
    /// 100 · (1 − RMS(residual) / RMS(measured)), about the reference.
    pub reduction_pct: f64,
    /// The same with each series' block mean removed (re-zeroed operator's view).
    pub rms_about_mean_um: f64,
    pub uncompensated_rms_about_mean_um: f64,
    pub reduction_about_mean_pct: f64,
    /// RMS(residual) ≤ RMS(measured) about the reference: the board did not
    /// make this block worse than no compensation.
    pub never_worse: bool,
    /// The same about the block's own mean (RMS about the mean not above
    /// the uncompensated one: `reduction_about_mean_pct` ≥ 0).
    pub never_worse_about_mean: bool,
    /// Rows at which an input of the model serving this direction was
    /// beyond its training envelope by more than the image's margin (the
    /// core's `StepOutput::envelope` bit, as the board counts it in input
    /// registers 360–371), and their share of the scored rows.
    pub out_of_envelope_rows: usize,
    pub out_of_envelope_share: f64,
    /// The image's envelope policy for this direction ("hold", "fallback"
    /// or "extrapolate"; "hold" without the section) and its margin (raw
    /// units: 1/16 °C, rpm).
    pub envelope_policy: &'static str,
    pub envelope_margin_raw: u16,
    /// The time constant (s) of the image's output low-pass on this
    /// direction (section kind 6); `None` without one.
    pub output_lag_s: Option<f64>,
    /// MAE (µm, about the run's reference) over those rows; `None` without any.
    pub out_of_envelope_mae_um: Option<f64>,
    /// MAE over the other scored rows; `None` without any.
    pub in_envelope_mae_um: Option<f64>,
}

/// Rows per status flag over the scored block.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FlagCounts {
    pub valid: usize,
    pub out_of_envelope: usize,
    pub clamped: usize,
    pub rate_limited: usize,
    pub stale: usize,
    pub sensor_fault: usize,
    pub no_model: usize,
    pub warming_up: usize,
    /// A direction served by a fallback model (a model sensor invalid).
    pub degraded: usize,
}

/// Count status flags over rows `[from, to)`.
pub fn flag_counts(rows: &[ReplayRow], from: usize, to: usize) -> FlagCounts {
    use thermocomp_core::compensator::status as st;
    let mut c = FlagCounts::default();
    for r in rows.iter().take(to).skip(from) {
        let s = r.out.status;
        let add = |bit: u16, n: &mut usize| {
            if s & bit != 0 {
                *n += 1;
            }
        };
        add(st::VALID, &mut c.valid);
        add(st::OUT_OF_ENVELOPE, &mut c.out_of_envelope);
        add(st::CLAMPED, &mut c.clamped);
        add(st::RATE_LIMITED, &mut c.rate_limited);
        add(st::STALE_INPUTS, &mut c.stale);
        add(st::SENSOR_FAULT, &mut c.sensor_fault);
        add(st::NO_MODEL, &mut c.no_model);
        add(st::WARMING_UP, &mut c.warming_up);
        add(st::DEGRADED, &mut c.degraded);
    }
    c
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn demeaned(v: &[f64]) -> Vec<f64> {
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    v.iter().map(|x| x - m).collect()
}

fn reduction(res: f64, raw: f64) -> f64 {
    if raw > 0.0 {
        100.0 * (1.0 - res / raw)
    } else {
        0.0
    }
}

/// Compare each direction `<name>` with the run's `d<name>_um` column over
/// rows `[from, to)`: residual = measured − served correction.
pub fn residuals(
    run: &tcomp_data::runcsv::Run,
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
        let (mut meas, mut res, mut outside) = (vec![], vec![], vec![]);
        for (row, m) in rows.iter().zip(measured).take(to).skip(from) {
            let Some(m) = m else { continue };
            meas.push(*m);
            res.push(m - f64::from(row.out.corrections[d]) / 10.0);
            outside.push(row.out.envelope & (1 << d) != 0);
        }
        if meas.is_empty() {
            continue;
        }
        let n = meas.len() as f64;
        let mae_where = |want: bool| {
            let v: Vec<f64> = res
                .iter()
                .zip(&outside)
                .filter(|(_, &o)| o == want)
                .map(|(r, _)| r.abs())
                .collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        let n_out = outside.iter().filter(|&&o| o).count();
        let policy = model
            .envelope
            .and_then(|p| p.get(d).copied())
            .unwrap_or_default();
        let (r_rms, m_rms) = (rms(&res), rms(&meas));
        let (r_rms0, m_rms0) = (rms(&demeaned(&res)), rms(&demeaned(&meas)));
        out.push(Residual {
            column,
            rows: meas.len(),
            mae_um: res.iter().map(|r| r.abs()).sum::<f64>() / n,
            rms_um: r_rms,
            peak_um: res.iter().fold(0.0f64, |a, r| a.max(r.abs())),
            uncompensated_rms_um: m_rms,
            reduction_pct: reduction(r_rms, m_rms),
            rms_about_mean_um: r_rms0,
            uncompensated_rms_about_mean_um: m_rms0,
            reduction_about_mean_pct: reduction(r_rms0, m_rms0),
            never_worse: r_rms <= m_rms,
            never_worse_about_mean: r_rms0 <= m_rms0 * (1.0 + 1e-12),
            out_of_envelope_rows: n_out,
            out_of_envelope_share: n_out as f64 / n,
            envelope_policy: policy.mode.name(),
            envelope_margin_raw: policy.margin,
            output_lag_s: model
                .output_decay_q30
                .and_then(|q| q.get(d).copied())
                .and_then(|q| crate::export::output_filter::tau_s(model.step_ms, q)),
            out_of_envelope_mae_um: mae_where(true),
            in_envelope_mae_um: mae_where(false),
        });
    }
    out
}

//! The eddy-current probe's own temperature drift (issue 28): the probe and
//! its mount read `k·(T − 20 °C)` more than the gap, `T` the DS18B20 named
//! as the probe's (the board's holding register 42). `tcomp fit
//! --probe-drift <run> --probe-channel T05` estimates `k` from a run in
//! which the target does not move (every change of the reading is the
//! probe's own), or takes it given (`--probe-drift-um-per-k`); the board
//! removes it before a reading is used for a reference
//! (`thermocomp_core::reference::remove_probe_drift`, holding register 43 in
//! nm/K) and `tcomp record` before it writes `dprobe_um`.
//!
//! The estimate is ordinary least squares of the raw reading on `T − 20`
//! (two parameters: closed form, hand-written as the rest of the crate's
//! small regressions), with its standard error from the residual.

use anyhow::{anyhow, bail, Result};
use tcomp_data::runcsv::Run;

/// The raw probe column `tcomp record` writes (not an error column: never fitted as a channel).
pub const RAW_COLUMN: &str = "probe_raw_um";
/// The drift-removed probe column.
pub const PROBE_COLUMN: &str = "dprobe_um";

/// What `tcomp fit` reports under `"probe_drift"`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProbeDrift {
    /// The probe's temperature column.
    pub channel: String,
    /// k, µm/K.
    pub um_per_k: f64,
    /// k as holding register 43 takes it (nm/K, rounded, int16).
    pub register_nm_per_k: i16,
    /// "estimated" or "given".
    pub source: String,
    /// Standard error of the estimate, µm/K (estimated only).
    pub stderr_um_per_k: Option<f64>,
    /// Rows used, temperature span (K), residual RMS after removal (µm).
    pub rows: usize,
    pub span_k: Option<f64>,
    pub residual_rms_um: Option<f64>,
    /// Which probe column the estimate read.
    pub column: Option<String>,
}

/// k (µm/K) as the board's register (nm/K), refused outside int16.
pub fn register_value(um_per_k: f64) -> Result<i16> {
    let nm = (um_per_k * 1000.0).round();
    if !nm.is_finite() || nm < f64::from(i16::MIN) || nm > f64::from(i16::MAX) {
        bail!("probe drift {um_per_k} µm/K: the board holds -32.768 to 32.767 µm/K");
    }
    Ok(nm as i16)
}

/// A given coefficient.
pub fn given(channel: &str, um_per_k: f64) -> Result<ProbeDrift> {
    Ok(ProbeDrift {
        channel: channel.to_string(),
        um_per_k,
        register_nm_per_k: register_value(um_per_k)?,
        source: "given".into(),
        stderr_um_per_k: None,
        rows: 0,
        span_k: None,
        residual_rms_um: None,
        column: None,
    })
}

/// Estimate k from `run` (the target does not move): the raw probe column
/// (`probe_raw_um`, else `dprobe_um`) against `channel` (°C).
pub fn estimate(run: &Run, channel: &str) -> Result<ProbeDrift> {
    let temps = run
        .col(channel)
        .ok_or_else(|| anyhow!("--probe-channel {channel}: the run has no such column"))?;
    let (column, probe) = [RAW_COLUMN, PROBE_COLUMN]
        .iter()
        .find_map(|c| run.col(c).map(|v| (c.to_string(), v)))
        .ok_or_else(|| {
            anyhow!("the run has no probe column ({RAW_COLUMN} or {PROBE_COLUMN}): record it with tcomp record")
        })?;
    let pairs: Vec<(f64, f64)> = temps
        .iter()
        .zip(probe)
        .filter_map(|(t, p)| Some(((*t)? - 20.0, (*p)?)))
        .filter(|(t, p)| t.is_finite() && p.is_finite())
        .collect();
    let n = pairs.len();
    if n < 3 {
        bail!("{channel} and {column}: {n} rows with both values; at least 3 needed");
    }
    let nf = n as f64;
    let mt = pairs.iter().map(|p| p.0).sum::<f64>() / nf;
    let mp = pairs.iter().map(|p| p.1).sum::<f64>() / nf;
    let stt: f64 = pairs.iter().map(|p| (p.0 - mt).powi(2)).sum();
    let (lo, hi) = pairs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    if stt <= 1e-12 || hi - lo < 0.5 {
        bail!(
            "{channel} spans {:.2} K: the probe's drift needs a run over at least 0.5 K",
            hi - lo
        );
    }
    let k = pairs.iter().map(|p| (p.0 - mt) * (p.1 - mp)).sum::<f64>() / stt;
    let a = mp - k * mt;
    let ss: f64 = pairs.iter().map(|p| (p.1 - a - k * p.0).powi(2)).sum();
    let stderr = (ss / (nf - 2.0).max(1.0) / stt).sqrt();
    Ok(ProbeDrift {
        channel: channel.to_string(),
        um_per_k: k,
        register_nm_per_k: register_value(k)?,
        source: "estimated".into(),
        stderr_um_per_k: Some(stderr),
        rows: n,
        span_k: Some(hi - lo),
        residual_rms_um: Some((ss / nf).sqrt()),
        column: Some(column),
    })
}

impl ProbeDrift {
    /// The text form.
    pub fn print(&self) {
        match self.stderr_um_per_k {
            Some(se) => println!(
                "probe drift ({}, {}): {:+.4} µm/K ± {:.4} over {} rows, {:.1} K span, residual RMS {:.3} µm; holding register 43 = {} nm/K",
                self.channel,
                self.column.as_deref().unwrap_or("-"),
                self.um_per_k,
                se,
                self.rows,
                self.span_k.unwrap_or(0.0),
                self.residual_rms_um.unwrap_or(0.0),
                self.register_nm_per_k
            ),
            None => println!(
                "probe drift ({}): {:+.4} µm/K (given); holding register 43 = {} nm/K",
                self.channel, self.um_per_k, self.register_nm_per_k
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(rows: &[(f64, f64)]) -> Run {
        let mut csv = String::from("time_s,T05,probe_raw_um\n");
        for (i, (t, p)) in rows.iter().enumerate() {
            csv += &format!("{i},{t},{p}\n");
        }
        Run::from_reader(csv.as_bytes()).unwrap()
    }

    #[test]
    fn a_linear_drift_is_found() {
        let rows: Vec<(f64, f64)> = (0..50)
            .map(|i| {
                let t = 18.0 + 0.3 * f64::from(i);
                (
                    t,
                    100.0 + 0.5 * (t - 20.0) + if i % 2 == 0 { 0.1 } else { -0.1 },
                )
            })
            .collect();
        let d = estimate(&run(&rows), "T05").unwrap();
        assert!((d.um_per_k - 0.5).abs() < 0.01, "{d:?}");
        assert!((d.register_nm_per_k - 500).abs() <= 10, "{d:?}");
        assert_eq!(d.rows, 50);
    }

    #[test]
    fn refusals_are_one_line() {
        let flat = run(&[(20.0, 1.0), (20.1, 1.0), (20.0, 1.1)]);
        let e = estimate(&flat, "T05").unwrap_err().to_string();
        assert!(e.contains("at least 0.5 K"), "{e}");
        assert!(estimate(&flat, "T09").is_err());
        assert!(register_value(40.0).is_err());
        assert_eq!(given("T05", -0.25).unwrap().register_nm_per_k, -250);
    }
}

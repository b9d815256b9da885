//! Checks a newcomer's runs pass before an image is made (`fit`, `export`):
//! temperatures that look like °F, error columns that look like mm, error
//! columns that do not start near 0 without `error_reference: absolute`,
//! and too few rows for the command. Each finding is one line in the
//! user's terms with its fix and the flag that accepts it; without the
//! flag the command refuses (exit 1).

use anyhow::{bail, Result};

use tcomp_data::runcsv::Run;

/// The coolest temperature column's median above this (°C) reads as °F: a
/// machine's coolest sensor sits near the shop air, 15–40 °C.
pub const FAHRENHEIT_ABOVE_C: f64 = 45.0;
/// An error column spanning less than this (µm) …
pub const MM_SPAN_UM: f64 = 0.5;
/// … while some temperature moves at least this (K) reads as mm.
pub const MM_TEMP_SPAN_K: f64 = 3.0;
/// An error column whose first valid sample is farther from 0 (µm) is not
/// a rise from the run's first sample.
pub const START_UM: f64 = 5.0;
/// Fewer rows than this per run give no meaningful correlation or RMS.
pub const MIN_ROWS: usize = 10;

/// The flags that accept what the checks flag.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct AcceptArgs {
    /// Go on although the run's temperatures look like °F or an error
    /// column looks like mm (the unit checks made before an image).
    #[arg(long)]
    pub accept_units: bool,
    /// Go on although an error column does not start near 0 µm and the
    /// run's metadata does not say `error_reference: absolute`.
    #[arg(long)]
    pub accept_reference: bool,
}

/// Check every `(label, run)`: accepted findings are printed as warnings
/// on stderr, the others refuse in one line.
pub fn check_runs<'a>(
    runs: impl IntoIterator<Item = (&'a str, &'a Run)>,
    accept: &AcceptArgs,
) -> Result<()> {
    let mut refused = Vec::new();
    for (label, run) in runs {
        for (units, msg) in findings(label, run) {
            let (ok, flag) = if units {
                (accept.accept_units, "--accept-units")
            } else {
                (accept.accept_reference, "--accept-reference")
            };
            if ok {
                eprintln!("warning: {msg} (accepted: {flag})");
            } else {
                refused.push(format!("{msg}, or pass {flag}"));
            }
        }
    }
    if !refused.is_empty() {
        bail!("{}", refused.join("; also "));
    }
    Ok(())
}

/// Refuse a run with fewer than [`MIN_ROWS`] rows for `command`, saying
/// `why` it needs them.
pub fn require_rows(label: &str, run: &Run, command: &str, why: &str) -> Result<()> {
    if run.rows() < MIN_ROWS {
        bail!(
            "{label}: {} row(s); `{command}` needs at least {MIN_ROWS} rows per run ({why})",
            run.rows()
        );
    }
    Ok(())
}

fn values(run: &Run, c: &str) -> Vec<f64> {
    run.col(c)
        .map(|v| v.iter().flatten().copied().collect())
        .unwrap_or_default()
}

fn span(v: &[f64]) -> f64 {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    hi - lo
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// `(is a unit finding, message)` for one run.
fn findings(label: &str, run: &Run) -> Vec<(bool, String)> {
    let mut out = Vec::new();
    let temps: Vec<(&str, Vec<f64>)> = run
        .temperature_columns()
        .into_iter()
        .map(|c| (c, values(run, c)))
        .filter(|(_, v)| !v.is_empty())
        .collect();
    let coolest = temps
        .iter()
        .map(|(c, v)| (*c, median(v)))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((c, m)) = coolest.filter(|(_, m)| *m > FAHRENHEIT_ABOVE_C) {
        out.push((
            true,
            format!(
                "{label}: the temperatures look like °F: the coolest sensor, {c}, reads {m:.1} (median), and a machine's coolest sensor sits near the shop air, 15–40 °C (flagged above {FAHRENHEIT_ABOVE_C} °C); the run format's temperatures are °C: convert them, (°F − 32) / 1.8"
            ),
        ));
    }
    let (temp_col, temp_span) = temps
        .iter()
        .map(|(c, v)| (*c, span(v)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or(("", 0.0));
    let absolute = run.meta("error_reference") == Some("absolute");
    for c in run.error_columns() {
        let v = values(run, c);
        if v.len() < 2 {
            continue;
        }
        let s = span(&v);
        // a constant column (a placeholder) says nothing about its unit
        if s > 0.0 && s < MM_SPAN_UM && temp_span >= MM_TEMP_SPAN_K {
            out.push((
                true,
                format!(
                    "{label}: {c} spans only {s:.3} while {temp_col} moves {temp_span:.1} K: that looks like mm, not µm (flagged: a span under {MM_SPAN_UM} with a temperature moving {MM_TEMP_SPAN_K} K or more); the run format's error columns are µm: multiply by 1000"
                ),
            ));
        }
        if !absolute && v[0].abs() > START_UM {
            out.push((
                false,
                format!(
                    "{label}: {c} starts at {:.1} µm, not near 0 (flagged beyond ±{START_UM} µm): the run format's error columns are rises from the run's first sample; if these are absolute readings, add the line `# error_reference: absolute` before the header (tcomp then subtracts the first sample)",
                    v[0]
                ),
            ));
        }
    }
    out
}

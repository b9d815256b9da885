//! A chiller must show as a line (`diagnose fit`, issue 52).
//!
//! The `coolant` candidate fits a sinusoid (gated by `coolant_on` when the
//! runs have it) to the nominal's residual; it earns the claim's margins
//! whenever the residual has structure at some period. Machining blocks
//! of 20–90 min, or a nominal that misfits the warm-up, give exactly that:
//! on the project's open world every `coolant` named on a case without a
//! cycling chiller (one wrong, two false alarms in 180 cases) came without
//! a spectral line, while 27 of 28 true chillers were also named by the
//! periodic line test. A cycling chiller is a periodic driver: some
//! sensor's residual carries a line at its period, significant against
//! the local background after correction for the number of periods and
//! channels tried (`periodic_claim`). So `coolant` stays claimed only when
//! that test claims a line at its period, within the periodogram's
//! resolution (1/T in frequency, T the shortest run); otherwise it is
//! listed untestable with why.

use crate::diagnose::ident::Problem;
use crate::diagnose::types::Finding;

/// The period [s] a finding states (`params.period_s`).
fn period(f: &Finding) -> Option<f64> {
    f.params
        .as_ref()
        .and_then(|p| p["period_s"].as_f64())
        .filter(|v| v.is_finite() && *v > 0.0)
}

/// Whether two periods [s] are one line at frequency resolution `df` [Hz].
fn same_line(a: f64, b: f64, df: f64) -> bool {
    (1.0 / a - 1.0 / b).abs() <= df
}

/// Takes every claimed `coolant` without a claimed periodic line at its
/// period out of `findings` and lists it under `untestable`.
pub(super) fn confirm(
    p: &Problem,
    findings: &mut Vec<Finding>,
    untestable: &mut Vec<(String, String)>,
) {
    let t =
        p.ds.runs
            .iter()
            .map(|r| r.rows() as f64 * r.dt)
            .fold(f64::INFINITY, f64::min);
    if !(t.is_finite() && t > 0.0) {
        return;
    }
    let lines: Vec<f64> = findings
        .iter()
        .filter(|f| f.name == "periodic")
        .filter_map(period)
        .collect();
    let mut kept = Vec::with_capacity(findings.len());
    for f in findings.drain(..) {
        let unconfirmed = f.name == "coolant"
            && period(&f).is_none_or(|pc| !lines.iter().any(|&pl| same_line(pc, pl, 1.0 / t)));
        if unconfirmed {
            untestable.push((
                "coolant (no spectral line)".into(),
                format!(
                    "a cycle of {:.0} s fits the residual, but no sensor's residual shows a line at that period by the periodic test: the duty's own rhythm or a misfit of the identified model reads as a chiller; a sensor on the coolant circuit, or runs with another duty, would separate them",
                    period(&f).unwrap_or(f64::NAN)
                ),
            ));
        } else {
            kept.push(f);
        }
    }
    *findings = kept;
}

#[cfg(test)]
mod tests {
    use super::same_line;

    #[test]
    fn one_line_within_the_periodograms_resolution() {
        let df = 1.0 / 28_800.0; // an 8 h run
        assert!(same_line(673.7, 673.4, df));
        assert!(same_line(2000.0, 2120.0, df));
        assert!(!same_line(2000.0, 2400.0, df));
        assert!(!same_line(3744.9, 2136.5, df));
    }
}

//! A chiller must show as a line (`diagnose fit`, issue 52).
//!
//! The `coolant` candidate fits a sinusoid (gated by `coolant_on` when the
//! runs have it) to the nominal's residual; it earns the claim's margins
//! whenever the residual has structure at some period. Machining blocks
//! of 20–90 min, or a nominal that misfits the warm-up, give exactly that:
//! on the project's open world every `coolant` named on a case without a
//! cycling chiller (one wrong, two false alarms in 180 cases) came without
//! a spectral line, while 27 of 28 true chillers were also named by the
//! periodic line test. A cycling chiller is a periodic driver: a sensor's
//! residual carries a line at its period, significant against the local
//! background after correction for the number of periods and channels
//! tried (`periodic_claim`). So a `coolant` candidate keeps its claim only
//! when that test claims its line (the residual's strongest) at the
//! candidate's period, within the periodogram's resolution (1/T in
//! frequency, T the shortest run); otherwise it is not claimed — before
//! any effect is selected or the ambiguity test runs — and is listed
//! untestable with why. (Only the strongest line is tested: a chiller
//! whose line is weaker than another line of the residual is listed, not
//! named.)

use crate::diagnose::effects::periodic_claim::LineCand;
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

/// Why a `coolant` candidate is not confirmed by the periodic test's
/// line `line` (`None`: the test could not run), or None when it is.
fn unconfirmed(p: &Problem, f: &Finding, line: Option<&LineCand>) -> Option<String> {
    let Some(pc) = period(f) else {
        return Some("the fitted cycle has no finite period".into());
    };
    let Some(cand) = line else {
        return Some(format!(
            "a cycle of {pc:.0} s fits the residual, but the periodic line test could not run (the identified model fitted on every row failed), so no line confirms it"
        ));
    };
    let t =
        p.ds.runs
            .iter()
            .map(|r| r.rows() as f64 * r.dt)
            .fold(f64::INFINITY, f64::min);
    let df = if t.is_finite() && t > 0.0 {
        1.0 / t
    } else {
        0.0
    };
    let confirmed = cand
        .as_ref()
        .is_some_and(|(_, l, claimed)| *claimed && same_line(pc, l.period_s, df));
    (!confirmed).then(|| format!(
        "a cycle of {pc:.0} s fits the residual, but the periodic test claims no line at that period in any sensor's residual: the duty's own rhythm or a misfit of the identified model reads as a chiller; a sensor on the coolant circuit, or runs with another duty, would separate them"
    ))
}

/// Takes the claim from every claimed `coolant` candidate the periodic
/// test's line does not confirm; returns their `untestable` entries.
pub(super) fn demote<'a>(
    p: &Problem,
    line: Option<&LineCand>,
    claims: impl Iterator<Item = (&'a Finding, &'a mut bool)>,
) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (f, claimed) in claims {
        if f.name != "coolant" || !*claimed {
            continue;
        }
        if let Some(why) = unconfirmed(p, f, line) {
            *claimed = false;
            out.push(("coolant (no spectral line)".into(), why));
        }
    }
    out
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

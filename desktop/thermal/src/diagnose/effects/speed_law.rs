//! `bearing_nonlinear`: spindle heat steeper in speed than the textbook law
//! (n and n^(5/3)), tested on runs of different speeds against a reference
//! that also carries the spindle's switched inputs, or against the nominal.

use serde_json::json;

use super::candidate::Candidate;
use crate::diagnose::ident::{ModelFit, Problem, Structure};
use crate::diagnose::signal::r4;

/// Distinct speed levels (2 % of the maximum apart) held for ≥ 5 % of the rows.
pub fn speed_levels(p: &Problem) -> Vec<f64> {
    let mut counts: std::collections::BTreeMap<i64, usize> = Default::default();
    let mut total = 0usize;
    for run in &p.ds.runs {
        if let Some(rpm) = &run.rpm {
            for n in rpm {
                total += 1;
                if *n > 0.0 {
                    *counts
                        .entry((n / p.n_max * 50.0).round() as i64)
                        .or_default() += 1;
                }
            }
        }
    }
    counts
        .iter()
        .filter(|(_, c)| **c * 20 >= total)
        .map(|(l, _)| *l as f64 / 50.0 * p.n_max)
        .collect()
}

/// Whether at least two runs differ in their mean running speed by 20 %
/// of the maximum: within one run a steeper speed law is confounded with
/// every other bilinear effect of running (coolant flow, preload).
pub fn runs_of_different_speeds(p: &Problem) -> bool {
    let means: Vec<f64> =
        p.ds.runs
            .iter()
            .filter_map(|r| {
                let v: Vec<f64> = r
                    .rpm
                    .as_ref()?
                    .iter()
                    .copied()
                    .filter(|n| *n > 0.0)
                    .collect();
                (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
            })
            .collect();
    let (lo, hi) = means
        .iter()
        .fold((f64::MAX, f64::MIN), |a, &m| (a.0.min(m), a.1.max(m)));
    means.len() >= 2 && hi - lo >= 0.2 * p.n_max
}

/// Speed levels a speed law needs: through two points every law is a line.
pub const MIN_SPEED_LEVELS: usize = 3;

/// Whether the data can test a speed law: `spindle_rpm`, at least
/// [`MIN_SPEED_LEVELS`] speed levels, and runs of different mean speed.
/// `fitmode::untestable` names whichever condition fails.
fn speed_law_testable(p: &Problem) -> bool {
    p.ds.has_rpm && speed_levels(p).len() >= MIN_SPEED_LEVELS && runs_of_different_speeds(p)
}

/// Exponent of the friction heat in the speed-law test's reference: a
/// bearing's viscous friction torque grows as (ν·n)^(2/3) (Palmgren), its
/// heat as n^(5/3); motor losses and load-dependent friction grow as n.
pub const PALMGREN_EXPONENT: f64 = 5.0 / 3.0;
/// Exponents of the steeper heat the speed-law test tries: above every
/// textbook bearing law (≤ n²), the one the fit rows support best is taken.
pub const STEEP_EXPONENTS: [f64; 3] = [2.5, 3.0, 4.0];

/// The steeper heat's extra columns of run `r`: `(n/n_max)^pw` through each
/// mode's lag (none for a run without `spindle_rpm`).
fn steep_columns(
    ds: &crate::diagnose::runs::Dataset,
    n_max: f64,
    pw: f64,
    modes: Vec<f64>,
) -> impl Fn(usize, usize) -> Vec<Vec<f64>> + Sync + '_ {
    move |_o: usize, r: usize| -> Vec<Vec<f64>> {
        let run = &ds.runs[r];
        let Some(rpm) = &run.rpm else {
            return Vec::new();
        };
        let u: Vec<f64> = rpm.iter().map(|n| (n.abs() / n_max).powf(pw)).collect();
        modes
            .iter()
            .map(|&tau| crate::diagnose::signal::lag(&u, run.dt, tau, 0.0))
            .collect()
    }
}

/// The steeper heat's exponent the fit rows support best against
/// `reference` (structure `st`): for each of `STEEP_EXPONENTS` the extra
/// columns where each output's BIC takes them, the lowest total ΔBIC.
fn steepest_supported(
    p: &Problem,
    st: &Structure,
    reference: &ModelFit,
) -> Option<(f64, ModelFit, Vec<usize>)> {
    let n_fit = reference.n_fit().max(2) as f64;
    STEEP_EXPONENTS
        .iter()
        .filter_map(|&pw| {
            let extra = steep_columns(p.ds, p.n_max, pw, st.modes.clone());
            let (fit, took) = p.fit_where_supported(st, &extra, reference);
            if took.is_empty() {
                return None;
            }
            let dbic = fit.j_fit(&p.outputs) - reference.j_fit(&p.outputs)
                + (st.modes.len() * took.len()) as f64 * n_fit.ln();
            Some((pw, fit, took, dbic))
        })
        .min_by(|a, b| a.3.total_cmp(&b.3))
        .map(|(pw, fit, took, _)| (pw, fit, took))
}

/// Steady-state rise of the extra heat term per sensor (each modal column
/// has unit DC gain), where it is largest, and the bound it ends on when
/// it comes out as cooling (friction only adds heat: c ≥ 0).
fn strongest_extra_heat(
    p: &Problem,
    fit: &ModelFit,
    took: &[usize],
) -> (Option<(usize, f64)>, Vec<String>) {
    let strongest = took
        .iter()
        .filter(|&&o| !p.outputs[o].is_disp)
        .map(|&o| (o, fit.outs[o].extra_coef.iter().sum::<f64>()))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
    let mut at_bound = Vec::new();
    if strongest.is_none_or(|s| s.1 <= 0.0) {
        at_bound.push("extra heat c at its bound 0 (fitted as cooling)".to_string());
    }
    (strongest, at_bound)
}

/// Speed nonlinearity seen across runs of different speeds: spindle heat
/// steeper in speed than the textbook law, `c·(n/n_max)^p` with `p` above
/// 2, through the same modes, on top of a reference that carries the
/// physics every machine has: motor heat ∝ n, bearing heat ∝ n^(5/3)
/// (fixed, not fitted: a free exponent would absorb the steeper heat), and
/// the spindle's switched inputs (`Problem::switch_with_spindle`: running
/// state and running × the leading sensor-rise component, a conductance
/// that flows only while the spindle runs). Returns the candidate and the
/// reference it is scored against. Only the heat must be positive (friction
/// adds heat): the steady rise of the extra term where it is largest.
pub fn speed_nonlinearity<'a>(p: &Problem<'a>) -> Option<(Candidate, ModelFit)> {
    let ds = p.ds;
    if !speed_law_testable(p) {
        return None;
    }
    let mut rp = Problem::new(ds);
    rp.exponents = vec![PALMGREN_EXPONENT];
    rp.switch_with_spindle(1);
    rp.removes_heat = true;
    let (st, reference) = rp.identify();
    if reference.outs.iter().any(|f| f.failed) {
        return None;
    }
    let n_max = p.n_max;
    let (pw, _, _) = steepest_supported(&rp, &st, &reference)?;
    // the alternative identified as the reference is (its own order): the
    // steeper heat as a third spindle input
    let mut ap = Problem::new(ds);
    ap.exponents = vec![PALMGREN_EXPONENT];
    ap.steep = Some(pw);
    ap.switch_with_spindle(1);
    ap.removes_heat = true;
    let (st1, _) = ap.identify();
    let extra = steep_columns(ds, n_max, pw, st1.modes.clone());
    let (fit, took) = rp.fit_where_supported(&st1, &extra, &reference);
    if took.is_empty() {
        return None;
    }
    let (strongest, at_bound) = strongest_extra_heat(p, &fit, &took);
    let i_pw = STEEP_EXPONENTS.iter().position(|&e| e == pw).unwrap_or(0);
    let lo_hi = (
        STEEP_EXPONENTS[0],
        STEEP_EXPONENTS[STEEP_EXPONENTS.len() - 1],
    );
    let cand = Candidate {
        name: "bearing_nonlinear",
        params: json!({
            "exponent": pw,
            "reference_exponent": r4(PALMGREN_EXPONENT),
            "sensor": strongest.map(|(o, _)| p.outputs[o].name.clone()),
            "extra_rise_c": strongest.map(|(_, g)| r4(g)),
        }),
        // the coefficients the alternative adds where it was taken (its
        // order may differ from the reference's), and the exponent's choice
        k_extra: took
            .iter()
            .map(|&o| fit.outs[o].k.saturating_sub(reference.outs[o].k))
            .sum::<usize>()
            + 1,
        affected: took,
        fit,
        at_bound,
        evidence: json!({
            "speed_levels_rpm": speed_levels(p).iter().map(|v| v.round()).collect::<Vec<_>>(),
            "driver": format!("extra spindle heat c·(n/n_max)^{pw} (exponent {} of {:?} by fit-row BIC{}) through the modes of the model identified with it (order {})", i_pw + 1, STEEP_EXPONENTS, if i_pw == STEEP_EXPONENTS.len() - 1 { format!(", the steepest tried ({}..{})", lo_hi.0, lo_hi.1) } else { String::new() }, st1.modes.len()),
            "reference": format!("identified again with motor heat ∝ n, Palmgren bearing heat ∝ n^(5/3) and inputs switched with the spindle (running state, running × leading sensor-rise component): order {}", st.modes.len()),
            "strongest_sensor": strongest.map(|(o, _)| p.outputs[o].name.clone()),
            "steady_rise_c": strongest.map(|(_, g)| r4(g)),
        }),
    };
    Some((cand, reference))
}

/// The speed law against the nominal itself (`a·n + b·n^e`, `e` of the
/// textbook laws chosen by BIC): the steeper heat through the nominal's own
/// modes, taken by each output whose BIC it improves. Where the switched
/// reference of `speed_nonlinearity` fits a machine worse than the nominal
/// (its bilinear term does not suit every machine), this one still tests
/// the law; being against a nominal that may absorb part of it, it is
/// claimed only when it leaves at most `SPEED_CLAIM_REL` of the held-out gap.
pub fn speed_nonlinearity_against_nominal(
    p: &Problem,
    st: &Structure,
    nom: &ModelFit,
) -> Option<Candidate> {
    if !speed_law_testable(p) {
        return None;
    }
    let (pw, fit, took) = steepest_supported(p, st, nom)?;
    let (strongest, at_bound) = strongest_extra_heat(p, &fit, &took);
    Some(Candidate {
        name: "bearing_nonlinear",
        params: json!({
            "exponent": pw,
            "reference_exponent": st.exponent,
            "sensor": strongest.map(|(o, _)| p.outputs[o].name.clone()),
            "extra_rise_c": strongest.map(|(_, g)| r4(g)),
        }),
        k_extra: st.modes.len() * took.len() + 1,
        affected: took,
        fit,
        at_bound,
        evidence: json!({
            "speed_levels_rpm": speed_levels(p).iter().map(|v| v.round()).collect::<Vec<_>>(),
            "driver": format!("extra spindle heat c·(n/n_max)^{pw} (of {:?} by fit-row BIC) through the nominal's modes", STEEP_EXPONENTS),
            "reference": format!("the nominal: motor heat ∝ n and friction heat ∝ n^{} (chosen by BIC of {:?})", st.exponent, crate::diagnose::ident::EXPONENTS),
            "against_nominal": true,
            "strongest_sensor": strongest.map(|(o, _)| p.outputs[o].name.clone()),
            "steady_rise_c": strongest.map(|(_, g)| r4(g)),
        }),
    })
}

//! Never build on an inadequate model (issue 49 item 2): one stated test of
//! a linear least-squares identification against the readings' stated
//! noise, used by `identify` (lines, held out one line at a time) and
//! `identify-rotary` (R-test files, held out one file at a time).
//!
//! **The test.** The design rows and readings come whitened (each divided
//! by its reading's stated σ), so under an adequate model the noise is
//! white with unit variance. Two statistics, each at 0.5 % false reject
//! (so at most [`FALSE_REJECT`] = 1 % together, Bonferroni):
//!
//! 1. the fit residual: χ² = Σ r² against the chi-square distribution with
//!    `dof` = readings − rank degrees of freedom (every unknown, the
//!    lines' zeros and the files' offsets included);
//! 2. the hold-out prediction: each group (line, file) predicted by the
//!    model fitted to the others. Directions only that group sees (the
//!    14-line plan has no line to spare; a file's own offsets) are fitted
//!    to the group itself, everything else is predicted. Under an adequate
//!    model the hold-out residual of group k is r_k = Q_k (e_k − X_k P_{−k}
//!    e_{−k}) (Q_k: the projection off the group's own directions, P_{−k}
//!    the others' pseudo-inverse), so its sum of squares has the exact mean
//!    Σ_k tr M_k with M_k = Q_k (I + X_k Σ_{−k} X_kᵀ) Q_k — the *expected
//!    inflation* of a hold-out prediction over the noise (on the 14-line
//!    plan about 1.2–1.3×: each line is predicted from 13 others, with
//!    their noise) — and variance ≈ 2 Σ_k ‖M_k‖²_F (the correlation
//!    between groups through shared data is neglected; measured false
//!    rejects on the identifier's own class: docs/geometry.md). Its 99.5 %
//!    point is Satterthwaite's scaled chi-square. So the limit on the
//!    hold-out RMS is k × noise with k = √(q_99.5 / n) computed for the
//!    plan at hand, not a constant: it is the expected inflation times the
//!    sampling allowance (about 1.1 for 560 readings).
//!
//! Both limits are taken at the stated noise × [`NOISE_TOLERANCE`] (1.2).
//!
//! **Inflation.** A model that fails (or nearly fails) leaves a misfit the
//! posterior σ's know nothing of: they are multiplied by
//! f = max(1, Birge ratio √(χ²/dof), hold-out RMS / its expected RMS).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::unit_svd::{complete_basis, unit_svd};

/// Documented default reading noise [µm], one reading of one run (the
/// laser interferometer of the line plans, the R-test's sensors): used when
/// the user gives no `--noise-um`, and said so.
pub const DEFAULT_NOISE_UM: f64 = 0.5;

/// Overall false-reject probability of the test on an adequate model
/// (two statistics at half of it each).
pub const FALSE_REJECT: f64 = 0.01;

/// The test asks whether the misfit is *materially* above the stated
/// noise: the noise is scaled by this before the two limits (an unmodelled
/// part up to √(1.2² − 1) = 0.66 σ in quadrature passes). A stated noise is
/// rarely known better than 20 %, and the independent line writer's own
/// class (setup errors: beam misalignment, reflector position) leaves
/// 1.06–1.09× the bare noise.
pub const NOISE_TOLERANCE: f64 = 1.2;

/// Standard normal quantile at 1 − FALSE_REJECT / 2 = 0.995.
const Z_995: f64 = 2.575_829;

/// Relative singular value below which a direction of the identification
/// counts as weakly determined and is named (`weak` below): its σ is more
/// than 100× that of the best-determined direction.
pub const WEAK_TOL: f64 = 1e-2;

/// The stated noise: given by the user or the documented default.
#[derive(Clone, Copy, Debug)]
pub struct StatedNoise {
    pub um: f64,
    pub given: bool,
}

impl StatedNoise {
    pub fn new(noise_um: Option<f64>) -> Result<StatedNoise> {
        match noise_um {
            Some(v) if !(v > 0.0 && v.is_finite()) => {
                bail!("--noise-um must be a positive number of µm, got {v}")
            }
            Some(v) => Ok(StatedNoise { um: v, given: true }),
            None => Ok(StatedNoise {
                um: DEFAULT_NOISE_UM,
                given: false,
            }),
        }
    }
    /// Where the noise comes from, for the report.
    pub fn source(&self) -> String {
        if self.given {
            "given (--noise-um)".into()
        } else {
            format!(
                "the documented default {DEFAULT_NOISE_UM} µm per reading (no --noise-um given)"
            )
        }
    }
}

/// The verdict, as written into model files (`"adequacy"`) and reports.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adequacy {
    pub adequate: bool,
    /// Stated noise of one reading [µm] and where it came from.
    pub noise_um: f64,
    pub noise_source: String,
    /// Whitened residual sum of squares, its degrees of freedom and its
    /// limit (chi-square, 99.5 %).
    pub chi2: f64,
    pub dof: usize,
    pub chi2_limit: f64,
    /// √(χ²/dof): the noise the fit implies over the stated one.
    pub birge_ratio: f64,
    /// `leave-one-line-out` or `leave-one-file-out`.
    pub holdout: String,
    pub holdout_groups: usize,
    /// RMS of the held-out predictions [µm], what an adequate model gives
    /// (the expected inflation over the noise included), and the limit.
    pub holdout_rms_um: f64,
    pub holdout_expected_rms_um: f64,
    pub holdout_limit_rms_um: f64,
    /// The limit as a multiple of the noise of the held-out readings (k).
    pub holdout_k: f64,
    /// Hold-out RMS over its expected value.
    pub holdout_ratio: f64,
    /// The factor the posterior σ's are multiplied by.
    pub sigma_inflation: f64,
    pub false_reject: f64,
    /// Directions the data determine weakly (relative singular value
    /// below 1e-2), named by the errors that combine in them.
    pub weak: Vec<Weak>,
    /// One line: what failed and by how much (empty when adequate).
    pub failure: String,
}

/// One weakly determined combination.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Weak {
    /// In words: which errors combine, e.g. "EAZ − ECZ (with EBZ)".
    pub words: String,
    pub relative_singular_value: f64,
    pub terms: Vec<String>,
}

/// Outcome of [`assess`]: the verdict and the full fit's posterior
/// covariance of the unknowns for unit noise (multiply by the inflation
/// squared; the rows were whitened, so it is in the unknowns' units²).
pub struct Assessment {
    pub adequacy: Adequacy,
    pub covariance: DMatrix<f64>,
}

/// The least-squares problem to test.
pub struct Problem<'a> {
    /// Whitened design and readings.
    pub a: &'a DMatrix<f64>,
    pub b: &'a DVector<f64>,
    /// Row sets held out in turn; rows in none are always fitted.
    pub groups: &'a [Vec<usize>],
    /// Relative singular value (unit-norm columns) of a null direction.
    pub rank_tol: f64,
    /// Noise of the held-out rows [µm] (to report RMS in µm).
    pub holdout_sigma_um: f64,
    /// Name of each unknown's error term (`EAZ`, `XOC`, …; empty: not an
    /// error, e.g. a line's zero) for naming weak directions.
    pub labels: &'a [String],
    pub holdout: &'a str,
}

/// Truncated SVD with unit-norm columns.
struct Tsvd {
    norms: Vec<f64>,
    /// (unit-norm-space right vector, singular value, left vector) kept.
    keep: Vec<(DVector<f64>, f64, DVector<f64>)>,
    /// Null directions in the original scale.
    null: Vec<DVector<f64>>,
    /// (relative singular value, unit-space vector) of every kept direction.
    all: Vec<(f64, DVector<f64>)>,
}

fn tsvd(a: &DMatrix<f64>, tol: f64) -> Result<Tsvd> {
    let (m, n) = a.shape();
    let (norms, u, vt, sv) = unit_svd(a)?;
    let smax = sv.iter().copied().fold(0.0, f64::max);
    let mut keep = Vec::new();
    let mut null_unit: Vec<DVector<f64>> = Vec::new();
    let mut all = Vec::new();
    for i in 0..sv.len() {
        let v = vt.row(i).transpose();
        if smax > 0.0 && sv[i] > tol * smax {
            all.push((sv[i] / smax, v.clone()));
            keep.push((v, sv[i], u.column(i).into_owned()));
        } else {
            null_unit.push(v);
        }
    }
    if m < n {
        let mut basis: Vec<DVector<f64>> = keep.iter().map(|k| k.0.clone()).collect();
        basis.extend(null_unit.iter().cloned());
        null_unit.extend(complete_basis(&mut basis, n));
    }
    let null = null_unit
        .into_iter()
        .map(|v| DVector::from_fn(n, |j, _| v[j] / norms[j]))
        .collect();
    Ok(Tsvd {
        norms,
        keep,
        null,
        all,
    })
}

impl Tsvd {
    fn solve(&self, b: &DVector<f64>) -> DVector<f64> {
        let n = self.norms.len();
        let mut x = DVector::zeros(n);
        for (v, s, u) in &self.keep {
            x += v * (u.dot(b) / s);
        }
        DVector::from_fn(n, |j, _| x[j] / self.norms[j])
    }
    /// (AᵀA)⁺ in the original scale.
    fn covariance(&self) -> DMatrix<f64> {
        let n = self.norms.len();
        let mut c = DMatrix::zeros(n, n);
        for (v, s, _) in &self.keep {
            c += v * v.transpose() / (s * s);
        }
        DMatrix::from_fn(n, n, |i, j| c[(i, j)] / (self.norms[i] * self.norms[j]))
    }
}

/// Upper quantile of a chi-square with `h` (not necessarily integer)
/// degrees of freedom at 1 − FALSE_REJECT/2 (Wilson–Hilferty; within
/// 0.5 % of the exact value from 10 degrees of freedom on).
pub fn chi2_upper(h: f64) -> f64 {
    let c = 2.0 / (9.0 * h);
    h * (1.0 - c + Z_995 * c.sqrt()).powi(3)
}

/// Test `p` (module doc) and give the verdict with the posterior
/// covariance of the full fit.
pub fn assess(p: &Problem, noise: StatedNoise) -> Result<Assessment> {
    let (m, n) = p.a.shape();
    let full = tsvd(p.a, p.rank_tol)?;
    let x = full.solve(p.b);
    let resid = p.b - p.a * &x;
    let chi2 = resid.norm_squared();
    let dof = m.saturating_sub(full.keep.len()).max(1);
    let chi2_limit = chi2_upper(dof as f64) * NOISE_TOLERANCE * NOISE_TOLERANCE;
    let birge = (chi2 / dof as f64).sqrt();

    let (mut ss, mut cnt, mut mean, mut var) = (0.0, 0usize, 0.0, 0.0);
    let mut used = 0usize;
    for g in p.groups {
        if g.is_empty() {
            continue;
        }
        let mut in_g = vec![false; m];
        g.iter().for_each(|&i| in_g[i] = true);
        let rest: Vec<usize> = (0..m).filter(|&i| !in_g[i]).collect();
        let ar = p.a.select_rows(&rest);
        let br = p.b.select_rows(&rest);
        let sub = tsvd(&ar, p.rank_tol)?;
        let xs = sub.solve(&br);
        let ak = p.a.select_rows(g);
        let bk = p.b.select_rows(g);
        let r = &bk - &ak * &xs;
        // The group's own directions: what only it sees.
        let cols: Vec<DVector<f64>> = sub
            .null
            .iter()
            .map(|v| &ak * v)
            .filter(|c| c.norm() > 1e-9)
            .collect();
        let nk = g.len();
        let q = if cols.is_empty() {
            DMatrix::identity(nk, nk)
        } else {
            let gm = DMatrix::from_columns(&cols);
            let svd = gm.svd(true, false);
            let u = svd.u.as_ref().expect("u requested");
            let smax = svd.singular_values.max();
            let mut q = DMatrix::identity(nk, nk);
            for i in 0..svd.singular_values.len() {
                if svd.singular_values[i] > 1e-10 * smax {
                    let c = u.column(i);
                    q -= c * c.transpose();
                }
            }
            q
        };
        let rq = &q * r;
        ss += rq.norm_squared();
        cnt += nk;
        let cov = sub.covariance();
        let mk = &q * (DMatrix::identity(nk, nk) + &ak * cov * ak.transpose()) * &q;
        mean += mk.trace();
        var += 2.0 * mk.norm_squared();
        used += 1;
    }
    let s = p.holdout_sigma_um;
    let (holdout_rms, expected_rms, limit_rms, k, ratio) = if cnt > 0 && mean > 0.0 {
        let g = var / (2.0 * mean);
        let h = 2.0 * mean * mean / var.max(1e-300);
        let q = g * chi2_upper(h);
        (
            s * (ss / cnt as f64).sqrt(),
            s * (mean / cnt as f64).sqrt(),
            s * NOISE_TOLERANCE * (q / cnt as f64).sqrt(),
            NOISE_TOLERANCE * (q / cnt as f64).sqrt(),
            (ss / mean).sqrt(),
        )
    } else {
        (0.0, 0.0, 0.0, 0.0, 0.0)
    };
    let chi_fail = chi2 > chi2_limit;
    let hold_fail = cnt > 0 && holdout_rms > limit_rms;
    let mut parts = Vec::new();
    if chi_fail {
        parts.push(format!(
            "the fit residual is {birge:.2}× the stated noise {:.3} µm (χ² {chi2:.0} on {dof} degrees of freedom, limit {chi2_limit:.0})",
            noise.um
        ));
    }
    if hold_fail {
        parts.push(format!(
            "{} {} predicts to {holdout_rms:.3} µm RMS, {ratio:.1}× what an adequate model gives ({expected_rms:.3} µm; limit {limit_rms:.3} µm = {k:.2}× the noise)",
            p.holdout,
            if p.holdout.contains("line") { "(each line from the others)" } else { "(each file from the others)" }
        ));
    }
    let inflation = 1f64.max(birge).max(ratio);
    let weak = name_weak(&full, p.labels);
    let _ = n;
    Ok(Assessment {
        adequacy: Adequacy {
            adequate: !(chi_fail || hold_fail),
            noise_um: noise.um,
            noise_source: noise.source(),
            chi2,
            dof,
            chi2_limit,
            birge_ratio: birge,
            holdout: p.holdout.to_string(),
            holdout_groups: used,
            holdout_rms_um: holdout_rms,
            holdout_expected_rms_um: expected_rms,
            holdout_limit_rms_um: limit_rms,
            holdout_k: k,
            holdout_ratio: ratio,
            sigma_inflation: inflation,
            false_reject: FALSE_REJECT,
            weak,
            failure: parts.join("; "),
        },
        covariance: full.covariance(),
    })
}

/// The weakly determined directions of the full fit, in words.
fn name_weak(t: &Tsvd, labels: &[String]) -> Vec<Weak> {
    let mut out = Vec::new();
    let mut dirs: Vec<&(f64, DVector<f64>)> = t.all.iter().filter(|d| d.0 < WEAK_TOL).collect();
    dirs.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (s, v) in dirs.into_iter().take(6) {
        if let Some(w) = words(v, labels) {
            out.push(Weak {
                words: w.0,
                relative_singular_value: *s,
                terms: w.1,
            });
        }
    }
    out
}

/// "EAZ − ECZ (with EBZ)" for a unit vector: per error its largest weight;
/// those above 0.3 of the largest combine, those from 0.1 are "with".
pub fn words(v: &DVector<f64>, labels: &[String]) -> Option<(String, Vec<String>)> {
    let mut per: Vec<(String, f64)> = Vec::new();
    for (j, w) in v.iter().enumerate() {
        let Some(l) = labels.get(j).filter(|l| !l.is_empty()) else {
            continue;
        };
        match per.iter_mut().find(|(n, _)| n == l) {
            Some(e) if e.1.abs() < w.abs() => e.1 = *w,
            Some(_) => {}
            None => per.push((l.clone(), *w)),
        }
    }
    per.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let top = per.first()?.1;
    if top.abs() < 1e-9 {
        return None;
    }
    let sign = top.signum();
    let mut main = String::new();
    let mut with = Vec::new();
    let mut terms = Vec::new();
    for (name, w) in &per {
        let r = w.abs() / top.abs();
        if r >= 0.3 {
            if main.is_empty() {
                main = name.clone();
            } else {
                main += if w * sign > 0.0 { " + " } else { " − " };
                main += name;
            }
            terms.push(name.clone());
        } else if r >= 0.1 && with.len() < 3 {
            with.push(name.clone());
            terms.push(name.clone());
        }
    }
    if !with.is_empty() {
        main += &format!(" (with {})", with.join(", "));
    }
    Some((main, terms))
}

impl Adequacy {
    /// The one-line refusal (or, with `--accept-inadequate`, warning).
    pub fn refusal(&self, what: &str, remedy: &str) -> String {
        format!(
            "{what} is inadequate: {} (stated noise {:.3} µm: {}, test at {} % false reject); {remedy}, or give --accept-inadequate to go on (σ's are then inflated ×{:.1})",
            self.failure,
            self.noise_um,
            self.noise_source,
            self.false_reject * 100.0,
            self.sigma_inflation
        )
    }
    /// One report line whatever the verdict.
    pub fn summary(&self) -> String {
        format!(
            "adequacy ({} % false reject; noise {:.3} µm, {}): residual {:.2}× the noise (χ² {:.0} / {} dof, limit {:.0}); {} {:.3} µm RMS, {:.2}× its expected {:.3} µm (limit {:.3} µm = {:.2}× the noise); σ's inflated ×{:.2} — {}",
            self.false_reject * 100.0,
            self.noise_um,
            self.noise_source,
            self.birge_ratio,
            self.chi2,
            self.dof,
            self.chi2_limit,
            self.holdout,
            self.holdout_rms_um,
            self.holdout_ratio,
            self.holdout_expected_rms_um,
            self.holdout_limit_rms_um,
            self.holdout_k,
            self.sigma_inflation,
            if self.adequate { "adequate" } else { "INADEQUATE" }
        )
    }
}

/// What a command that uses a model file does with the file's verdict:
/// `Ok(None)` adequate, `Ok(Some(warning))` unknown (an older file
/// without it) or inadequate but accepted, `Err` inadequate.
pub fn check_model_file(
    adequate: Option<bool>,
    path: &std::path::Path,
    accept: bool,
    failure: Option<&str>,
) -> Result<Option<String>> {
    match adequate {
        Some(true) => Ok(None),
        None => Ok(Some(format!(
            "{}: no adequacy verdict (not written by identify/identify-rotary, or from before the test): adequacy unknown, used as it is",
            path.display()
        ))),
        Some(false) if accept => Ok(Some(format!(
            "{}: the model is inadequate{}; going on (--accept-inadequate)",
            path.display(),
            failure.map(|f| format!(" ({f})")).unwrap_or_default()
        ))),
        Some(false) => bail!(
            "{}: the model is inadequate{}; measure more lines: `tcomp geometry plan`, or give --accept-inadequate to go on",
            path.display(),
            failure.map(|f| format!(" ({f})")).unwrap_or_default()
        ),
    }
}

/// [`check_model_file`] for any JSON file with a top-level `"adequate"`
/// (and `"adequacy"."failure"`): an errors file, a volumetric table, a
/// rotary model.
pub fn check_json_file(path: &std::path::Path, accept: bool) -> Result<Option<String>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    check_model_file(
        v.get("adequate").and_then(|x| x.as_bool()),
        path,
        accept,
        v.pointer("/adequacy/failure").and_then(|x| x.as_str()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_quantile_matches_tables() {
        // χ²_0.995 for 10, 100, 500 degrees of freedom: 25.19, 140.17, 585.21
        for (h, q) in [(10.0, 25.188), (100.0, 140.169), (500.0, 585.207)] {
            assert!(
                (chi2_upper(h) / q - 1.0).abs() < 0.005,
                "{h}: {}",
                chi2_upper(h)
            );
        }
    }

    /// A straight line fitted to straight data with unit noise passes; to
    /// a parabola well above the noise, it fails both ways.
    #[test]
    fn a_line_holds_a_line_and_not_a_parabola() {
        let mut rng = tcomp_numerics::rng::Rng::new(3);
        let m = 200;
        let a = DMatrix::from_fn(m, 2, |i, j| if j == 0 { 1.0 } else { i as f64 / m as f64 });
        let groups: Vec<Vec<usize>> = (0..10).map(|g| (g * 20..g * 20 + 20).collect()).collect();
        let labels = vec!["c".to_string(), "s".to_string()];
        let noise = StatedNoise::new(Some(1.0)).unwrap();
        let run = |curv: f64, rng: &mut tcomp_numerics::rng::Rng| {
            let b = DVector::from_fn(m, |i, _| {
                let u = i as f64 / m as f64;
                1.0 + 2.0 * u + curv * (u - 0.5).powi(2) + rng.normal()
            });
            let p = Problem {
                a: &a,
                b: &b,
                groups: &groups,
                rank_tol: 1e-6,
                holdout_sigma_um: 1.0,
                labels: &labels,
                holdout: "leave-one-group-out",
            };
            assess(&p, noise).unwrap().adequacy
        };
        let ok = run(0.0, &mut rng);
        assert!(ok.adequate, "{ok:?}");
        assert!(ok.holdout_expected_rms_um > 1.0 && ok.holdout_expected_rms_um < 1.1);
        let bad = run(40.0, &mut rng);
        assert!(!bad.adequate, "{bad:?}");
        assert!(bad.sigma_inflation > 2.0, "{bad:?}");
    }
}

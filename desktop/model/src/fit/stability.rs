//! The stability guard of the choice (issue 50): how collinear a model's
//! inputs are (condition number, variance inflation) and how much a linear
//! candidate's coefficients move across the cross-validation folds; a
//! candidate whose coefficients flip sign or change by more than
//! [`CHANGE_FACTOR`] is not chosen over a stabler one within noise.
//!
//! Why: two near-collinear inputs fitted with large opposite coefficients
//! cancel inside the training envelope and amplify any change of their
//! difference outside it. The folds are the cheapest witness: each refits
//! the model on most of the same rows, so a coefficient that swings
//! between folds is not determined by the data, and what it does beyond
//! the training envelope is not either.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, SymmetricEigen};
use serde::Serialize;

use super::choice::CvScore;
use super::model::FeatureSpec;
use super::samples::{normalize_rows, Samples};

/// A coefficient is material when, in some fold, it reaches this share of
/// the target's standard deviation per standard deviation of its input
/// (smaller ones move predictions by less than a tenth of the signal: their
/// sign and size are left to noise).
pub const MATERIAL_SHARE: f64 = 0.1;

/// A material coefficient may vary across the folds by at most this factor
/// (largest |b| / smallest |b|) and must keep its sign.
pub const CHANGE_FACTOR: f64 = 3.0;

/// How one linear candidate's coefficients moved across the CV folds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Stability {
    /// No material coefficient flips sign or changes by more than [`CHANGE_FACTOR`].
    pub stable: bool,
    /// The worst input's largest |b| / smallest |b| over the folds (`None`:
    /// no material coefficient, or a sign flip: unbounded).
    pub worst_factor: Option<f64>,
    /// A material coefficient changes sign between folds.
    pub sign_flip: bool,
    /// The worst input and its smallest and largest standardised
    /// coefficient over the folds (µm per standard deviation of the input).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_input: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coef_range_um: Option<(f64, f64)>,
    /// Folds compared.
    pub folds: usize,
}

impl Stability {
    /// The rank the rule compares, three levels and no finer (two unstable
    /// candidates whose factors differ a little are not told apart by
    /// noise): 0 stable, 1 a material coefficient changes by more than
    /// [`CHANGE_FACTOR`], 2 one flips sign.
    pub fn level(&self) -> u8 {
        match (self.stable, self.sign_flip) {
            (true, _) => 0,
            (false, false) => 1,
            (false, true) => 2,
        }
    }
}

/// Assess the standardised coefficients `fold_coefs[fold][input]` of one
/// candidate (`names` its inputs); `y_sd` is the target's standard
/// deviation on the training rows. Fewer than two folds: stable (nothing
/// to compare).
pub fn assess(names: &[String], fold_coefs: &[Vec<f64>], y_sd: f64) -> Stability {
    let mut out = Stability {
        stable: true,
        folds: fold_coefs.len(),
        ..Stability::default()
    };
    if fold_coefs.len() < 2 {
        return out;
    }
    let floor = MATERIAL_SHARE * y_sd;
    let mut worst = (0.0f64, false);
    for (j, name) in names.iter().enumerate() {
        let b: Vec<f64> = fold_coefs
            .iter()
            .filter_map(|c| c.get(j).copied())
            .collect();
        let big = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if b.len() < 2 || !(big >= floor) {
            continue;
        }
        let (lo, hi) = b
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(*v), h.max(*v))
            });
        let flip = lo < 0.0 && hi > 0.0;
        let small = b.iter().fold(f64::INFINITY, |m, v| m.min(v.abs()));
        let factor = if flip {
            f64::INFINITY
        } else {
            big / small.max(1e-300)
        };
        if (flip, factor) > (worst.1, worst.0) || out.worst_input.is_none() {
            worst = (factor, flip);
            out.worst_input = Some(name.clone());
            out.coef_range_um = Some((lo, hi));
        }
    }
    out.sign_flip = worst.1;
    out.worst_factor = (out.worst_input.is_some() && !worst.1).then_some(worst.0);
    out.stable = !out.sign_flip && worst.0 <= CHANGE_FACTOR;
    out
}

/// Whether candidate `s`'s CV error is within noise of `u`'s: its pooled
/// RMS within the choice margin, or (the one-standard-error rule) the mean
/// over the folds of its fold MSE minus `u`'s no larger than the standard
/// error of that mean (same folds only).
pub fn within_noise(s: &CvScore, u: &CvScore, margin: f64) -> bool {
    if s.rms_um <= u.rms_um * (1.0 + margin) {
        return true;
    }
    let k = s.fold_rms_um.len();
    if k < 2 || k != u.fold_rms_um.len() {
        return false;
    }
    let d: Vec<f64> = s
        .fold_rms_um
        .iter()
        .zip(&u.fold_rms_um)
        .map(|(a, b)| a * a - b * b)
        .collect();
    let mean = d.iter().sum::<f64>() / k as f64;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1) as f64;
    mean <= (var / k as f64).sqrt()
}

/// The stability rule: every candidate of `cv` that `stab` assesses as
/// unstable is removed when a stabler candidate, one of a lower
/// [`Stability::level`] (`none`, which has no coefficient, is level 0), is
/// within noise of it ([`within_noise`]). Candidates `stab` does not assess
/// (the networks) are neither removed nor taken as stabler. Returns
/// `(removed, in favour of)`.
pub fn stability_rule(
    cv: &mut BTreeMap<String, CvScore>,
    stab: &BTreeMap<String, Stability>,
    margin: f64,
) -> Vec<(String, String)> {
    let level = |n: &str| {
        if n == "none" {
            Some(0)
        } else {
            stab.get(n).map(Stability::level)
        }
    };
    let mut out = Vec::new();
    for (u, su) in cv.iter() {
        let Some(st) = stab.get(u).filter(|s| !s.stable) else {
            continue;
        };
        let better = cv.iter().filter(|(s, ss)| {
            level(s).is_some_and(|x| x < st.level()) && within_noise(ss, su, margin)
        });
        // The stabler candidate with the lowest CV error.
        if let Some((s, _)) = better.min_by(|a, b| a.1.rms_um.total_cmp(&b.1.rms_um)) {
            out.push((u.clone(), s.clone()));
        }
    }
    for (u, _) in &out {
        cv.remove(u);
    }
    out
}

/// How collinear a model's inputs are on its training rows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Collinearity {
    /// √(λmax/λmin) of the inputs' correlation matrix: the condition number
    /// of the standardised inputs (1: orthogonal; `None`: singular).
    pub condition_number: Option<f64>,
    /// The largest variance inflation factor, 1/(1 − R²) of an input on the
    /// others (`None`: singular), and whose it is.
    pub max_vif: Option<f64>,
    pub max_vif_input: Option<String>,
}

/// [`Collinearity`] of the inputs `specs` on the rows `rows` (normalised
/// as the models see them); `None` for fewer than one input or two rows.
pub fn collinearity(specs: &[FeatureSpec], rows: &Samples) -> Option<Collinearity> {
    let p = specs.len();
    let xn = normalize_rows(specs, &rows.x);
    let n = xn.len();
    if p == 0 || n < 2 {
        return None;
    }
    let mean: Vec<f64> = (0..p)
        .map(|j| xn.iter().map(|r| r[j]).sum::<f64>() / n as f64)
        .collect();
    let sd: Vec<f64> = (0..p)
        .map(|j| (xn.iter().map(|r| (r[j] - mean[j]).powi(2)).sum::<f64>() / n as f64).sqrt())
        .collect();
    let mut c = DMatrix::<f64>::zeros(p, p);
    for r in &xn {
        for a in 0..p {
            for b in 0..p {
                let za = if sd[a] > 0.0 {
                    (r[a] - mean[a]) / sd[a]
                } else {
                    0.0
                };
                let zb = if sd[b] > 0.0 {
                    (r[b] - mean[b]) / sd[b]
                } else {
                    0.0
                };
                c[(a, b)] += za * zb / n as f64;
            }
        }
    }
    let eig = SymmetricEigen::new(c.clone()).eigenvalues;
    let (lo, hi) = (eig.min(), eig.max());
    let singular = !(lo > hi * 1e-14);
    let condition_number = (!singular).then(|| (hi / lo).sqrt());
    let inv = if singular { None } else { c.try_inverse() };
    let (max_vif, max_vif_input) = match inv {
        Some(inv) => {
            let (j, v) = (0..p)
                .map(|j| (j, inv[(j, j)]))
                .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
            (Some(v), Some(specs[j].name()))
        }
        None => (None, None),
    };
    Some(Collinearity {
        condition_number,
        max_vif,
        max_vif_input,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(k: usize) -> Vec<String> {
        (0..k).map(|i| format!("x{i}")).collect()
    }

    #[test]
    fn a_sign_flip_of_a_material_coefficient_is_unstable_a_small_one_is_not() {
        let flips = vec![vec![2.0, 0.5], vec![-1.5, 0.6], vec![1.8, 0.55]];
        let s = assess(&names(2), &flips, 1.0);
        assert!(!s.stable && s.sign_flip);
        assert_eq!(s.worst_input.as_deref(), Some("x0"));
        // The same flip far below a tenth of the target's spread: noise.
        let s = assess(&names(2), &flips, 100.0);
        assert!(s.stable && !s.sign_flip);
        let steady = vec![vec![2.0, 0.5], vec![1.9, 0.6], vec![2.2, 0.45]];
        assert!(assess(&names(2), &steady, 1.0).stable);
        let grows = vec![vec![0.4, 0.5], vec![1.9, 0.6]];
        let s = assess(&names(2), &grows, 1.0);
        assert!(!s.stable && !s.sign_flip && s.worst_factor.unwrap() > CHANGE_FACTOR);
    }

    #[test]
    fn an_unstable_candidate_gives_way_only_to_a_stabler_one_within_noise() {
        let sc = |folds: &[f64]| CvScore {
            rms_um: (folds.iter().map(|f| f * f).sum::<f64>() / folds.len() as f64).sqrt(),
            fold_rms_um: folds.to_vec(),
            ..CvScore::default()
        };
        let unstable = Stability {
            stable: false,
            sign_flip: true,
            ..Stability::default()
        };
        let stable = Stability {
            stable: true,
            folds: 3,
            ..Stability::default()
        };
        let mut cv = BTreeMap::new();
        cv.insert("mlr".to_string(), sc(&[1.0, 1.0, 1.0]));
        cv.insert("ridge".to_string(), sc(&[1.01, 1.0, 1.0]));
        cv.insert("none".to_string(), sc(&[5.0, 6.0, 7.0]));
        let stab = BTreeMap::from([
            ("mlr".to_string(), unstable.clone()),
            ("ridge".to_string(), stable),
        ]);
        let mut c = cv.clone();
        assert_eq!(
            stability_rule(&mut c, &stab, 0.02),
            vec![("mlr".to_string(), "ridge".to_string())]
        );
        // Ridge unstable too, though less so: not stabler, mlr stays.
        let grows = Stability {
            stable: false,
            ..Stability::default()
        };
        let both = BTreeMap::from([
            ("mlr".to_string(), grows.clone()),
            ("ridge".to_string(), grows),
        ]);
        assert!(stability_rule(&mut cv.clone(), &both, 0.02).is_empty());
        // Ridge far worse on every fold: mlr stays.
        cv.insert("ridge".to_string(), sc(&[2.0, 2.1, 2.2]));
        let mut c = cv.clone();
        assert!(stability_rule(&mut c, &stab, 0.02).is_empty());
        assert!(c.contains_key("mlr"));
    }
}

//! Identification with no shape assumed (issue 29): every error function
//! in a rich basis (shifted Legendre polynomials up to degree `degree`,
//! zero at the axis zero; straightness also zero at the stroke's end, the
//! ISO end-point reference), a per-line laser scale (ppm) with its own
//! prior, the three squareness errors; a Gaussian prior whose strengths
//! are chosen from the data by maximising the marginal likelihood
//! (evidence) — noise σ, one size for positioning, straightness and angles,
//! and how fast the size falls with the order (coefficient j has prior
//! standard deviation τ·j^(−p)). Nothing is tuned by hand per machine.
//!
//! Reported beside the fit: effective number of parameters, the noise the
//! evidence found, leave-one-line-out prediction error (each line predicted
//! by the model identified from the other 13), per-line scale, and per
//! error the posterior standard deviation (RMS over the stroke): an error
//! whose two posterior standard deviations exceed the stated tolerance
//! (1 µm, 4 µrad) is marked
//! `unobservable` (the lines do not determine it; what the prior says is
//! not a measurement).

use anyhow::{bail, Result};
use nalgebra::DMatrix;

use super::errors::{GeometricErrors, Poly, Term};
use super::identify::LineObs;
pub use super::identify::{loo_warning, LOO_NOISE_FLOOR_UM, LOO_WARN_RATIO};
use super::kinematics::Structure;
use super::prior_solve::{normal_equations, observability, solve, Normal, Prior, Search, Unknown};
pub use super::prior_solve::{
    Hyper, SmoothFit, DETERMINED_UM, DETERMINED_URAD, SCALE_PRIOR_PPM, SQUARENESS_PRIOR_URAD,
};

/// Degree of the Legendre basis per error function.
pub const DEFAULT_DEGREE: usize = 10;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SCol {
    Term {
        term: Term,
        j: usize,
    },
    Squareness(usize),
    /// Laser scale of line `i` [ppm].
    Scale(usize),
}

impl Unknown for SCol {
    fn squareness(&self) -> Option<usize> {
        match self {
            SCol::Squareness(i) => Some(*i),
            _ => None,
        }
    }
    fn scale(&self) -> Option<usize> {
        match self {
            SCol::Scale(i) => Some(*i),
            _ => None,
        }
    }
}

/// Prior group of a column.
fn group(c: &SCol) -> usize {
    match c {
        SCol::Term { term, .. } if term.component.is_angular() => 2,
        SCol::Term { term, .. } if term.is_straightness() => 1,
        SCol::Term { .. } => 0,
        SCol::Squareness(_) => 3,
        SCol::Scale(_) => 4,
    }
}

/// Monomial coefficients (u^0 … u^n) of the shifted Legendre polynomial
/// P̃_n(u) = P_n(2u − 1).
pub fn shifted_legendre(n: usize) -> Vec<f64> {
    let binom = |n: usize, k: usize| -> f64 {
        (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
    };
    (0..=n)
        .map(|k| {
            let s = if (n + k).is_multiple_of(2) { 1.0 } else { -1.0 };
            s * binom(n, k) * binom(n + k, k)
        })
        .collect()
}

/// Monomial coefficients c_1 … c_n (u^1 … u^n) of basis function j of a term.
pub fn basis_monomials(straightness: bool, j: usize) -> Vec<f64> {
    let p = shifted_legendre(j);
    let mut c: Vec<f64> = p[1..].to_vec();
    if straightness {
        // Minus its end-point line: P̃(0)(1 − u) + P̃(1)u; P̃(0) is removed
        // with the constant, the slope part is (P̃(1) − P̃(0))·u.
        let at1: f64 = p.iter().sum();
        c[0] -= at1 - p[0];
    }
    c
}

fn eval_monomials(c: &[f64], u: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, v| acc * u + v) * u
}

struct Design {
    cols: Vec<SCol>,
    ne: Normal,
}

fn design(st: &Structure, lines: &[LineObs], degree: usize, stroke: [f64; 3]) -> Design {
    let mut cols = Vec::new();
    for term in Term::all() {
        let first = if term.is_straightness() { 2 } else { 1 };
        for j in first..=degree {
            cols.push(SCol::Term { term, j });
        }
    }
    cols.extend((0..3).map(SCol::Squareness));
    cols.extend((0..lines.len()).map(SCol::Scale));
    let mono: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| match c {
            SCol::Term { term, j } => basis_monomials(term.is_straightness(), *j),
            _ => Vec::new(),
        })
        .collect();
    let ne = normal_equations(st, lines, &cols, |ci, pos, s, d| match cols[ci] {
        SCol::Term { term, .. } => {
            let u = pos[term.axis.index()] / stroke[term.axis.index()];
            d.dot(&s.terms[term.axis.index()][term.component.index()])
                * eval_monomials(&mono[ci], u)
        }
        _ => 0.0,
    });
    Design { cols, ne }
}

/// Prior variances of the columns for hyperparameters v = (ln σ, ln τ_pos,
/// ln τ_str, ln τ_ang, p).
fn prior_var(cols: &[SCol], v: &[f64; 5]) -> Vec<f64> {
    cols.iter()
        .map(|c| {
            let tau = match group(c) {
                0 => v[1].exp(),
                1 => v[2].exp(),
                2 => v[3].exp(),
                3 => return SQUARENESS_PRIOR_URAD.powi(2),
                _ => return SCALE_PRIOR_PPM.powi(2),
            };
            let j = match c {
                SCol::Term { j, .. } => *j as f64,
                _ => 1.0,
            };
            (tau * j.powf(-v[4])).powi(2)
        })
        .collect()
}

/// Identify with the rich basis; `degree` of the Legendre basis (10: waves
/// down to about half a stroke).
pub fn identify_smooth(
    st: &Structure,
    lines: &[LineObs],
    degree: usize,
    stroke: [f64; 3],
) -> Result<SmoothFit> {
    crate::identify::displacement_only(lines, "the smooth model")?;
    if lines.iter().filter(|l| l.points.len() >= 2).count() < 2 {
        bail!("fewer than two lines with at least two targets: nothing to identify from");
    }
    let d = design(st, lines, degree, stroke);
    // Coordinate search in (ln σ, ln τ…, p) from a neutral start.
    let start = Search {
        start: [0.5f64.ln(), 10f64.ln(), 3f64.ln(), 10f64.ln(), 1.0],
        lo: [0.002f64.ln(), 0.01f64.ln(), 0.01f64.ln(), 0.01f64.ln(), 0.0],
        hi: [20f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 8.0],
        step: [1.0, 1.0, 1.0, 1.0, 0.5],
    };
    let prior = |v: &[f64; 5]| Some(Prior::Variances(prior_var(&d.cols, v)));
    let solved = solve(&d.ne, &d.cols, lines, prior, &start)?;
    let errors = to_errors(&d.cols, solved.x.as_slice(), degree, stroke);
    let obs = observability(&d.cols, &solved.cov, |_, t| {
        term_sd(&d.cols, &solved.cov, t)
    });
    let decay = solved.v[4];
    let mut fit = solved.fit(errors, format!("Legendre degree {degree}"), degree, obs);
    fit.hyper.decay = Some(decay);
    Ok(fit)
}

/// The error functions of a solved series (monomial coefficients per term).
pub(crate) fn to_errors(
    cols: &[SCol],
    x: &[f64],
    degree: usize,
    stroke: [f64; 3],
) -> GeometricErrors {
    let mut e = GeometricErrors::zero();
    for t in Term::all() {
        e.set(t, Poly::new(stroke[t.axis.index()], vec![0.0; degree]));
    }
    for (c, v) in cols.iter().zip(x) {
        match *c {
            SCol::Term { term, j } => {
                let mut p = e.get(term).clone();
                for (k, m) in basis_monomials(term.is_straightness(), j)
                    .iter()
                    .enumerate()
                {
                    p.coeffs[k] += v * m;
                }
                e.set(term, p);
            }
            SCol::Squareness(i) => e.squareness.set(i, *v),
            SCol::Scale(_) => {}
        }
    }
    e
}

/// Posterior standard deviation of error `t`, RMS over its stroke.
fn term_sd(cols: &[SCol], cov: &DMatrix<f64>, t: Term) -> f64 {
    let idx: Vec<(usize, Vec<f64>)> = cols
        .iter()
        .enumerate()
        .filter_map(|(i, c)| match c {
            SCol::Term { term, j } if *term == t => {
                Some((i, basis_monomials(t.is_straightness(), *j)))
            }
            _ => None,
        })
        .collect();
    let n = 21;
    let mut var = 0.0;
    for q in 0..n {
        let u = q as f64 / (n - 1) as f64;
        let phi: Vec<f64> = idx.iter().map(|(_, m)| eval_monomials(m, u)).collect();
        for (a, (ia, _)) in idx.iter().enumerate() {
            for (b, (ib, _)) in idx.iter().enumerate() {
                var += phi[a] * phi[b] * cov[(*ia, *ib)];
            }
        }
    }
    (var / n as f64).max(0.0).sqrt()
}

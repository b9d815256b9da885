//! Identification with per-target values (issue 29, seed 002's "no assumed
//! shape"): every error function is its values at `nodes` equally spaced
//! positions of its stroke (41 = one per target of the plan's lines,
//! linear between), zero at the axis zero and, for straightness, at the
//! stroke's end (the ISO end-point reference). Fourteen lines cannot fix
//! 18 free functions (examples/null_probe.rs: exact null directions grow by
//! ≈ 3.5 per polynomial degree), so the values carry a roughness prior: a
//! Gaussian process (Matérn 5/2, conditioned on the zeros) per function,
//! one size each for positioning, straightness and angles and one length
//! scale, chosen with the noise σ by maximising the marginal likelihood
//! (evidence). Per-line laser scale (ppm) with its own stated prior,
//! squareness with a weak one. Nothing is set by hand per machine.
//!
//! Reported beside the fit (as `smooth`): effective number of parameters,
//! the noise the evidence found, leave-one-line-out prediction error, the
//! per-line scale, per error its posterior standard deviation and the
//! errors it leaves undetermined (`unobservable`).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use super::errors::{GeometricErrors, Poly, Term};
use super::identify::LineObs;
use super::kinematics::Structure;
use super::prior_solve::{
    normal_equations, observability, solve, Normal, Prior, Search, Unknown, SCALE_PRIOR_PPM,
    SQUARENESS_PRIOR_URAD,
};
use super::smooth::{basis_monomials, SmoothFit};

/// Nodes per error function (both ends included).
pub const DEFAULT_NODES: usize = 21;
/// Degree of the polynomial the node values are carried in afterwards
/// (`GeometricErrors` holds polynomials; table, tooltip and export use them).
pub const OUTPUT_DEGREE: usize = 12;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DCol {
    /// Value of `term` at node k (1 ≤ k < nodes).
    Node {
        t: usize,
        k: usize,
    },
    Squareness(usize),
    Scale(usize),
}

impl Unknown for DCol {
    fn squareness(&self) -> Option<usize> {
        match self {
            DCol::Squareness(i) => Some(*i),
            _ => None,
        }
    }
    fn scale(&self) -> Option<usize> {
        match self {
            DCol::Scale(i) => Some(*i),
            _ => None,
        }
    }
}

struct Design {
    cols: Vec<DCol>,
    terms: Vec<Term>,
    nodes: usize,
    ne: Normal,
}

fn hat(nodes: usize, k: usize, u: f64) -> f64 {
    let h = (u * (nodes - 1) as f64 - k as f64).abs();
    (1.0 - h).max(0.0)
}

fn design(st: &Structure, lines: &[LineObs], nodes: usize, stroke: [f64; 3]) -> Design {
    let terms: Vec<Term> = Term::all().collect();
    let mut cols = Vec::new();
    for (t, term) in terms.iter().enumerate() {
        let last = if term.is_straightness() {
            nodes - 2
        } else {
            nodes - 1
        };
        cols.extend((1..=last).map(|k| DCol::Node { t, k }));
    }
    cols.extend((0..3).map(DCol::Squareness));
    cols.extend((0..lines.len()).map(DCol::Scale));
    let ne = normal_equations(st, lines, &cols, |ci, pos, s, d| match cols[ci] {
        DCol::Node { t, k } => {
            let term = terms[t];
            let ax = term.axis.index();
            let w = hat(nodes, k, pos[ax] / stroke[ax]);
            if w == 0.0 {
                0.0
            } else {
                d.dot(&s.terms[ax][term.component.index()]) * w
            }
        }
        _ => 0.0,
    });
    Design {
        cols,
        terms,
        nodes,
        ne,
    }
}

fn matern52(r: f64, ell: f64) -> f64 {
    let a = 5f64.sqrt() * r / ell;
    (1.0 + a + a * a / 3.0) * (-a).exp()
}

/// Unit-size prior correlation of a function's free node values: Matérn
/// 5/2 of length `ell` (in strokes) conditioned on f(0) = 0 and, when
/// `both`, f(1) = 0. Returns its inverse and log-determinant.
fn node_prior(nodes: usize, ell: f64, both: bool) -> Option<(DMatrix<f64>, f64)> {
    let h = 1.0 / (nodes - 1) as f64;
    let fixed: Vec<f64> = if both { vec![0.0, 1.0] } else { vec![0.0] };
    let free: Vec<f64> = (1..nodes - usize::from(both))
        .map(|k| k as f64 * h)
        .collect();
    let kf = DMatrix::from_fn(free.len(), free.len(), |i, j| {
        matern52((free[i] - free[j]).abs(), ell)
    });
    let kx = DMatrix::from_fn(free.len(), fixed.len(), |i, j| {
        matern52((free[i] - fixed[j]).abs(), ell)
    });
    let kc = DMatrix::from_fn(fixed.len(), fixed.len(), |i, j| {
        matern52((fixed[i] - fixed[j]).abs(), ell)
    });
    let kc_inv = kc.try_inverse()?;
    let mut c = kf - &kx * kc_inv * kx.transpose();
    // A little jitter: a long length scale makes neighbouring values nearly
    // equal, and the conditioned matrix loses rank in floating point.
    for i in 0..c.nrows() {
        c[(i, i)] += 1e-6;
    }
    let ch = c.cholesky()?;
    let logdet = 2.0 * ch.l().diagonal().iter().map(|x| x.ln()).sum::<f64>();
    Some((ch.inverse(), logdet))
}

/// Hyperparameters v = (ln σ, ln τ_pos, ln τ_str, ln τ_ang, ln ℓ).
type V = [f64; 5];

fn group(term: Term) -> usize {
    if term.component.is_angular() {
        3
    } else if term.is_straightness() {
        2
    } else {
        1
    }
}

/// The prior precision (block diagonal) and the log-determinant of the
/// prior covariance.
fn prior(d: &Design, v: &V) -> Option<Prior> {
    let ell = v[4].exp();
    let one = node_prior(d.nodes, ell, false)?;
    let two = node_prior(d.nodes, ell, true)?;
    let n = d.cols.len();
    let mut p = DMatrix::zeros(n, n);
    let mut logdet = 0.0;
    let mut i = 0;
    while i < n {
        match d.cols[i] {
            DCol::Node { t, .. } => {
                let term = d.terms[t];
                let (pinv, ld) = if term.is_straightness() { &two } else { &one };
                let tau2 = (2.0 * v[group(term)]).exp();
                let k = pinv.nrows();
                p.view_mut((i, i), (k, k)).copy_from(&(pinv / tau2));
                logdet += ld + k as f64 * tau2.ln();
                i += k;
            }
            DCol::Squareness(_) => {
                p[(i, i)] = SQUARENESS_PRIOR_URAD.powi(-2);
                logdet += 2.0 * SQUARENESS_PRIOR_URAD.ln();
                i += 1;
            }
            DCol::Scale(_) => {
                p[(i, i)] = SCALE_PRIOR_PPM.powi(-2);
                logdet += 2.0 * SCALE_PRIOR_PPM.ln();
                i += 1;
            }
        }
    }
    Some(Prior::Precision(p, logdet))
}

/// Identify with per-target values and the evidence-chosen roughness prior.
pub fn identify_dense(
    st: &Structure,
    lines: &[LineObs],
    nodes: usize,
    stroke: [f64; 3],
) -> Result<SmoothFit> {
    crate::identify::displacement_only(lines, "the dense model")?;
    if lines.iter().filter(|l| l.points.len() >= 2).count() < 2 {
        bail!("fewer than two lines with at least two targets: nothing to identify from");
    }
    if nodes < 4 {
        bail!("at least 4 nodes per error function, got {nodes}");
    }
    let d = design(st, lines, nodes, stroke);
    // Coordinate search from a neutral start.
    let start = Search {
        start: [0.5f64.ln(), 10f64.ln(), 3f64.ln(), 10f64.ln(), 0.3f64.ln()],
        lo: [
            0.002f64.ln(),
            0.01f64.ln(),
            0.01f64.ln(),
            0.01f64.ln(),
            0.05f64.ln(),
        ],
        hi: [20f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 3f64.ln()],
        step: [1.0; 5],
    };
    let solved = solve(&d.ne, &d.cols, lines, |v| prior(&d, v), &start)?;
    let (errors, fit_um) = to_errors(&d, solved.x.as_slice(), stroke);
    let obs = observability(&d.cols, &solved.cov, |t, _| node_sd(&d, &solved.cov, t));
    let ell = solved.v[4].exp();
    let basis = format!(
        "values at {nodes} nodes, Matérn 5/2 prior; carried as degree {OUTPUT_DEGREE} (fit {fit_um:.3} µm)"
    );
    let mut fit = solved.fit(errors, basis, nodes, obs);
    fit.hyper.length_scale_strokes = Some(ell);
    Ok(fit)
}

/// Node values of every term (zeros included), indexed like `d.terms`.
fn node_values(d: &Design, x: &[f64]) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; d.nodes]; d.terms.len()];
    for (c, v) in d.cols.iter().zip(x) {
        if let DCol::Node { t, k } = *c {
            out[t][k] = *v;
        }
    }
    out
}

/// The errors as polynomials of `OUTPUT_DEGREE` (least squares through the
/// piecewise-linear node function at 8 points per node interval, in the
/// Legendre basis of `smooth`), and the worst RMS of that approximation.
fn to_errors(d: &Design, x: &[f64], stroke: [f64; 3]) -> (GeometricErrors, f64) {
    let vals = node_values(d, x);
    let mut e = GeometricErrors::zero();
    let npts = 8 * (d.nodes - 1) + 1;
    let us: Vec<f64> = (0..npts).map(|i| i as f64 / (npts - 1) as f64).collect();
    let mut worst = 0.0f64;
    for (t, term) in d.terms.iter().enumerate() {
        let straight = term.is_straightness();
        let first = if straight { 2 } else { 1 };
        let basis: Vec<Vec<f64>> = (first..=OUTPUT_DEGREE)
            .map(|j| basis_monomials(straight, j))
            .collect();
        let eval = |c: &[f64], u: f64| c.iter().rev().fold(0.0, |acc, v| acc * u + v) * u;
        let a = DMatrix::from_fn(npts, basis.len(), |i, j| eval(&basis[j], us[i]));
        let y = DVector::from_fn(npts, |i, _| {
            (0..d.nodes)
                .map(|k| vals[t][k] * hat(d.nodes, k, us[i]))
                .sum()
        });
        let coef = a
            .clone()
            .svd(true, true)
            .solve(&y, 1e-12)
            .unwrap_or_else(|_| DVector::zeros(basis.len()));
        let r = &a * &coef - &y;
        worst = worst.max((r.norm_squared() / npts as f64).sqrt());
        let mut mono = vec![0.0; OUTPUT_DEGREE];
        for (c, m) in coef.iter().zip(&basis) {
            for (k, v) in m.iter().enumerate() {
                mono[k] += c * v;
            }
        }
        e.set(*term, Poly::new(stroke[term.axis.index()], mono));
    }
    for (c, v) in d.cols.iter().zip(x) {
        if let DCol::Squareness(i) = *c {
            e.squareness.set(i, *v);
        }
    }
    (e, worst)
}

/// Posterior standard deviation of error `t` (index into `d.terms`), RMS
/// over its nodes.
fn node_sd(d: &Design, cov: &DMatrix<f64>, t: usize) -> f64 {
    let var: f64 = d
        .cols
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c, DCol::Node { t: tt, .. } if *tt == t))
        .map(|(i, _)| cov[(i, i)])
        .sum();
    (var / d.nodes as f64).max(0.0).sqrt()
}

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
use nalgebra::{Cholesky, DMatrix, DVector, Dyn, Vector3};

use super::errors::{GeometricErrors, Poly, Term, SQUARENESS_NAMES};
use super::identify::LineObs;
use super::kinematics::{sensitivity, Structure};
use super::smooth::{
    basis_monomials, Hyper, SmoothFit, DETERMINED_UM, DETERMINED_URAD, SCALE_PRIOR_PPM,
    SQUARENESS_PRIOR_URAD,
};

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

struct Design {
    cols: Vec<DCol>,
    terms: Vec<Term>,
    nodes: usize,
    g: DMatrix<f64>,
    b: DVector<f64>,
    yy: f64,
    per_line: Vec<(DMatrix<f64>, DVector<f64>, f64, usize)>,
    m: usize,
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
    let n = cols.len();
    let mut g = DMatrix::zeros(n, n);
    let mut b = DVector::zeros(n);
    let (mut yy, mut m) = (0.0, 0);
    let mut per_line = Vec::new();
    for (li, l) in lines.iter().enumerate() {
        let d = Vector3::from(l.direction);
        let p0 = l.points.first().map(|p| p.pos_mm).unwrap_or([0.0; 3]);
        let k = l.points.len();
        let mut a = DMatrix::zeros(k, n);
        let mut y = DVector::zeros(k);
        for (r, p) in l.points.iter().enumerate() {
            let s = sensitivity(st, p.pos_mm, l.tool_offset_mm);
            let along = d.dot(&(Vector3::from(p.pos_mm) - Vector3::from(p0)));
            for (ci, c) in cols.iter().enumerate() {
                a[(r, ci)] = match *c {
                    DCol::Node { t, k } => {
                        let term = terms[t];
                        let ax = term.axis.index();
                        let w = hat(nodes, k, p.pos_mm[ax] / stroke[ax]);
                        if w == 0.0 {
                            0.0
                        } else {
                            d.dot(&s.terms[ax][term.component.index()]) * w
                        }
                    }
                    DCol::Squareness(i) => d.dot(&s.squareness[i]),
                    DCol::Scale(i) if i == li => along * 1e-3,
                    DCol::Scale(_) => 0.0,
                };
            }
            y[r] = p.disp_um;
        }
        for ci in 0..n {
            let mean = a.column(ci).mean();
            a.column_mut(ci).add_scalar_mut(-mean);
        }
        let mean = y.mean();
        y.add_scalar_mut(-mean);
        let gl = a.transpose() * &a;
        let bl = a.transpose() * &y;
        let yl = y.norm_squared();
        g += &gl;
        b += &bl;
        yy += yl;
        m += k;
        per_line.push((gl, bl, yl, k));
    }
    Design {
        cols,
        terms,
        nodes,
        g,
        b,
        yy,
        per_line,
        m,
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
fn prior(d: &Design, v: &V) -> Option<(DMatrix<f64>, f64)> {
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
    Some((p, logdet))
}

/// −2 ln evidence (without constants), the posterior Cholesky and the
/// prior precision.
fn evidence(d: &Design, v: &V, lines: usize) -> Option<(f64, Cholesky<f64, Dyn>, DMatrix<f64>)> {
    let s2 = (2.0 * v[0]).exp();
    let (p, logdet_p) = prior(d, v)?;
    let mm = &d.g / s2 + &p;
    let ch = mm.cholesky()?;
    let logdet_m: f64 = 2.0 * ch.l().diagonal().iter().map(|x| x.ln()).sum::<f64>();
    let bs = &d.b / s2;
    let x = ch.solve(&bs);
    let quad = (d.yy - bs.dot(&x) * s2) / s2;
    let dof = (d.m - lines) as f64;
    Some((dof * s2.ln() + logdet_p + logdet_m + quad, ch, p))
}

/// Coordinate search of the evidence from a neutral start.
fn search(d: &Design, lines: usize) -> V {
    let f = |v: &V| evidence(d, v, lines).map_or(f64::INFINITY, |r| r.0);
    let mut v: V = [0.5f64.ln(), 10f64.ln(), 3f64.ln(), 10f64.ln(), 0.3f64.ln()];
    let lo: V = [
        0.002f64.ln(),
        0.01f64.ln(),
        0.01f64.ln(),
        0.01f64.ln(),
        0.05f64.ln(),
    ];
    let hi: V = [20f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 3f64.ln()];
    let mut best = f(&v);
    let mut step = [1.0; 5];
    for _ in 0..200 {
        let mut moved = false;
        for k in 0..5 {
            for dir in [1.0, -1.0] {
                let mut w = v;
                w[k] = (w[k] + dir * step[k]).clamp(lo[k], hi[k]);
                let fw = f(&w);
                if fw < best - 1e-9 {
                    best = fw;
                    v = w;
                    moved = true;
                }
            }
        }
        if !moved {
            step.iter_mut().for_each(|s| *s *= 0.5);
            if step[0] < 0.01 {
                break;
            }
        }
    }
    v
}

/// Identify with per-target values and the evidence-chosen roughness prior.
pub fn identify_dense(
    st: &Structure,
    lines: &[LineObs],
    nodes: usize,
    stroke: [f64; 3],
) -> Result<SmoothFit> {
    if lines.iter().filter(|l| l.points.len() >= 2).count() < 2 {
        bail!("fewer than two lines with at least two targets: nothing to identify from");
    }
    if nodes < 4 {
        bail!("at least 4 nodes per error function, got {nodes}");
    }
    let d = design(st, lines, nodes, stroke);
    let nl = lines.len();
    let v = search(&d, nl);
    let (_, ch, p) = evidence(&d, &v, nl)
        .ok_or_else(|| anyhow::anyhow!("internal: the posterior is not positive definite"))?;
    let s2 = (2.0 * v[0]).exp();
    let x = ch.solve(&(&d.b / s2));
    let cov = ch.inverse();
    let effective_parameters = (&cov * &d.g / s2).trace();
    let resid_ss = d.yy - 2.0 * d.b.dot(&x) + x.dot(&(&d.g * &x));
    let residual_rms_um = (resid_ss.max(0.0) / d.m as f64).sqrt();
    let (loo_rms_um, loo_per_line_um) = leave_one_line_out(&d, &p, s2, lines);
    let (errors, fit_um) = to_errors(&d, x.as_slice(), stroke);
    let (posterior_sd, unobservable_terms) = observability(&d, &cov);
    let line_scale_ppm = d
        .cols
        .iter()
        .zip(x.iter())
        .filter_map(|(c, v)| match c {
            DCol::Scale(i) => Some((lines[*i].id.clone(), *v)),
            _ => None,
        })
        .collect();
    let noise_um = v[0].exp();
    let warning = super::smooth::loo_warning(loo_rms_um, noise_um);
    Ok(SmoothFit {
        errors,
        basis: format!(
            "values at {nodes} nodes, Matérn 5/2 prior; carried as degree {OUTPUT_DEGREE} (fit {fit_um:.3} µm)"
        ),
        degree: nodes,
        unknowns: d.cols.len(),
        readings: d.m,
        lines: nl,
        effective_parameters,
        hyper: Hyper {
            noise_um,
            positioning_um: v[1].exp(),
            straightness_um: v[2].exp(),
            angular_urad: v[3].exp(),
            decay: None,
            length_scale_strokes: Some(v[4].exp()),
        },
        residual_rms_um,
        loo_rms_um,
        loo_per_line_um,
        line_scale_ppm,
        posterior_sd,
        unobservable_terms,
        warning,
    })
}

/// Each line predicted from the posterior of the others [µm]: RMS over all
/// readings, and per line.
fn leave_one_line_out(
    d: &Design,
    p: &DMatrix<f64>,
    s2: f64,
    lines: &[LineObs],
) -> (f64, Vec<(String, f64)>) {
    let (mut ss_all, mut per) = (0.0, Vec::new());
    for (li, (gl, bl, yl, k)) in d.per_line.iter().enumerate() {
        let mm = (&d.g - gl) / s2 + p;
        let Some(c) = mm.cholesky() else { continue };
        let xl = c.solve(&((&d.b - bl) / s2));
        let ss = (yl - 2.0 * bl.dot(&xl) + xl.dot(&(gl * &xl))).max(0.0);
        ss_all += ss;
        per.push((lines[li].id.clone(), (ss / *k as f64).sqrt()));
    }
    ((ss_all / d.m as f64).sqrt(), per)
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

/// Posterior standard deviation of each error, RMS over its nodes, and the
/// errors whose two standard deviations exceed the stated tolerance.
fn observability(d: &Design, cov: &DMatrix<f64>) -> (Vec<(String, f64)>, Vec<String>) {
    let (mut sd, mut bad) = (Vec::new(), Vec::new());
    for (t, term) in d.terms.iter().enumerate() {
        let var: f64 = d
            .cols
            .iter()
            .enumerate()
            .filter(|(_, c)| matches!(c, DCol::Node { t: tt, .. } if *tt == t))
            .map(|(i, _)| cov[(i, i)])
            .sum();
        let s = (var / d.nodes as f64).max(0.0).sqrt();
        let tol = if term.component.is_angular() {
            DETERMINED_URAD
        } else {
            DETERMINED_UM
        };
        if 2.0 * s > tol {
            bad.push(term.name());
        }
        sd.push((term.name(), s));
    }
    for (i, c) in d.cols.iter().enumerate() {
        if let DCol::Squareness(k) = c {
            let s = cov[(i, i)].sqrt();
            if 2.0 * s > DETERMINED_URAD {
                bad.push(SQUARENESS_NAMES[*k].to_string());
            }
            sd.push((SQUARENESS_NAMES[*k].to_string(), s));
        }
    }
    bad.sort();
    (sd, bad)
}

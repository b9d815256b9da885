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
use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;

use super::errors::{GeometricErrors, Poly, Term, SQUARENESS_NAMES};
use super::identify::LineObs;
pub use super::identify::{loo_warning, LOO_NOISE_FLOOR_UM, LOO_WARN_RATIO};
use super::kinematics::{sensitivity, Structure};

/// Degree of the Legendre basis per error function.
pub const DEFAULT_DEGREE: usize = 10;
/// Prior standard deviation of a line's laser scale error [ppm] (beam
/// misalignment cosine error, wavelength compensation): stated, not fitted.
pub const SCALE_PRIOR_PPM: f64 = 1.0;
/// Prior standard deviation of a squareness error [µrad] (weak).
pub const SQUARENESS_PRIOR_URAD: f64 = 200.0;
/// An error counts as determined when twice its posterior standard
/// deviation (RMS over the stroke) is within this [µm] for translational
/// errors …
pub const DETERMINED_UM: f64 = 1.0;
/// … and this [µrad] for angular errors and squareness.
pub const DETERMINED_URAD: f64 = 4.0;

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

#[derive(Clone, Debug, Serialize)]
pub struct Hyper {
    pub noise_um: f64,
    pub positioning_um: f64,
    pub straightness_um: f64,
    pub angular_urad: f64,
    /// Legendre basis: how fast the prior size falls with the order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decay: Option<f64>,
    /// Node values: the prior's length scale [strokes].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub length_scale_strokes: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct SmoothFit {
    #[serde(skip)]
    pub errors: GeometricErrors,
    /// What each error function is made of, in words.
    pub basis: String,
    pub degree: usize,
    pub unknowns: usize,
    pub readings: usize,
    pub lines: usize,
    pub effective_parameters: f64,
    pub hyper: Hyper,
    pub residual_rms_um: f64,
    /// Leave-one-line-out: RMS over every reading of each line predicted
    /// from the other lines [µm], and per line.
    pub loo_rms_um: f64,
    pub loo_per_line_um: Vec<(String, f64)>,
    /// Laser scale per line [ppm] (estimated with prior SCALE_PRIOR_PPM).
    pub line_scale_ppm: Vec<(String, f64)>,
    /// Posterior standard deviation per error (RMS over the stroke) [µm, µrad].
    pub posterior_sd: Vec<(String, f64)>,
    pub unobservable_terms: Vec<String>,
    /// One line when the lines are predicted much worse than the noise.
    pub warning: Option<String>,
}

struct Design {
    cols: Vec<SCol>,
    /// ÃᵀÃ and Ãᵀy with each line centred, total and per line.
    g: DMatrix<f64>,
    b: DVector<f64>,
    yy: f64,
    per_line: Vec<(DMatrix<f64>, DVector<f64>, f64, usize)>,
    m: usize,
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
                    SCol::Term { term, .. } => {
                        let u = p.pos_mm[term.axis.index()] / stroke[term.axis.index()];
                        d.dot(&s.terms[term.axis.index()][term.component.index()])
                            * eval_monomials(&mono[ci], u)
                    }
                    SCol::Squareness(i) => d.dot(&s.squareness[i]),
                    // ppm × mm = nm: µm per ppm is along/1e3.
                    SCol::Scale(i) if i == li => along * 1e-3,
                    SCol::Scale(_) => 0.0,
                };
            }
            y[r] = p.disp_um;
        }
        // The line's free zero: centre its rows and readings.
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
        g,
        b,
        yy,
        per_line,
        m,
    }
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

/// −2 ln evidence (without constants) and the posterior (Cholesky of M).
fn neg_log_evidence(
    d: &Design,
    v: &[f64; 5],
    lines: usize,
) -> Option<(f64, nalgebra::Cholesky<f64, nalgebra::Dyn>)> {
    let s2 = (2.0 * v[0]).exp();
    let pv = prior_var(&d.cols, v);
    let mut mm = &d.g / s2;
    for (i, p) in pv.iter().enumerate() {
        mm[(i, i)] += 1.0 / p;
    }
    let ch = mm.cholesky()?;
    let logdet_m: f64 = 2.0 * ch.l().diagonal().iter().map(|x| x.ln()).sum::<f64>();
    let logdet_p: f64 = pv.iter().map(|p| p.ln()).sum();
    let bs = &d.b / s2;
    let x = ch.solve(&bs);
    let quad = (d.yy - bs.dot(&x) * s2) / s2;
    let dof = (d.m - lines) as f64;
    Some((dof * s2.ln() + logdet_p + logdet_m + quad, ch))
}

/// Identify with the rich basis; `degree` of the Legendre basis (10: waves
/// down to about half a stroke).
pub fn identify_smooth(
    st: &Structure,
    lines: &[LineObs],
    degree: usize,
    stroke: [f64; 3],
) -> Result<SmoothFit> {
    if lines.iter().filter(|l| l.points.len() >= 2).count() < 2 {
        bail!("fewer than two lines with at least two targets: nothing to identify from");
    }
    let d = design(st, lines, degree, stroke);
    let nl = lines.len();
    let f = |v: &[f64; 5]| neg_log_evidence(&d, v, nl).map_or(f64::INFINITY, |r| r.0);
    // Coordinate search in (ln σ, ln τ…, p) from a neutral start.
    let mut v = [0.5f64.ln(), 10f64.ln(), 3f64.ln(), 10f64.ln(), 1.0];
    let lo = [0.002f64.ln(), 0.01f64.ln(), 0.01f64.ln(), 0.01f64.ln(), 0.0];
    let hi = [20f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 1e3f64.ln(), 8.0];
    let mut best = f(&v);
    let mut step = [1.0, 1.0, 1.0, 1.0, 0.5];
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
    let (_, ch) = neg_log_evidence(&d, &v, nl)
        .ok_or_else(|| anyhow::anyhow!("internal: the posterior is not positive definite"))?;
    let s2 = (2.0 * v[0]).exp();
    let x = ch.solve(&(&d.b / s2));
    let cov = ch.inverse();
    let n = d.cols.len();
    let effective_parameters = (&cov * &d.g / s2).trace();
    let resid_ss = d.yy - 2.0 * d.b.dot(&x) + x.dot(&(&d.g * &x));
    let residual_rms_um = (resid_ss.max(0.0) / d.m as f64).sqrt();
    // Leave one line out: the posterior without its normal equations.
    let pv = prior_var(&d.cols, &v);
    let (mut loo_ss, mut loo_per_line) = (0.0, Vec::new());
    for (li, (gl, bl, yl, k)) in d.per_line.iter().enumerate() {
        let mut mm = (&d.g - gl) / s2;
        for (i, p) in pv.iter().enumerate() {
            mm[(i, i)] += 1.0 / p;
        }
        let Some(c) = mm.cholesky() else { continue };
        let xl = c.solve(&((&d.b - bl) / s2));
        let ss = (yl - 2.0 * bl.dot(&xl) + xl.dot(&(gl * &xl))).max(0.0);
        loo_ss += ss;
        loo_per_line.push((lines[li].id.clone(), (ss / *k as f64).sqrt()));
    }
    let loo_rms_um = (loo_ss / d.m as f64).sqrt();
    let errors = to_errors(&d.cols, x.as_slice(), degree, stroke);
    let (posterior_sd, unobservable_terms) = observability(&d.cols, &cov, stroke);
    let line_scale_ppm = d
        .cols
        .iter()
        .zip(x.iter())
        .filter_map(|(c, v)| match c {
            SCol::Scale(i) => Some((lines[*i].id.clone(), *v)),
            _ => None,
        })
        .collect();
    let noise_um = v[0].exp();
    let warning = super::identify::loo_warning(loo_rms_um, noise_um);
    Ok(SmoothFit {
        errors,
        basis: format!("Legendre degree {degree}"),
        degree,
        unknowns: n,
        readings: d.m,
        lines: nl,
        effective_parameters,
        hyper: Hyper {
            noise_um,
            positioning_um: v[1].exp(),
            straightness_um: v[2].exp(),
            angular_urad: v[3].exp(),
            decay: Some(v[4]),
            length_scale_strokes: None,
        },
        residual_rms_um,
        loo_rms_um,
        loo_per_line_um: loo_per_line,
        line_scale_ppm,
        posterior_sd,
        unobservable_terms,
        warning,
    })
}

fn to_errors(cols: &[SCol], x: &[f64], degree: usize, stroke: [f64; 3]) -> GeometricErrors {
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

/// Posterior standard deviation of each error, RMS over its stroke, and the
/// errors above the stated tolerance.
fn observability(
    cols: &[SCol],
    cov: &DMatrix<f64>,
    stroke: [f64; 3],
) -> (Vec<(String, f64)>, Vec<String>) {
    let _ = stroke;
    let mut sd = Vec::new();
    let mut bad = Vec::new();
    for t in Term::all() {
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
        let s = (var / n as f64).max(0.0).sqrt();
        let tol = if t.component.is_angular() {
            DETERMINED_URAD
        } else {
            DETERMINED_UM
        };
        // Determined: two posterior standard deviations within the tolerance
        // (one was measured to leave terms 1.6 sd off on rich machines).
        if 2.0 * s > tol {
            bad.push(t.name());
        }
        sd.push((t.name(), s));
    }
    for (i, c) in cols.iter().enumerate() {
        if let SCol::Squareness(k) = c {
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

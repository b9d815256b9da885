//! What the two identifications with no shape assumed share (issue 29;
//! `smooth`: a Legendre basis per error, `dense`: values at nodes): the
//! normal equations with each line's free zero centred out, the Gaussian
//! prior's evidence and its coordinate search, and the posterior's figures
//! (effective parameters, residual, leave-one-line-out, per-line scale, the
//! errors it leaves undetermined), gathered in a [`SmoothFit`]. Each method
//! keeps its own columns, prior and conversion to error polynomials.

use anyhow::Result;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn, Vector3};
use serde::Serialize;

use super::errors::{GeometricErrors, Term, SQUARENESS_NAMES};
use super::identify::{loo_warning, LineObs};
use super::kinematics::{sensitivity, Sensitivity, Structure};

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

/// Hyperparameters v = (ln σ, ln τ_pos, ln τ_str, ln τ_ang, the method's
/// fifth: the Legendre decay or the node prior's ln length scale, and any
/// further ones a method adds, e.g. `generic`'s ln scale prior).
pub(crate) type V<const N: usize = 5> = [f64; N];

/// What a column of either method is besides an error-function unknown.
pub(crate) trait Unknown {
    /// Squareness error i (EC0Y, EB0Z, EA0Z).
    fn squareness(&self) -> Option<usize>;
    /// Laser scale of line i [ppm].
    fn scale(&self) -> Option<usize>;
}

/// ÃᵀÃ and Ãᵀy with each line centred (its free zero), total and per line.
pub(crate) struct Normal {
    pub g: DMatrix<f64>,
    pub b: DVector<f64>,
    pub yy: f64,
    /// (ÃᵀÃ, Ãᵀy, yᵀy, readings) of each line.
    pub per_line: Vec<(DMatrix<f64>, DVector<f64>, f64, usize)>,
    /// Readings in all.
    pub m: usize,
}

/// The normal equations of `cols` over the lines: a squareness or scale
/// column is the same for every method, an error-function column's value
/// at a reading is `term_value(column index, position, sensitivity,
/// line direction)`.
pub(crate) fn normal_equations<C: Unknown>(
    st: &Structure,
    lines: &[LineObs],
    cols: &[C],
    term_value: impl Fn(usize, [f64; 3], &Sensitivity, &Vector3<f64>) -> f64,
) -> Normal {
    let n = cols.len();
    let mut g = DMatrix::zeros(n, n);
    let mut b = DVector::zeros(n);
    let (mut yy, mut m) = (0.0, 0);
    let mut per_line = Vec::new();
    for (li, l) in lines.iter().enumerate() {
        // The reading is the error along the line's sense (its travel for a
        // displacement line); the scale column is µm per ppm of the travel
        // for a laser, per µrad of slope for a straightness optic.
        let d = Vector3::from(l.sense);
        let t = Vector3::from(l.direction);
        let p0 = l.points.first().map(|p| p.pos_mm).unwrap_or([0.0; 3]);
        let k = l.points.len();
        let mut a = DMatrix::zeros(k, n);
        let mut y = DVector::zeros(k);
        for (r, p) in l.points.iter().enumerate() {
            let s = sensitivity(st, p.pos_mm, l.tool_offset_mm);
            let along = t.dot(&(Vector3::from(p.pos_mm) - Vector3::from(p0)));
            for (ci, c) in cols.iter().enumerate() {
                a[(r, ci)] = match (c.squareness(), c.scale()) {
                    (Some(i), _) => d.dot(&s.squareness[i]),
                    // ppm (µrad) × mm = nm: µm per ppm is along/1e3.
                    (_, Some(i)) if i == li => along * 1e-3,
                    (_, Some(_)) => 0.0,
                    (None, None) => term_value(ci, p.pos_mm, &s, &d),
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
    Normal {
        g,
        b,
        yy,
        per_line,
        m,
    }
}

/// A Gaussian prior on the columns.
pub(crate) enum Prior {
    /// Independent columns: each one's prior variance.
    Variances(Vec<f64>),
    /// The prior precision and the log-determinant of the prior covariance.
    Precision(DMatrix<f64>, f64),
}

impl Prior {
    /// `mm` (the data's precision) plus the prior's.
    pub(crate) fn add_to(&self, mut mm: DMatrix<f64>) -> DMatrix<f64> {
        match self {
            Prior::Variances(pv) => {
                for (i, p) in pv.iter().enumerate() {
                    mm[(i, i)] += 1.0 / p;
                }
            }
            Prior::Precision(p, _) => mm += p,
        }
        mm
    }

    fn logdet(&self) -> f64 {
        match self {
            Prior::Variances(pv) => pv.iter().map(|p| p.ln()).sum(),
            Prior::Precision(_, ld) => *ld,
        }
    }
}

/// −2 ln evidence (without constants) and the posterior (Cholesky of M).
fn neg_log_evidence(
    ne: &Normal,
    s2: f64,
    prior: &Prior,
    lines: usize,
) -> Option<(f64, Cholesky<f64, Dyn>)> {
    let ch = prior.add_to(&ne.g / s2).cholesky()?;
    let logdet_m: f64 = 2.0 * ch.l().diagonal().iter().map(|x| x.ln()).sum::<f64>();
    let logdet_p = prior.logdet();
    let bs = &ne.b / s2;
    let x = ch.solve(&bs);
    let quad = (ne.yy - bs.dot(&x) * s2) / s2;
    let dof = (ne.m - lines) as f64;
    Some((dof * s2.ln() + logdet_p + logdet_m + quad, ch))
}

/// Where the coordinate search of the evidence starts, its bounds and
/// first steps (a coordinate with step 0 stays where it starts).
pub(crate) struct Search<const N: usize = 5> {
    pub start: V<N>,
    pub lo: V<N>,
    pub hi: V<N>,
    pub step: V<N>,
}

/// Coordinate search of the evidence: each coordinate stepped both ways
/// while that improves it, the steps halved when none does.
fn search<const N: usize>(f: impl Fn(&V<N>) -> f64, s: &Search<N>) -> V<N> {
    let (mut v, lo, hi, mut step) = (s.start, s.lo, s.hi, s.step);
    let mut best = f(&v);
    for _ in 0..200 {
        let mut moved = false;
        for k in (0..N).filter(|k| step[*k] > 0.0) {
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

/// The posterior at the evidence's hyperparameters, with its figures.
pub(crate) struct Solved<const N: usize = 5> {
    pub v: V<N>,
    /// Posterior mean and covariance of the columns.
    pub x: DVector<f64>,
    pub cov: DMatrix<f64>,
    effective_parameters: f64,
    residual_rms_um: f64,
    loo_rms_um: f64,
    loo_per_line_um: Vec<(String, f64)>,
    line_scale_ppm: Vec<(String, f64)>,
    unknowns: usize,
    readings: usize,
    lines: usize,
}

/// Choose the hyperparameters by the evidence (`prior` gives the prior at
/// each; `None` where it does not exist) and solve at them.
pub(crate) fn solve<C: Unknown, const N: usize>(
    ne: &Normal,
    cols: &[C],
    lines: &[LineObs],
    prior: impl Fn(&V<N>) -> Option<Prior>,
    start: &Search<N>,
) -> Result<Solved<N>> {
    let nl = lines.len();
    let f = |v: &V<N>| {
        prior(v)
            .and_then(|p| neg_log_evidence(ne, (2.0 * v[0]).exp(), &p, nl))
            .map_or(f64::INFINITY, |r| r.0)
    };
    let v = search(f, start);
    let s2 = (2.0 * v[0]).exp();
    let not_pd = || anyhow::anyhow!("internal: the posterior is not positive definite");
    let p = prior(&v).ok_or_else(not_pd)?;
    let (_, ch) = neg_log_evidence(ne, s2, &p, nl).ok_or_else(not_pd)?;
    let x = ch.solve(&(&ne.b / s2));
    let cov = ch.inverse();
    let effective_parameters = (&cov * &ne.g / s2).trace();
    let resid_ss = ne.yy - 2.0 * ne.b.dot(&x) + x.dot(&(&ne.g * &x));
    let residual_rms_um = (resid_ss.max(0.0) / ne.m as f64).sqrt();
    let (loo_rms_um, loo_per_line_um) = leave_one_line_out(ne, &p, s2, lines);
    let line_scale_ppm = cols
        .iter()
        .zip(x.iter())
        .filter_map(|(c, v)| c.scale().map(|i| (lines[i].id.clone(), *v)))
        .collect();
    Ok(Solved {
        v,
        x,
        cov,
        effective_parameters,
        residual_rms_um,
        loo_rms_um,
        loo_per_line_um,
        line_scale_ppm,
        unknowns: cols.len(),
        readings: ne.m,
        lines: nl,
    })
}

/// Each line predicted from the posterior of the others (the posterior
/// without its normal equations) [µm]: RMS over all readings, and per line.
fn leave_one_line_out(
    ne: &Normal,
    p: &Prior,
    s2: f64,
    lines: &[LineObs],
) -> (f64, Vec<(String, f64)>) {
    let (mut ss_all, mut per) = (0.0, Vec::new());
    for (li, (gl, bl, yl, k)) in ne.per_line.iter().enumerate() {
        let mm = p.add_to((&ne.g - gl) / s2);
        let Some(c) = mm.cholesky() else { continue };
        let xl = c.solve(&((&ne.b - bl) / s2));
        let ss = (yl - 2.0 * bl.dot(&xl) + xl.dot(&(gl * &xl))).max(0.0);
        ss_all += ss;
        per.push((lines[li].id.clone(), (ss / *k as f64).sqrt()));
    }
    ((ss_all / ne.m as f64).sqrt(), per)
}

impl<const N: usize> Solved<N> {
    /// The fit's report: `errors` in the method's words (`basis`,
    /// `degree`), with the per-error posterior standard deviations and the
    /// undetermined errors of [`observability`]. The hyperparameters' fifth
    /// (decay or length scale) is the caller's to fill in.
    pub fn fit(
        self,
        errors: GeometricErrors,
        basis: String,
        degree: usize,
        (posterior_sd, unobservable_terms): (Vec<(String, f64)>, Vec<String>),
    ) -> SmoothFit {
        let v = self.v;
        let noise_um = v[0].exp();
        SmoothFit {
            errors,
            basis,
            degree,
            unknowns: self.unknowns,
            readings: self.readings,
            lines: self.lines,
            effective_parameters: self.effective_parameters,
            hyper: Hyper {
                noise_um,
                positioning_um: v[1].exp(),
                straightness_um: v[2].exp(),
                angular_urad: v[3].exp(),
                decay: None,
                length_scale_strokes: None,
            },
            residual_rms_um: self.residual_rms_um,
            warning: loo_warning(self.loo_rms_um, noise_um),
            loo_rms_um: self.loo_rms_um,
            loo_per_line_um: self.loo_per_line_um,
            line_scale_ppm: self.line_scale_ppm,
            posterior_sd,
            unobservable_terms,
        }
    }
}

/// Posterior standard deviation of each error (`term_sd(index, term)` for
/// the error functions, in `Term::all()` order; the squareness columns'
/// own), and the errors whose two standard deviations exceed the stated
/// tolerance, sorted.
pub(crate) fn observability<C: Unknown>(
    cols: &[C],
    cov: &DMatrix<f64>,
    term_sd: impl Fn(usize, Term) -> f64,
) -> (Vec<(String, f64)>, Vec<String>) {
    let (mut sd, mut bad) = (Vec::new(), Vec::new());
    for (t, term) in Term::all().enumerate() {
        let s = term_sd(t, term);
        let tol = if term.component.is_angular() {
            DETERMINED_URAD
        } else {
            DETERMINED_UM
        };
        // Determined: two posterior standard deviations within the tolerance
        // (one was measured to leave terms 1.6 sd off on rich machines).
        if 2.0 * s > tol {
            bad.push(term.name());
        }
        sd.push((term.name(), s));
    }
    for (i, c) in cols.iter().enumerate() {
        if let Some(k) = c.squareness() {
            let s = cov[(i, i)].sqrt();
            if 2.0 * s > DETERMINED_URAD {
                bad.push(SQUARENESS_NAMES[k].to_string());
            }
            sd.push((SQUARENESS_NAMES[k].to_string(), s));
        }
    }
    bad.sort();
    (sd, bad)
}

//! The generic identifier (issue 49 items 1–2): not told the error shape,
//! the default of `identify` when the lines determine the machine.
//!
//! * **Class**: every error function a Legendre series of degree [`DEGREE`]
//!   (the class `plan` judges plans by; zero at the axis zero,
//!   straightness also at the stroke's end, the ISO end-point reference),
//!   the three squareness errors.
//! * **Prior**: coefficient j of an error of class g (positioning,
//!   straightness, angles) has standard deviation τ_g·j^(−p); τ_g, p, the
//!   noise σ and the size of the lines' laser scale errors are chosen by
//!   maximising the evidence (type-II maximum likelihood; `prior_solve`).
//! * **Per line** (what a line's description implies it may carry beside
//!   the machine): a free zero (the interferometer reads relative
//!   displacement) and a laser scale error (wavelength compensation and
//!   the beam's cosine misalignment, which reads as a scale), both
//!   integrated out. A straightness-optics line (`LineKind::Straightness`)
//!   reads the error along its `sense`, perpendicular to the travel, up to
//!   an offset and a slope (the optic's alignment): the same two columns,
//!   the slope with the wide prior [`SLOPE_PRIOR_URAD`] instead of the
//!   laser scale's. A reflector a millimetre off its stated offset moves
//!   a reading by the angles × 1 mm (0.03 µm at 30 µrad): below the noise,
//!   left to it.
//! * **Posterior**: each error's σ at any position; an error is
//!   *undetermined* when its posterior σ is above [`UNDETERMINED_RATIO`] of
//!   its prior σ (RMS over the stroke): the lines did not remove three
//!   quarters of what the prior allowed — not a rank of a tight prior.
//! * **Adequacy** (`adequacy::Adequacy`, the same verdict as the
//!   polynomial model's): the fit residual against the stated noise
//!   (χ², degrees of freedom readings − lines − effective parameters), and
//!   each line predicted from the others' posterior against its exact
//!   predictive expectation (noise + the others' posterior σ + its own
//!   scale), 99.5 % each, the noise × `NOISE_TOLERANCE`.
//!
//! Null directions (combinations of the class no line sees, `plan`'s
//! criterion) are counted and named by [`null_combinations`]: a plan with
//! one cannot pin the machine down, whatever the prior says.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Vector3};

use super::adequacy::{chi2_upper, words, Adequacy, StatedNoise, FALSE_REJECT, NOISE_TOLERANCE};
use super::errors::{GeometricErrors, Term, SQUARENESS_NAMES};
use super::identify::{LineKind, LineObs};
use super::kinematics::{sensitivity, Structure};
use super::plan::{
    CLASS_DEGREE, NULL_TOLERANCE, POSITIONS, PRIOR_SQUARENESS_URAD, SLOPE_PRIOR_URAD,
};
use super::prior_solve::{normal_equations, solve, Normal, Prior, Search, SmoothFit};
use super::smooth::{to_errors, SCol};

/// Legendre degree per error function (the plan criterion's class).
pub const DEGREE: usize = CLASS_DEGREE;
/// The fewest lines the generic identifier is the default for (about one
/// per error function; docs/geometry.md, the rich plan).
pub const MIN_LINES: usize = 18;
/// An error is undetermined when its posterior σ exceeds this fraction of
/// its prior σ (RMS over the stroke).
pub const UNDETERMINED_RATIO: f64 = 0.5;

/// Basis function j of an error at u = q / stroke: P̃_j(u) − P̃_j(0), for
/// straightness minus its end-point line (Legendre by its recurrence,
/// stable at degree 16).
pub fn basis(straightness: bool, j: usize, u: f64) -> f64 {
    let x = 2.0 * u - 1.0;
    let (mut p0, mut p1) = (1.0, x);
    for n in 1..j {
        let p2 = ((2 * n + 1) as f64 * x * p1 - n as f64 * p0) / (n + 1) as f64;
        p0 = p1;
        p1 = p2;
    }
    let pj = if j == 0 { 1.0 } else { p1 };
    let at0 = if j.is_multiple_of(2) { 1.0 } else { -1.0 };
    let v = pj - at0;
    if straightness {
        v - u * (1.0 - at0)
    } else {
        v
    }
}

/// Hyperparameters: ln σ, ln τ_pos, ln τ_str, ln τ_ang, decay p, ln scale
/// prior [ppm].
type V = [f64; 6];

/// A figure per error, by name.
type Named = Vec<(String, f64)>;

fn columns(lines: usize) -> Vec<SCol> {
    let mut cols = Vec::new();
    for term in Term::all() {
        let first = if term.is_straightness() { 2 } else { 1 };
        cols.extend((first..=DEGREE).map(|j| SCol::Term { term, j }));
    }
    cols.extend((0..3).map(SCol::Squareness));
    cols.extend((0..lines).map(SCol::Scale));
    cols
}

fn prior_var(cols: &[SCol], kinds: &[LineKind], v: &V) -> Vec<f64> {
    cols.iter()
        .map(|c| match *c {
            SCol::Term { term, j } => {
                let tau = if term.component.is_angular() {
                    v[3]
                } else if term.is_straightness() {
                    v[2]
                } else {
                    v[1]
                };
                (tau.exp() * (j as f64).powf(-v[4])).powi(2)
            }
            SCol::Squareness(_) => PRIOR_SQUARENESS_URAD.powi(2),
            SCol::Scale(i) if kinds.get(i) == Some(&LineKind::Straightness) => {
                SLOPE_PRIOR_URAD.powi(2)
            }
            SCol::Scale(_) => (2.0 * v[5]).exp(),
        })
        .collect()
}

/// Each line predicted from the others' posterior: its sum of squares and
/// what the predictive distribution expects of it.
#[derive(Clone, Debug)]
struct LineHold {
    id: String,
    readings: usize,
    /// Residual sum of squares of the full fit on this line [µm²].
    fit_ss: f64,
    /// Held-out prediction's sum of squares [µm²].
    ss: f64,
    /// tr(Σ₋ₖ Gₖ) and tr((Σ₋ₖ Gₖ)²): the others' posterior seen by the line.
    t1: f64,
    t2: f64,
}

/// The generic identification: its report, its posterior and what the
/// adequacy test needs.
pub struct Generic {
    /// The report in `smooth`'s words (hyperparameters, effective
    /// parameters, leave-one-line-out, per-line scale, σ per error,
    /// undetermined errors).
    pub fit: SmoothFit,
    /// Prior size of the lines' laser scale errors the evidence chose [ppm].
    pub scale_prior_ppm: f64,
    /// Per error: posterior σ over prior σ (RMS over the stroke).
    pub ratio: Vec<(String, f64)>,
    post: Posterior,
    hold: Vec<LineHold>,
}

/// The posterior of the columns and how to read an error from it.
struct Posterior {
    cols: Vec<SCol>,
    x: DVector<f64>,
    cov: DMatrix<f64>,
    /// The prior variance of each column at the evidence's choice.
    pv: Vec<f64>,
    stroke: [f64; 3],
}

/// Identify the 21 errors with the generic class (module doc).
pub fn identify_generic(st: &Structure, lines: &[LineObs], stroke: [f64; 3]) -> Result<Generic> {
    if lines.iter().filter(|l| l.points.len() >= 2).count() < 2 {
        bail!("fewer than two lines with at least two targets: nothing to identify from");
    }
    let cols = columns(lines.len());
    let ne = normal_equations(st, lines, &cols, |ci, pos, s, d| match cols[ci] {
        SCol::Term { term, j } => {
            let k = term.axis.index();
            d.dot(&s.terms[k][term.component.index()])
                * basis(term.is_straightness(), j, pos[k] / stroke[k])
        }
        _ => 0.0,
    });
    let start = Search {
        start: [
            0.5f64.ln(),
            10f64.ln(),
            3f64.ln(),
            10f64.ln(),
            1.0,
            0.5f64.ln(),
        ],
        lo: [
            0.002f64.ln(),
            0.01f64.ln(),
            0.01f64.ln(),
            0.01f64.ln(),
            0.0,
            0.02f64.ln(),
        ],
        hi: [
            20f64.ln(),
            1e3f64.ln(),
            1e3f64.ln(),
            1e3f64.ln(),
            8.0,
            5f64.ln(),
        ],
        step: [1.0, 1.0, 1.0, 1.0, 0.5, 1.0],
    };
    let kinds: Vec<LineKind> = lines.iter().map(|l| l.kind).collect();
    let prior = |v: &V| Some(Prior::Variances(prior_var(&cols, &kinds, v)));
    let solved = solve(&ne, &cols, lines, prior, &start)?;
    let v = solved.v;
    let pv = prior_var(&cols, &kinds, &v);
    let hold = hold_out(&ne, &pv, (2.0 * v[0]).exp(), &solved.x, lines)?;
    let errors = to_errors(&cols, solved.x.as_slice(), DEGREE, stroke);
    let post = Posterior {
        x: solved.x.clone(),
        cov: solved.cov.clone(),
        cols,
        pv: pv.clone(),
        stroke,
    };
    let (sd, ratio) = post.term_figures(&pv);
    let mut bad: Vec<String> = ratio
        .iter()
        .filter(|(_, r)| *r > UNDETERMINED_RATIO)
        .map(|(n, _)| n.clone())
        .collect();
    bad.sort();
    let mut fit = solved.fit(
        errors,
        format!("Legendre degree {DEGREE}"),
        DEGREE,
        (sd, bad),
    );
    fit.hyper.decay = Some(v[4]);
    Ok(Generic {
        fit,
        scale_prior_ppm: v[5].exp(),
        ratio,
        post,
        hold,
    })
}

/// Per line: the full fit's residual and the prediction from the others'
/// posterior (their normal equations only; the line's own scale stays at
/// its prior), with the traces its predictive variance needs.
fn hold_out(
    ne: &Normal,
    pv: &[f64],
    s2: f64,
    x: &DVector<f64>,
    lines: &[LineObs],
) -> Result<Vec<LineHold>> {
    let prior = Prior::Variances(pv.to_vec());
    let mut out = Vec::new();
    for (li, (gl, bl, yl, k)) in ne.per_line.iter().enumerate() {
        let fit_ss = (yl - 2.0 * bl.dot(x) + x.dot(&(gl * x))).max(0.0);
        let mm = prior.add_to((&ne.g - gl) / s2);
        let Some(ch) = mm.cholesky() else {
            bail!(
                "internal: the posterior without line {} is not positive definite",
                lines[li].id
            );
        };
        let sigma = ch.inverse();
        let xl = &sigma * ((&ne.b - bl) / s2);
        let ss = (yl - 2.0 * bl.dot(&xl) + xl.dot(&(gl * &xl))).max(0.0);
        let sg = &sigma * gl;
        out.push(LineHold {
            id: lines[li].id.clone(),
            readings: *k,
            fit_ss,
            ss,
            t1: sg.trace(),
            t2: sg.component_mul(&sg.transpose()).sum(),
        });
    }
    Ok(out)
}

impl Posterior {
    /// Posterior σ of `term` at axis position `q_mm` [µm or µrad].
    fn sigma(&self, term: Term, q_mm: f64) -> f64 {
        let u = q_mm / self.stroke[term.axis.index()];
        let g: Vec<(usize, f64)> = self
            .cols
            .iter()
            .enumerate()
            .filter_map(|(i, c)| match *c {
                SCol::Term { term: t, j } if t == term => {
                    Some((i, basis(t.is_straightness(), j, u)))
                }
                _ => None,
            })
            .collect();
        let mut v = 0.0;
        for &(i, gi) in &g {
            for &(j, gj) in &g {
                v += gi * gj * self.cov[(i, j)];
            }
        }
        v.max(0.0).sqrt()
    }

    /// Posterior σ of squareness `i` (EC0Y, EB0Z, EA0Z) [µrad].
    fn squareness_sigma(&self, i: usize) -> f64 {
        self.cols
            .iter()
            .position(|c| *c == SCol::Squareness(i))
            .map_or(0.0, |k| self.cov[(k, k)].max(0.0).sqrt())
    }

    /// Per error (21, `Term::all()` then squareness): posterior σ (RMS over
    /// the stroke) and posterior over prior σ.
    fn term_figures(&self, pv: &[f64]) -> (Named, Named) {
        let (mut sd, mut ratio) = (Vec::new(), Vec::new());
        for t in Term::all() {
            let l = self.stroke[t.axis.index()];
            let (mut post, mut pri) = (0.0, 0.0);
            for q in 1..POSITIONS {
                let u = q as f64 / (POSITIONS - 1) as f64;
                post += self.sigma(t, u * l).powi(2);
                pri += self
                    .cols
                    .iter()
                    .zip(pv)
                    .filter_map(|(c, p)| match *c {
                        SCol::Term { term, j } if term == t => {
                            Some(basis(t.is_straightness(), j, u).powi(2) * p)
                        }
                        _ => None,
                    })
                    .sum::<f64>();
            }
            let n = (POSITIONS - 1) as f64;
            sd.push((t.name(), (post / n).sqrt()));
            ratio.push((t.name(), (post / pri.max(1e-300)).sqrt()));
        }
        for (i, n) in SQUARENESS_NAMES.iter().enumerate() {
            let s = self.squareness_sigma(i);
            sd.push((n.to_string(), s));
            ratio.push((n.to_string(), s / PRIOR_SQUARENESS_URAD));
        }
        (sd, ratio)
    }
}

impl Generic {
    /// Posterior σ of `term` at axis position `q_mm` [µm or µrad].
    pub fn sigma(&self, term: Term, q_mm: f64) -> f64 {
        self.post.sigma(term, q_mm)
    }

    /// Posterior σ of squareness `i` (EC0Y, EB0Z, EA0Z) [µrad].
    pub fn squareness_sigma(&self, i: usize) -> f64 {
        self.post.squareness_sigma(i)
    }

    /// The posterior's columns and each one's prior variance at the
    /// evidence's choice (`shape_free`'s prior along the null directions).
    pub(crate) fn columns_and_prior(&self) -> (&[SCol], &[f64]) {
        (&self.post.cols, &self.post.pv)
    }

    /// Leave-one-line-out RMS [µm], per line.
    pub fn loo_per_line(&self) -> Vec<(String, f64)> {
        self.hold
            .iter()
            .map(|h| (h.id.clone(), (h.ss / h.readings as f64).sqrt()))
            .collect()
    }

    /// The stated adequacy test (module doc) with each line's stated σ per
    /// (averaged) reading `line_sigma_um`; the σ inflation is the held-out
    /// prediction over what the model's own posterior (at the evidence's
    /// noise) expects of it.
    pub fn adequacy(&self, line_sigma_um: &[f64], noise: StatedNoise) -> Adequacy {
        let (mut chi2, mut m) = (0.0, 0usize);
        let (mut ssw, mut mean, mut var, mut own_mean, mut ss) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let se2 = self.fit.hyper.noise_um.powi(2);
        for (h, s) in self.hold.iter().zip(line_sigma_um) {
            let (s2, n1) = (s * s, h.readings.saturating_sub(1) as f64);
            chi2 += h.fit_ss / s2;
            m += h.readings;
            ssw += h.ss / s2;
            ss += h.ss;
            mean += n1 + h.t1 / s2;
            var += 2.0 * (n1 + 2.0 * h.t1 / s2 + h.t2 / (s2 * s2));
            own_mean += se2 * n1 + h.t1;
        }
        let dof_f = (m as f64 - self.hold.len() as f64 - self.fit.effective_parameters).max(1.0);
        let dof = dof_f.round() as usize;
        let chi2_limit = chi2_upper(dof_f) * NOISE_TOLERANCE * NOISE_TOLERANCE;
        let birge = (chi2 / dof_f).sqrt();
        let nl = line_sigma_um.len().max(1) as f64;
        let s = (line_sigma_um.iter().map(|v| v * v).sum::<f64>() / nl).sqrt();
        let cnt = m.max(1) as f64;
        let q = (var / (2.0 * mean)) * chi2_upper(2.0 * mean * mean / var.max(1e-300));
        let k = NOISE_TOLERANCE * (q / cnt).sqrt();
        let (hold_rms, expected, limit) = (s * (ssw / cnt).sqrt(), s * (mean / cnt).sqrt(), s * k);
        let ratio = (ssw / mean).sqrt();
        let chi_fail = chi2 > chi2_limit;
        let hold_fail = hold_rms > limit;
        let mut parts = Vec::new();
        if chi_fail {
            parts.push(format!(
                "the fit residual is {birge:.2}× the stated noise {:.3} µm (χ² {chi2:.0} on {dof} degrees of freedom, limit {chi2_limit:.0})",
                noise.um
            ));
        }
        if hold_fail {
            parts.push(format!(
                "leave-one-line-out (each line from the others) predicts to {hold_rms:.3} µm RMS, {ratio:.1}× what an adequate model gives ({expected:.3} µm; limit {limit:.3} µm = {k:.2}× the noise)"
            ));
        }
        Adequacy {
            adequate: !(chi_fail || hold_fail),
            noise_um: noise.um,
            noise_source: noise.source(),
            chi2,
            dof,
            chi2_limit,
            birge_ratio: birge,
            holdout: "leave-one-line-out".into(),
            holdout_groups: self.hold.len(),
            holdout_rms_um: hold_rms,
            holdout_expected_rms_um: expected,
            holdout_limit_rms_um: limit,
            holdout_k: k,
            holdout_ratio: ratio,
            sigma_inflation: 1f64.max((ss / own_mean.max(1e-300)).sqrt()),
            false_reject: FALSE_REJECT,
            weak: Vec::new(),
            failure: parts.join("; "),
        }
    }
}

/// The errors' posterior as a prior for a fit with other data (the rotary
/// joint fit, `rotary::joint_generic`): the columns of the error functions
/// and the squareness errors, the lines' scales integrated out.
impl Generic {
    fn error_cols(&self) -> Vec<usize> {
        (self.post.cols.iter().enumerate())
            .filter(|(_, c)| !matches!(c, SCol::Scale(_)))
            .map(|(i, _)| i)
            .collect()
    }

    /// Posterior mean and covariance of the error columns (the order of
    /// [`Generic::error_row`]).
    pub fn error_posterior(&self) -> (DVector<f64>, DMatrix<f64>) {
        let idx = self.error_cols();
        let x = DVector::from_iterator(idx.len(), idx.iter().map(|&i| self.post.x[i]));
        let cov = DMatrix::from_fn(idx.len(), idx.len(), |r, c| self.post.cov[(idx[r], idx[c])]);
        (x, cov)
    }

    /// A reading along `dir` at axis positions `pos` with the tool at
    /// `tool`: its sensitivity to each error column (first order).
    pub fn error_row(
        &self,
        st: &Structure,
        dir: [f64; 3],
        pos: [f64; 3],
        tool: [f64; 3],
    ) -> Vec<f64> {
        let s = sensitivity(st, pos, tool);
        let d = Vector3::from(dir);
        let stroke = self.post.stroke;
        (self.error_cols().into_iter())
            .map(|i| match self.post.cols[i] {
                SCol::Term { term, j } => {
                    let k = term.axis.index();
                    d.dot(&s.terms[k][term.component.index()])
                        * basis(term.is_straightness(), j, pos[k] / stroke[k])
                }
                SCol::Squareness(q) => d.dot(&s.squareness[q]),
                SCol::Scale(_) => 0.0,
            })
            .collect()
    }

    /// The errors at the posterior mean plus `delta` on the error columns.
    pub fn errors_with(&self, delta: &[f64]) -> GeometricErrors {
        let mut x = self.post.x.clone();
        for (i, d) in self.error_cols().into_iter().zip(delta) {
            x[i] += d;
        }
        to_errors(&self.post.cols, x.as_slice(), DEGREE, self.post.stroke)
    }

    /// RMS of the lines' residual [µm] (each line's zero taken out, its
    /// scale at the posterior mean) with `delta` added to the error columns.
    pub fn line_residual_rms(&self, st: &Structure, lines: &[LineObs], delta: &[f64]) -> f64 {
        let idx = self.error_cols();
        let mut x: Vec<f64> = idx.iter().map(|&i| self.post.x[i]).collect();
        x.iter_mut().zip(delta).for_each(|(a, d)| *a += d);
        let (mut ss, mut m) = (0.0, 0usize);
        for (li, l) in lines.iter().enumerate() {
            let scale = (self.post.cols.iter())
                .position(|c| *c == SCol::Scale(li))
                .map_or(0.0, |k| self.post.x[k]);
            let p0 = Vector3::from(l.points.first().map_or([0.0; 3], |p| p.pos_mm));
            let d = Vector3::from(l.direction);
            let r: Vec<f64> = (l.points.iter())
                .map(|p| {
                    let row = self.error_row(st, l.sense, p.pos_mm, l.tool_offset_mm);
                    let along = d.dot(&(Vector3::from(p.pos_mm) - p0));
                    let pred: f64 = row.iter().zip(&x).map(|(a, b)| a * b).sum();
                    p.disp_um - pred - along * 1e-3 * scale
                })
                .collect();
            let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
            ss += r.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
            m += r.len();
        }
        (ss / m.max(1) as f64).sqrt()
    }
}

/// The lines' design matrix for `cols` (one row per point; straightness
/// and angle terms by their Legendre basis, squareness, no scale), each
/// line's rows centred (its zero is free) and a straightness line's also
/// free of its slope (the optic's alignment), at least as many rows as
/// columns (zero rows pad a short plan).
pub(crate) fn centred_design(
    st: &Structure,
    lines: &[LineObs],
    stroke: [f64; 3],
    cols: &[SCol],
) -> DMatrix<f64> {
    let n = cols.len();
    let m: usize = lines.iter().map(|l| l.points.len()).sum();
    let mut a = DMatrix::zeros(m.max(n), n);
    let mut r = 0;
    for l in lines {
        let (d, r0) = (Vector3::from(l.sense), r);
        for p in &l.points {
            let s = sensitivity(st, p.pos_mm, l.tool_offset_mm);
            for (ci, c) in cols.iter().enumerate() {
                a[(r, ci)] = match *c {
                    SCol::Term { term, j } => {
                        let k = term.axis.index();
                        d.dot(&s.terms[k][term.component.index()])
                            * basis(term.is_straightness(), j, p.pos_mm[k] / stroke[k])
                    }
                    SCol::Squareness(i) => d.dot(&s.squareness[i]),
                    SCol::Scale(_) => 0.0,
                };
            }
            r += 1;
        }
        for ci in 0..n {
            let mut c = a.view_mut((r0, ci), (r - r0, 1));
            let mean = c.mean();
            c.add_scalar_mut(-mean);
        }
        if l.kind == LineKind::Straightness {
            let slope = centred_travel(l);
            for ci in 0..n {
                let mut c = a.view_mut((r0, ci), (r - r0, 1));
                let k = slope.dot(&c);
                c -= &slope * k;
            }
        }
    }
    a
}

/// The line's travel from its first target at each target, centred and
/// of unit norm (a straightness line's slope direction in reading space).
fn centred_travel(l: &LineObs) -> DVector<f64> {
    let t = Vector3::from(l.direction);
    let p0 = Vector3::from(l.points.first().map_or([0.0; 3], |p| p.pos_mm));
    let mut s = DVector::from_iterator(
        l.points.len(),
        (l.points.iter()).map(|p| t.dot(&(Vector3::from(p.pos_mm) - p0))),
    );
    s.add_scalar_mut(-s.mean());
    let n = s.norm();
    if n > 0.0 {
        s /= n;
    }
    s
}

/// The combinations of the class's errors no line sees (the plan's null
/// directions for these lines, `plan::null_directions`' tolerance), each
/// in words ("EAZ − ECZ (with EBZ)") with the errors in it.
pub fn null_combinations(
    st: &Structure,
    lines: &[LineObs],
    stroke: [f64; 3],
) -> Vec<(String, Vec<String>)> {
    let cols: Vec<SCol> = columns(0);
    let n = cols.len();
    let mut a = centred_design(st, lines, stroke, &cols);
    for j in 0..n {
        let nn = a.column(j).norm();
        if nn > 0.0 {
            a.column_mut(j).scale_mut(1.0 / nn);
        }
    }
    let svd = a.qr().r().svd(false, true);
    let Some(vt) = svd.v_t else {
        return Vec::new();
    };
    let smax = svd.singular_values.max().max(f64::MIN_POSITIVE);
    let labels: Vec<String> = cols
        .iter()
        .map(|c| match *c {
            SCol::Term { term, .. } => term.name(),
            SCol::Squareness(i) => SQUARENESS_NAMES[i].to_string(),
            SCol::Scale(_) => String::new(),
        })
        .collect();
    (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] < NULL_TOLERANCE * smax)
        .filter_map(|i| words(&vt.row(i).transpose(), &labels))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smooth::basis_monomials;

    #[test]
    fn the_recurrence_basis_is_the_monomial_one_to_degree_16() {
        for j in 1..=DEGREE {
            for straight in [false, true] {
                if straight && j < 2 {
                    continue;
                }
                let m = basis_monomials(straight, j);
                for u in [0.0, 0.13, 0.5, 0.77, 1.0] {
                    let mono = m.iter().rev().fold(0.0, |a, c| a * u + c) * u;
                    assert!((mono - basis(straight, j, u)).abs() < 1e-5, "{j} {u}");
                }
            }
        }
    }
}

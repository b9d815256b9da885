//! Measurement plans that pin the machine down (issue 49 item 1).
//!
//! The 14-line plan (`lines::plan14`) was chosen for the polynomial model of
//! `identify`'s default degrees. Against a model class that is not told the
//! error shape it has exact null directions: combinations of the 21 errors
//! that change no reading of any of its lines, yet move the tool tip
//! (examples/null_probe.rs). No identifier can fix those; only lines can.
//!
//! This module states the criterion a plan is judged by and designs a plan
//! by it:
//!
//! * **Class** (the one `identify --method smooth` uses, richer): every
//!   error function a shifted-Legendre series of degree [`CLASS_DEGREE`],
//!   zero at the axis zero, straightness also zero at the stroke's end (the
//!   ISO end-point reference); the three squareness errors.
//! * **Prior** (stated, not fitted): coefficient j of a term has standard
//!   deviation τ·j^(−[`PRIOR_DECAY`]), τ = [`PRIOR_POSITIONING_UM`],
//!   [`PRIOR_STRAIGHTNESS_UM`], [`PRIOR_ANGULAR_URAD`]; squareness
//!   [`PRIOR_SQUARENESS_URAD`].
//! * **Nuisance per line**: its zero (free) and its laser scale
//!   ([`SCALE_PPM`] standard deviation), both integrated out; a
//!   straightness-optics line reads along its `sense` with a free offset
//!   and a slope of [`SLOPE_PRIOR_URAD`] in place of the scale.
//! * **Noise**: σ per reading of one run; a line's reading is the mean of
//!   its forward and backward runs (σ/√2), [`TARGETS`] targets per line.
//! * **Criterion**: the posterior standard deviation of each of the 21
//!   errors, worst over [`POSITIONS`] positions of its stroke, worst over
//!   the errors, in units of the determination tolerance
//!   (`smooth::DETERMINED_UM` µm, `smooth::DETERMINED_URAD` µrad); ties by
//!   the mean over the errors. Beside it: the number of null directions of
//!   the plan for the class (rank deficiency of its design matrix, each
//!   line's zero free) and the fewest of the plan's lines, in
//!   order, that have none.
//!
//! [`crate::plan_design::design`] picks lines from a candidate pool ([`pool`]: today's 14, face
//! lines between half-stroke grid points with slopes unlike the corner
//! diagonals and shifted parallel in their plane, body lines of such
//! slopes, axis-parallel lines at other grid positions, each with six
//! reflector offsets) by greedy addition and then exchange on that
//! criterion. [`rich_plan`] is the plan it chose for the default volume
//! (800 × 500 × 400 mm, tool 100 mm, side 100 mm, σ 0.5 µm; reproduced by
//! `cargo run -p tcomp-geometry --release --example plan_design`), its
//! lines given on the half-stroke grid so they scale with any volume, and
//! its criterion evaluated for the volume and noise asked.

use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;

use super::errors::{Term, SQUARENESS_NAMES};
use super::identify::LineKind;
use super::kinematics::{sensitivity, Structure};
use super::lines::{plan14, LineSpec};
use super::smooth::{DETERMINED_UM, DETERMINED_URAD};

/// Legendre degree per error function of the class a plan is judged by.
pub const CLASS_DEGREE: usize = 16;
/// Prior size of the positioning errors' Legendre coefficients [µm] …
pub const PRIOR_POSITIONING_UM: f64 = 10.0;
/// … of the straightness errors' [µm] …
pub const PRIOR_STRAIGHTNESS_UM: f64 = 6.0;
/// … and of the angular errors' [µrad] (the project's error sizes, `sim::ErrorSizes`).
pub const PRIOR_ANGULAR_URAD: f64 = 20.0;
/// Coefficient j has prior standard deviation τ·j^(−PRIOR_DECAY).
pub const PRIOR_DECAY: f64 = 1.0;
/// Prior standard deviation of a squareness error [µrad] (weak).
pub const PRIOR_SQUARENESS_URAD: f64 = 200.0;
/// Per-line laser scale error, standard deviation [ppm] (beam misalignment
/// cosine error, wavelength compensation).
pub const SCALE_PPM: f64 = 0.5;
/// Prior standard deviation of a straightness optic's slope against the
/// travel [µrad] (its alignment, 1 mm/m: far above any machine angle, so
/// the line's slope is in effect free; `generic` uses the same).
pub const SLOPE_PRIOR_URAD: f64 = 1000.0;
/// Targets per line, both ends included (what `geometry simulate` writes).
pub const TARGETS: usize = 41;
/// Positions per stroke at which each error's σ is taken (its worst).
pub const POSITIONS: usize = 21;
/// A singular value of the design (unit-norm columns) below this fraction
/// of the largest is a null direction.
pub const NULL_TOLERANCE: f64 = 1e-9;
/// The most lines a recommended displacement-only plan may have.
pub const MAX_LINES: usize = 28;

/// One unknown of the class.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Col {
    Term { term: Term, j: usize },
    Squareness(usize),
}

/// Legendre P_j(x) by the three-term recurrence (stable to degree 16 and
/// beyond, unlike the monomial form).
fn legendre(j: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, x);
    if j == 0 {
        return p0;
    }
    for n in 1..j {
        let p2 = ((2 * n + 1) as f64 * x * p1 - n as f64 * p0) / (n + 1) as f64;
        p0 = p1;
        p1 = p2;
    }
    p1
}

/// Basis function j of a term at u = q / stroke: P̃_j(u) − P̃_j(0), and for
/// straightness minus its end-point line (the basis of `smooth`).
fn basis(straightness: bool, j: usize, u: f64) -> f64 {
    let at0 = if j.is_multiple_of(2) { 1.0 } else { -1.0 };
    let v = legendre(j, 2.0 * u - 1.0) - at0;
    if straightness {
        v - u * (1.0 - at0)
    } else {
        v
    }
}

fn columns(degree: usize) -> Vec<Col> {
    let mut cols = Vec::new();
    for term in Term::all() {
        let first = if term.is_straightness() { 2 } else { 1 };
        cols.extend((first..=degree).map(|j| Col::Term { term, j }));
    }
    cols.extend((0..3).map(Col::Squareness));
    cols
}

fn prior_sd(c: &Col) -> f64 {
    match *c {
        Col::Term { term, j } => {
            let tau = if term.component.is_angular() {
                PRIOR_ANGULAR_URAD
            } else if term.is_straightness() {
                PRIOR_STRAIGHTNESS_UM
            } else {
                PRIOR_POSITIONING_UM
            };
            tau * (j as f64).powf(-PRIOR_DECAY)
        }
        Col::Squareness(_) => PRIOR_SQUARENESS_URAD,
    }
}

/// A line's rows for the class (the error along the line's sense), each
/// column centred (the line's free zero removed), and its laser-scale
/// column (µm per ppm; a straightness line's slope, µm per µrad), centred.
pub(crate) fn line_rows(
    st: &Structure,
    stroke: [f64; 3],
    cols: &[Col],
    l: &LineSpec,
) -> (DMatrix<f64>, DVector<f64>) {
    let tg = l.targets(TARGETS);
    let d = Vector3::from(l.sense);
    let mut a = DMatrix::zeros(tg.len(), cols.len());
    let mut sc = DVector::zeros(tg.len());
    for (r, (s_mm, p)) in tg.iter().enumerate() {
        let s = sensitivity(st, *p, l.tool_offset_mm);
        for (ci, c) in cols.iter().enumerate() {
            a[(r, ci)] = match *c {
                Col::Term { term, j } => {
                    let k = term.axis.index();
                    d.dot(&s.terms[k][term.component.index()])
                        * basis(term.is_straightness(), j, p[k] / stroke[k])
                }
                Col::Squareness(i) => d.dot(&s.squareness[i]),
            };
        }
        sc[r] = s_mm * 1e-3;
    }
    for ci in 0..cols.len() {
        let m = a.column(ci).mean();
        a.column_mut(ci).add_scalar_mut(-m);
    }
    let m = sc.mean();
    sc.add_scalar_mut(-m);
    (a, sc)
}

/// Prior standard deviation of the line's scale column: its laser scale
/// [ppm], or a straightness optic's slope [µrad].
pub(crate) fn nuisance_sd(l: &LineSpec) -> f64 {
    match l.kind {
        LineKind::Displacement => SCALE_PPM,
        LineKind::Straightness => SLOPE_PRIOR_URAD,
    }
}

/// The line's information in whitened form B (BᵀB), its zero and laser
/// scale (of prior σ `nuisance_sd`, [`nuisance_sd`]) integrated out:
/// BᵀB = Ãᵀ(σ²I + s²ããᵀ)⁻¹Ã on the centred rows.
pub(crate) fn whitened(
    a: &DMatrix<f64>,
    sc: &DVector<f64>,
    sigma: f64,
    nuisance_sd: f64,
) -> DMatrix<f64> {
    let s2 = nuisance_sd * nuisance_sd;
    let n2 = sc.norm_squared();
    let mut b = a / sigma;
    if n2 > 0.0 {
        let delta = 1.0 - sigma / (sigma * sigma + s2 * n2).sqrt();
        let u = sc / n2.sqrt();
        let ub = u.transpose() * &b;
        b -= (u * delta) * ub;
    }
    b
}

/// The posterior standard deviation of every error, worst over its stroke.
#[derive(Clone, Debug, Serialize)]
pub struct TermSigma {
    pub error: String,
    pub unit: &'static str,
    pub sigma: f64,
}

/// A plan judged by the stated criterion.
#[derive(Clone, Debug, Serialize)]
pub struct Criterion {
    pub lines: usize,
    /// Noise of one reading of one run [µm] the figures are for.
    pub noise_um: f64,
    /// Worst posterior σ of the translational errors [µm] and which.
    pub worst_um: f64,
    pub worst_um_error: String,
    /// Worst posterior σ of the angular and squareness errors [µrad] and which.
    pub worst_urad: f64,
    pub worst_urad_error: String,
    /// max(worst_um / 1 µm, worst_urad / 4 µrad): ≤ 0.5 means every error
    /// is determined within the tolerance at two σ.
    pub score: f64,
    /// Null directions for the class (combinations no line sees).
    pub null_directions: usize,
    /// The fewest of the plan's lines, taken in order, without a null
    /// direction (None: even all of them have one).
    pub min_lines_identifiable: Option<usize>,
    pub per_error: Vec<TermSigma>,
    /// What the figures assume, in words.
    pub class: String,
}

/// The stated class and the evaluation points of every error.
pub(crate) struct Setup {
    pub(crate) cols: Vec<Col>,
    /// n × m: column q is the linear functional "error e at position u".
    pub(crate) phi: DMatrix<f64>,
    /// Per evaluation point: (error index 0‥20, angular).
    pub(crate) which: Vec<(usize, bool)>,
    pub(crate) names: Vec<(String, bool)>,
    pub(crate) prior_precision: DVector<f64>,
}

pub(crate) fn setup(degree: usize) -> Setup {
    let cols = columns(degree);
    let mut names = Vec::new();
    let mut evals: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut which = Vec::new();
    for (ti, t) in Term::all().enumerate() {
        names.push((t.name(), t.component.is_angular()));
        for q in 0..POSITIONS {
            let u = q as f64 / (POSITIONS - 1) as f64;
            let v: Vec<(usize, f64)> = cols
                .iter()
                .enumerate()
                .filter_map(|(i, c)| match *c {
                    Col::Term { term, j } if term == t => {
                        Some((i, basis(t.is_straightness(), j, u)))
                    }
                    _ => None,
                })
                .collect();
            evals.push(v);
            which.push((ti, t.component.is_angular()));
        }
    }
    for (k, n) in SQUARENESS_NAMES.iter().enumerate() {
        let i = cols
            .iter()
            .position(|c| *c == Col::Squareness(k))
            .unwrap_or(0);
        names.push((n.to_string(), true));
        evals.push(vec![(i, 1.0)]);
        which.push((18 + k, true));
    }
    let mut phi = DMatrix::zeros(cols.len(), evals.len());
    for (q, v) in evals.iter().enumerate() {
        for (i, x) in v {
            phi[(*i, q)] = *x;
        }
    }
    let prior_precision =
        DVector::from_iterator(cols.len(), cols.iter().map(|c| prior_sd(c).powi(-2)));
    Setup {
        cols,
        phi,
        which,
        names,
        prior_precision,
    }
}

/// Per error: the largest variance over its evaluation points.
pub(crate) fn worst_variances(s: &Setup, var: &[f64]) -> Vec<f64> {
    let mut w = vec![0.0f64; s.names.len()];
    for (q, (e, _)) in s.which.iter().enumerate() {
        w[*e] = w[*e].max(var[q]);
    }
    w
}

/// The design objective from per-error worst variances: the worst σ in
/// units of the tolerance, plus a hundredth of the mean (ties).
pub(crate) fn objective(s: &Setup, worst_var: &[f64]) -> f64 {
    let r: Vec<f64> = worst_var
        .iter()
        .zip(&s.names)
        .map(|(v, (_, ang))| v.max(0.0).sqrt() / if *ang { DETERMINED_URAD } else { DETERMINED_UM })
        .collect();
    let max = r.iter().copied().fold(0.0, f64::max);
    max + 0.01 * r.iter().sum::<f64>() / r.len() as f64
}

/// Noise of a line's (two-run averaged) reading [µm].
pub(crate) fn reading_sigma(noise_um: f64) -> f64 {
    (noise_um / 2f64.sqrt()).max(1e-6)
}

pub(crate) fn posterior_cov(s: &Setup, bs: &[DMatrix<f64>]) -> DMatrix<f64> {
    let n = s.cols.len();
    let mut m = DMatrix::from_diagonal(&s.prior_precision);
    for b in bs {
        m += b.transpose() * b;
    }
    m.cholesky()
        .map(|c| c.inverse())
        .unwrap_or_else(|| DMatrix::identity(n, n))
}

pub(crate) fn variances(s: &Setup, c: &DMatrix<f64>) -> Vec<f64> {
    let cp = c * &s.phi;
    (0..s.phi.ncols())
        .map(|q| s.phi.column(q).dot(&cp.column(q)))
        .collect()
}

/// The singular values of a plan's design matrix for the class of Legendre
/// degree `degree` (every line's rows centred for its free zero, columns
/// scaled to unit norm), relative to the largest, smallest first.
///
/// The lines' laser scales are not columns here: with a free scale per
/// line the linear part of the machine (first Legendre terms, squareness)
/// trades against the scales on any plan; the scale's stated size
/// ([`SCALE_PPM`]) bounds that trade, and the criterion's σ's include it.
pub fn design_singular_values(
    st: &Structure,
    stroke: [f64; 3],
    plan: &[LineSpec],
    degree: usize,
) -> Vec<f64> {
    let cols = columns(degree);
    let n = cols.len();
    let rows: usize = plan.len() * TARGETS;
    let mut a = DMatrix::zeros(rows.max(n), n);
    for (li, l) in plan.iter().enumerate() {
        let (mut al, sc) = line_rows(st, stroke, &cols, l);
        if l.kind == LineKind::Straightness && sc.norm() > 0.0 {
            // The optic's slope is free: what it sees is orthogonal to it.
            let u = &sc / sc.norm();
            let k = u.transpose() * &al;
            al -= u * k;
        }
        a.view_mut((li * TARGETS, 0), (al.nrows(), n))
            .copy_from(&al);
    }
    for j in 0..n {
        let nn = a.column(j).norm();
        if nn > 0.0 {
            a.column_mut(j).scale_mut(1.0 / nn);
        }
    }
    // The singular values of A are those of its triangular factor (n × n).
    let sv = a.qr().r().singular_values();
    let smax = sv
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let mut v: Vec<f64> = sv.iter().map(|s| s / smax).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// Null directions of a plan for the class of Legendre degree `degree`:
/// combinations of the 21 errors that change no reading of any line (its
/// zero free) — the rank deficiency of its design matrix
/// ([`design_singular_values`] below [`NULL_TOLERANCE`]).
pub fn null_directions(
    st: &Structure,
    stroke: [f64; 3],
    plan: &[LineSpec],
    degree: usize,
) -> usize {
    design_singular_values(st, stroke, plan, degree)
        .iter()
        .filter(|s| **s < NULL_TOLERANCE)
        .count()
}

/// The plan's criterion at `noise_um` (σ of one reading of one run).
pub fn evaluate(st: &Structure, stroke: [f64; 3], plan: &[LineSpec], noise_um: f64) -> Criterion {
    let s = setup(CLASS_DEGREE);
    let sigma = reading_sigma(noise_um);
    let bs: Vec<DMatrix<f64>> = plan
        .iter()
        .map(|l| {
            let (a, sc) = line_rows(st, stroke, &s.cols, l);
            whitened(&a, &sc, sigma, nuisance_sd(l))
        })
        .collect();
    let c = posterior_cov(&s, &bs);
    let var = variances(&s, &c);
    let wv = worst_variances(&s, &var);
    let per_error: Vec<TermSigma> = s
        .names
        .iter()
        .zip(&wv)
        .map(|((n, ang), v)| TermSigma {
            error: n.clone(),
            unit: if *ang { "urad" } else { "um" },
            sigma: v.max(0.0).sqrt(),
        })
        .collect();
    let worst = |ang: bool| {
        per_error
            .iter()
            .filter(|t| (t.unit == "urad") == ang)
            .max_by(|a, b| a.sigma.total_cmp(&b.sigma))
            .map(|t| (t.sigma, t.error.clone()))
            .unwrap_or((0.0, String::new()))
    };
    let (wu, wun) = worst(false);
    let (wa, wan) = worst(true);
    let nulls = null_directions(st, stroke, plan, CLASS_DEGREE);
    // Fewest lines in order without a null: nulls only fall as lines are
    // added, so bisect on the prefix length.
    let min_lines = if nulls > 0 {
        None
    } else {
        let (mut lo, mut hi) = (1usize, plan.len());
        while lo < hi {
            let mid = (lo + hi) / 2;
            if null_directions(st, stroke, &plan[..mid], CLASS_DEGREE) == 0 {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        Some(hi)
    };
    Criterion {
        lines: plan.len(),
        noise_um,
        worst_um: wu,
        worst_um_error: wun,
        worst_urad: wa,
        worst_urad_error: wan,
        score: (wu / DETERMINED_UM).max(wa / DETERMINED_URAD),
        null_directions: nulls,
        min_lines_identifiable: min_lines,
        per_error,
        class: class_words(),
    }
}

/// The class, prior and nuisance the criterion assumes, in words.
pub fn class_words() -> String {
    format!(
        "each error a Legendre series of degree {CLASS_DEGREE} (zero at the axis zero, straightness also at the stroke's end), \
         prior coefficient j: {PRIOR_POSITIONING_UM} µm (positioning), {PRIOR_STRAIGHTNESS_UM} µm (straightness), \
         {PRIOR_ANGULAR_URAD} µrad (angles) × j^-{PRIOR_DECAY}, squareness {PRIOR_SQUARENESS_URAD} µrad; \
         per line a free zero and a laser scale of {SCALE_PPM} ppm (a straightness line: a slope of {SLOPE_PRIOR_URAD} µrad); {TARGETS} targets per line, \
         forward and backward runs averaged; σ of each error worst over {POSITIONS} positions of its stroke"
    )
}

/// Reflector offsets a pool line may use (tool = reflector length, side =
/// lateral offset).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Offset {
    /// (side, 0, tool)
    PlusX,
    /// (−side, 0, tool)
    MinusX,
    /// (0, side, tool)
    PlusY,
    /// (0, −side, tool)
    MinusY,
    /// (side, side, tool)
    PlusXY,
    /// (0, 0, 2.5 tool): the long extension.
    Long,
}

impl Offset {
    pub const ALL: [Offset; 6] = [
        Offset::PlusX,
        Offset::MinusX,
        Offset::PlusY,
        Offset::MinusY,
        Offset::PlusXY,
        Offset::Long,
    ];
    pub fn mm(self, tool: f64, side: f64) -> [f64; 3] {
        match self {
            Offset::PlusX => [side, 0.0, tool],
            Offset::MinusX => [-side, 0.0, tool],
            Offset::PlusY => [0.0, side, tool],
            Offset::MinusY => [0.0, -side, tool],
            Offset::PlusXY => [side, side, tool],
            Offset::Long => [0.0, 0.0, 2.5 * tool],
        }
    }
}

/// A line between two points of the half-stroke grid {0, ½, 1}³ (in halves
/// of each stroke) with a reflector offset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridLine {
    pub from: [u8; 3],
    pub to: [u8; 3],
    pub offset: Offset,
}

impl GridLine {
    /// What the line is, in words (its purpose in the plan).
    pub fn purpose(&self) -> String {
        let d: Vec<i32> = (0..3)
            .map(|k| self.to[k] as i32 - self.from[k] as i32)
            .collect();
        let nz: Vec<usize> = (0..3).filter(|k| d[*k] != 0).collect();
        let ax = ['X', 'Y', 'Z'];
        let at = |k: usize| {
            let v = ["0", "½ stroke", "stroke"][self.from[k] as usize];
            format!("{} = {v}", ['x', 'y', 'z'][k])
        };
        match nz.len() {
            1 => {
                let others: Vec<String> = (0..3).filter(|k| *k != nz[0]).map(at).collect();
                format!("{} axis at {}", ax[nz[0]], others.join(", "))
            }
            2 => {
                let other = (0..3).find(|k| !nz.contains(k)).unwrap_or(2);
                let corner = d[nz[0]].abs() == 2 && d[nz[1]].abs() == 2;
                format!(
                    "{}{} plane at {}, {}",
                    ax[nz[0]],
                    ax[nz[1]],
                    at(other),
                    if corner {
                        "face diagonal shifted parallel".to_string()
                    } else {
                        format!(
                            "slope {}:{} (shifted, unlike the corner diagonals)",
                            d[nz[0]].abs(),
                            d[nz[1]].abs()
                        )
                    }
                )
            }
            _ => {
                if d.iter().all(|v| v.abs() == 2) {
                    "body diagonal".to_string()
                } else {
                    format!(
                        "body line, slope {}:{}:{}",
                        d[0].abs(),
                        d[1].abs(),
                        d[2].abs()
                    )
                }
            }
        }
    }

    pub fn spec(&self, id: &str, stroke: [f64; 3], tool: f64, side: f64) -> LineSpec {
        let p = |h: [u8; 3]| [0, 1, 2].map(|k| stroke[k] * h[k] as f64 / 2.0);
        let (a, b) = (p(self.from), p(self.to));
        let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        LineSpec {
            id: id.to_string(),
            start_mm: a,
            direction: d.map(|c| c / len),
            length_mm: len,
            tool_offset_mm: self.offset.mm(tool, side),
            purpose: self.purpose(),
            kind: Default::default(),
            sense: d.map(|c| c / len),
        }
    }
}

/// The candidate lines beyond today's 14: on the half-stroke grid, every
/// line that runs the full stroke of at least one axis — axis-parallel
/// lines at the grid's other positions, face lines (corner diagonals
/// shifted parallel, and slopes 2:1, 1:2 in every plane at every level),
/// body lines of slopes with a full and a half stroke — each with the six
/// reflector offsets of [`Offset`].
pub fn pool() -> Vec<GridLine> {
    let mut geo: Vec<([u8; 3], [u8; 3])> = Vec::new();
    let pts: Vec<[u8; 3]> = (0..27u8).map(|i| [i % 3, (i / 3) % 3, i / 9]).collect();
    for a in &pts {
        for b in &pts {
            let d: Vec<i32> = (0..3).map(|k| b[k] as i32 - a[k] as i32).collect();
            // One direction per line: its first moving axis runs forward.
            let Some(first) = d.iter().find(|v| **v != 0) else {
                continue;
            };
            if *first < 0 || !d.iter().any(|v| v.abs() == 2) {
                continue;
            }
            geo.push((*a, *b));
        }
    }
    let mut out = Vec::new();
    for (from, to) in geo {
        for offset in Offset::ALL {
            out.push(GridLine { from, to, offset });
        }
    }
    out
}

/// Today's 14 lines on the grid (as `lines::plan14`).
pub fn plan14_grid() -> Vec<GridLine> {
    use Offset::*;
    let g = |from, to, offset| GridLine { from, to, offset };
    vec![
        g([0, 0, 0], [2, 2, 2], PlusX),
        g([2, 0, 0], [0, 2, 2], PlusXY),
        g([0, 2, 0], [2, 0, 2], PlusXY),
        g([2, 2, 0], [0, 0, 2], Long),
        g([2, 0, 0], [1, 2, 2], Long),
        g([0, 0, 0], [2, 2, 0], PlusY),
        g([2, 0, 2], [0, 2, 2], MinusX),
        g([0, 2, 0], [2, 2, 2], Long),
        g([2, 0, 0], [0, 0, 2], MinusX),
        g([2, 0, 0], [2, 2, 2], MinusX),
        g([2, 2, 0], [2, 0, 2], MinusX),
        g([0, 0, 0], [0, 2, 0], PlusX),
        g([2, 0, 2], [2, 2, 2], Long),
        g([0, 0, 0], [0, 0, 2], PlusXY),
    ]
}

/// The 14 lines `design` added to today's 14 from [`pool`] for the default
/// volume (800 × 500 × 400 mm, tool 100, side 100, σ 0.5 µm), in the order
/// chosen (examples/plan_design.rs prints this list).
pub fn rich_additions() -> Vec<GridLine> {
    use Offset::*;
    let g = |from, to, offset| GridLine { from, to, offset };
    vec![
        g([0, 0, 0], [2, 0, 0], MinusY),
        g([0, 0, 2], [1, 0, 0], PlusY),
        g([0, 1, 0], [1, 0, 2], Long),
        g([1, 2, 0], [2, 0, 0], MinusX),
        g([0, 2, 2], [2, 2, 0], MinusY),
        g([0, 0, 2], [1, 2, 0], MinusY),
        g([0, 0, 1], [1, 2, 2], PlusY),
        g([0, 0, 2], [0, 1, 0], MinusY),
        g([0, 2, 0], [1, 2, 2], MinusY),
        g([0, 2, 2], [2, 2, 0], PlusY),
        g([0, 2, 0], [1, 0, 2], MinusY),
        g([0, 1, 0], [1, 2, 2], Long),
        g([0, 2, 2], [2, 0, 0], Long),
        g([1, 1, 0], [2, 0, 2], MinusY),
    ]
}

/// A plan and its criterion.
#[derive(Clone, Debug)]
pub struct DesignedPlan {
    pub name: &'static str,
    pub lines: Vec<LineSpec>,
    pub criterion: Criterion,
}

/// The recommended displacement-only plan (≤ [`MAX_LINES`] lines): today's
/// 14 and the 14 lines of [`rich_additions`], scaled to the volume, with
/// its criterion at `noise_um` for the XY/Z structure.
pub fn rich_plan(stroke: [f64; 3], tool: f64, side: f64, noise_um: f64) -> DesignedPlan {
    let st = Structure::parse("XY/Z").expect("XY/Z is a structure");
    rich_plan_for(&st, stroke, tool, side, noise_um)
}

/// The rich plan's lines (today's 14 first, L01‥L14, then L15‥).
pub fn rich_lines(stroke: [f64; 3], tool: f64, side: f64) -> Vec<LineSpec> {
    let mut lines = plan14(stroke, tool, side);
    for (i, g) in rich_additions().iter().enumerate() {
        lines.push(g.spec(&format!("L{:02}", 15 + i), stroke, tool, side));
    }
    lines
}

/// [`rich_plan`] for another structure.
pub fn rich_plan_for(
    st: &Structure,
    stroke: [f64; 3],
    tool: f64,
    side: f64,
    noise_um: f64,
) -> DesignedPlan {
    let lines = rich_lines(stroke, tool, side);
    let criterion = evaluate(st, stroke, &lines, noise_um);
    DesignedPlan {
        name: "rich",
        lines,
        criterion,
    }
}

/// Today's 14-line plan with its criterion.
pub fn plan14_designed(
    st: &Structure,
    stroke: [f64; 3],
    tool: f64,
    side: f64,
    noise_um: f64,
) -> DesignedPlan {
    let lines = plan14(stroke, tool, side);
    let criterion = evaluate(st, stroke, &lines, noise_um);
    DesignedPlan {
        name: "14",
        lines,
        criterion,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_basis_matches_the_smooth_identifiers() {
        for j in 1..=10 {
            for straight in [false, true] {
                if straight && j < 2 {
                    continue;
                }
                let m = super::super::smooth::basis_monomials(straight, j);
                for u in [0.0, 0.13, 0.5, 0.77, 1.0] {
                    let mono = m.iter().rev().fold(0.0, |a, c| a * u + c) * u;
                    assert!((mono - basis(straight, j, u)).abs() < 1e-6, "{j} {u}");
                }
            }
        }
    }

    #[test]
    fn plan14_grid_is_plan14() {
        let (s, t, d) = ([800.0, 500.0, 400.0], 100.0, 100.0);
        for (a, g) in plan14(s, t, d).iter().zip(plan14_grid()) {
            let b = g.spec(&a.id, s, t, d);
            for k in 0..3 {
                assert!((a.start_mm[k] - b.start_mm[k]).abs() < 1e-9);
                assert!((a.direction[k] - b.direction[k]).abs() < 1e-12);
                assert_eq!(a.tool_offset_mm[k], b.tool_offset_mm[k]);
            }
        }
    }
}

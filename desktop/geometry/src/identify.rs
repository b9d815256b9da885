//! Identification of the 21 errors from displacement lines: one linear
//! least-squares problem (a direct solution, no iteration).
//!
//! Unknowns: per error term a polynomial in u = q / stroke of degree
//! `degree` without constant (zero at K = 0). The straightness terms follow
//! the ISO 230-1 reference-line convention: their end-point line is taken
//! out (basis u^j − u, zero at both ends) and carried by the squareness
//! errors and the orientation of the machine frame (X defines x, X and Y the
//! xy plane), which displacement along lines cannot see. The three
//! squareness errors are constants. Each line's reading is zeroed at its
//! first target, so each line has a free offset: it is eliminated by
//! centring the line's rows (the same as an offset unknown per line).
//!
//! The model is the first-order kinematics (`kinematics::sensitivity`);
//! readings come from files. Conditioning is reported from the SVD of the
//! design matrix with unit-norm columns; directions with a singular value
//! below `RANK_TOL × σ_max` are reported as not observable, never filled in.

use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;

use super::errors::{GeometricErrors, Poly, Squareness, Term, SQUARENESS_NAMES};
use super::kinematics::{sensitivity, Structure};
use super::unit_svd::{complete_basis, unit_svd};

/// Relative singular-value threshold (of the design matrix with unit-norm
/// columns) below which a direction counts as not observable. The full
/// 14-line plan's smallest is 2.6e-3 (condition number 381); dropping a
/// line leaves directions at 1e-5 … 1e-4 whose solution is noise times
/// 10⁴ (issue 29: EXX −184 µm, EAZ −1,946 µrad from 13 lines), so the
/// threshold sits at 1e-3: a condition number above 1,000 is refused.
pub const RANK_TOL: f64 = 1e-3;

/// Weight (unit-norm null vector, unit-norm columns) from which a column
/// counts as part of an unobservable combination.
pub const NULL_WEIGHT: f64 = 0.05;

/// One target of one line as the identification sees it.
#[derive(Clone, Debug)]
pub struct Observation {
    pub pos_mm: [f64; 3],
    /// Reading [µm] along the line's `sense` (a displacement line: first target = 0).
    pub disp_um: f64,
}

/// What a line's instrument reads (docs/formats/displacement-lines.md,
/// `measures`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LineKind {
    /// Laser interferometer: the tool point's error along the travel, up to
    /// a free zero and a laser scale error.
    #[default]
    Displacement,
    /// Straightness optics (or a straightedge with a probe): the error
    /// along `sense`, perpendicular to the travel, up to an unknown offset
    /// and slope (the optic's alignment); no laser scale.
    Straightness,
}

impl LineKind {
    /// The metadata value (`measures: …`).
    pub fn name(self) -> &'static str {
        match self {
            LineKind::Displacement => "displacement",
            LineKind::Straightness => "straightness",
        }
    }
}

/// One line ready for identification (forward/backward already averaged).
#[derive(Clone, Debug)]
pub struct LineObs {
    pub id: String,
    /// Unit vector of travel.
    pub direction: [f64; 3],
    /// Unit vector the reading is the error along: `direction` for a
    /// displacement line, perpendicular to it for a straightness line.
    pub sense: [f64; 3],
    pub kind: LineKind,
    pub tool_offset_mm: [f64; 3],
    pub points: Vec<Observation>,
}

impl LineObs {
    /// A displacement line (the reading along the travel).
    pub fn displacement(
        id: String,
        direction: [f64; 3],
        tool_offset_mm: [f64; 3],
        points: Vec<Observation>,
    ) -> LineObs {
        LineObs {
            id,
            direction,
            sense: direction,
            kind: LineKind::Displacement,
            tool_offset_mm,
            points,
        }
    }
}

/// Refuse straightness-optics lines for a method that reads every line as
/// a displacement along its travel (`what` names the method).
pub fn displacement_only(lines: &[LineObs], what: &str) -> anyhow::Result<()> {
    let s: Vec<&str> = (lines.iter())
        .filter(|l| l.kind == LineKind::Straightness)
        .map(|l| l.id.as_str())
        .collect();
    if !s.is_empty() {
        anyhow::bail!(
            "{what} reads every line as a displacement along its travel; line{} {} {} straightness-optics (use the generic model: --method generic, 18 lines or more)",
            if s.len() > 1 { "s" } else { "" },
            s.join(", "),
            if s.len() > 1 { "are" } else { "is" }
        );
    }
    Ok(())
}

/// Polynomial degree per group of terms. Fourteen lines of one-dimensional
/// displacement carry too little to give every term the same high degree
/// (docs/geometry.md, "What 14 lines can see"): positioning, pitch and yaw
/// are seen directly by the axis-parallel lines; straightness and roll only
/// through the diagonals.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Degrees {
    /// EXX, EYY, EZZ and the two angles of each axis that are not its roll.
    pub main: usize,
    /// EYX, EZX, EXY, EZY, EXZ, EYZ (≥ 2: the linear part is squareness).
    pub straightness: usize,
    /// EAX, EBY, ECZ.
    pub roll: usize,
}

impl Default for Degrees {
    fn default() -> Self {
        Degrees {
            main: 3,
            straightness: 2,
            roll: 1,
        }
    }
}

impl Degrees {
    pub fn uniform(d: usize) -> Degrees {
        Degrees {
            main: d,
            straightness: d,
            roll: d,
        }
    }
    pub fn of(&self, t: Term) -> usize {
        if t.is_straightness() {
            self.straightness
        } else if t.is_roll() {
            self.roll
        } else {
            self.main
        }
    }
    pub fn max(&self) -> usize {
        self.main.max(self.straightness).max(self.roll).max(1)
    }
}

/// What the unknowns are.
#[derive(Clone, Debug)]
pub struct Basis {
    pub degrees: Degrees,
    pub stroke_mm: [f64; 3],
    /// (term, power j) per column, then the three squareness columns.
    pub columns: Vec<Column>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Column {
    Term { term: Term, power: usize },
    Squareness(usize),
}

impl Column {
    /// The error this column belongs to (`EXX`, …, `EC0Y`).
    pub fn label(&self) -> String {
        match self {
            Column::Term { term, .. } => term.name(),
            Column::Squareness(i) => SQUARENESS_NAMES[*i].to_string(),
        }
    }
}

impl Basis {
    pub fn new(degrees: Degrees, stroke_mm: [f64; 3]) -> Basis {
        let mut columns = Vec::new();
        for term in Term::all() {
            let first = if term.is_straightness() { 2 } else { 1 };
            for power in first..=degrees.of(term) {
                columns.push(Column::Term { term, power });
            }
        }
        columns.extend((0..3).map(Column::Squareness));
        Basis {
            degrees,
            stroke_mm,
            columns,
        }
    }

    /// Value of the basis function of a term column at axis position q.
    pub fn phi(&self, term: Term, power: usize, q_mm: f64) -> f64 {
        let u = q_mm / self.stroke_mm[term.axis.index()];
        if term.is_straightness() {
            u.powi(power as i32) - u
        } else {
            u.powi(power as i32)
        }
    }

    pub fn column_name(&self, c: &Column) -> String {
        match c {
            Column::Term { term, power } => format!("{}·u^{power}", term.name()),
            Column::Squareness(i) => SQUARENESS_NAMES[*i].to_string(),
        }
    }

    /// The design row of a reading along `dir` at `pos` with `tool`.
    pub fn row(&self, st: &Structure, dir: [f64; 3], pos: [f64; 3], tool: [f64; 3]) -> Vec<f64> {
        let s = sensitivity(st, pos, tool);
        let d = Vector3::from(dir);
        self.columns
            .iter()
            .map(|c| match *c {
                Column::Term { term, power } => {
                    d.dot(&s.terms[term.axis.index()][term.component.index()])
                        * self.phi(term, power, pos[term.axis.index()])
                }
                Column::Squareness(i) => d.dot(&s.squareness[i]),
            })
            .collect()
    }

    /// Errors from a parameter vector.
    pub fn errors(&self, x: &[f64]) -> GeometricErrors {
        let mut e = GeometricErrors::zero();
        for t in Term::all() {
            e.set(
                t,
                Poly::new(
                    self.stroke_mm[t.axis.index()],
                    vec![0.0; self.degrees.of(t).max(1)],
                ),
            );
        }
        for (c, v) in self.columns.iter().zip(x) {
            match *c {
                Column::Term { term, power } => {
                    let mut p = e.get(term).clone();
                    p.coeffs[power - 1] += v;
                    if term.is_straightness() {
                        p.coeffs[0] -= v;
                    }
                    e.set(term, p);
                }
                Column::Squareness(i) => e.squareness.set(i, *v),
            }
        }
        e
    }
}

/// One direction the lines cannot see: the combination of unknowns (largest
/// first) that changes no reading.
#[derive(Clone, Debug, Serialize)]
pub struct Unobservable {
    pub singular_value: f64,
    /// (column name, weight) of the largest weights, unit-norm vector.
    pub combination: Vec<(String, f64)>,
}

#[derive(Clone, Debug)]
pub struct Identification {
    pub basis: Basis,
    pub errors: GeometricErrors,
    /// Parameter vector (basis order).
    pub params: Vec<f64>,
    /// Singular values of the column-normalised design matrix, descending.
    pub singular_values: Vec<f64>,
    pub rank: usize,
    pub condition_number: f64,
    pub unobservable: Vec<Unobservable>,
    /// The errors (`EXX`, …, `EC0Y`) that have a column in an unobservable
    /// combination: their values are not determined by the lines (the
    /// minimum-norm solution fills them with something), sorted.
    pub unobservable_terms: Vec<String>,
    /// RMS of the readings minus the model [µm].
    pub residual_rms_um: f64,
    pub readings: usize,
    /// The unobservable directions in parameter space (basis order), one
    /// vector per combination of `unobservable`.
    pub null_space: Vec<Vec<f64>>,
}

/// Solve for the errors from the lines.
pub fn identify(
    st: &Structure,
    lines: &[LineObs],
    degrees: Degrees,
    stroke_mm: [f64; 3],
) -> anyhow::Result<Identification> {
    let basis = Basis::new(degrees, stroke_mm);
    displacement_only(lines, "the polynomial model")?;
    if lines.iter().all(|l| l.points.len() < 2) {
        anyhow::bail!("no line with at least two targets: nothing to identify from");
    }
    let n = basis.columns.len();
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut rhs: Vec<f64> = Vec::new();
    for l in lines {
        let first = rows.len();
        for p in &l.points {
            rows.push(basis.row(st, l.direction, p.pos_mm, l.tool_offset_mm));
            rhs.push(p.disp_um);
        }
        // Free offset per line: centre its rows and readings.
        let m = rows.len() - first;
        if m == 0 {
            continue;
        }
        for j in 0..n {
            let mean = rows[first..].iter().map(|r| r[j]).sum::<f64>() / m as f64;
            rows[first..].iter_mut().for_each(|r| r[j] -= mean);
        }
        let mean = rhs[first..].iter().sum::<f64>() / m as f64;
        rhs[first..].iter_mut().for_each(|b| *b -= mean);
    }
    let m = rows.len();
    let a = DMatrix::from_fn(m, n, |i, j| rows[i][j]);
    let b = DVector::from_vec(rhs);
    // Unit-norm columns: the singular values then compare like with like.
    let (norms, u, vt, singular_values) = unit_svd(&a)?;
    let mut order: Vec<usize> = (0..singular_values.len()).collect();
    order.sort_by(|&i, &j| singular_values[j].total_cmp(&singular_values[i]));
    let sv: Vec<f64> = order.iter().map(|&i| singular_values[i]).collect();
    // A design with fewer readings than unknowns has n − m null directions
    // that the thin SVD does not list.
    let smax = sv.first().copied().unwrap_or(0.0);
    let tol = RANK_TOL * smax;
    let rank = sv.iter().filter(|s| **s > tol).count();
    // Truncated-SVD (minimum-norm) solution: unobservable directions stay 0.
    let mut xn = DVector::zeros(n);
    for &i in &order {
        let s = singular_values[i];
        if s > tol {
            let coef = u.column(i).dot(&b) / s;
            xn += vt.row(i).transpose() * coef;
        }
    }
    let x: Vec<f64> = (0..n).map(|j| xn[j] / norms[j]).collect();
    let resid = &a * DVector::from_vec(x.clone()) - &b;
    let residual_rms_um = (resid.norm_squared() / m.max(1) as f64).sqrt();
    // Null space: right singular vectors below the threshold plus, when the
    // SVD is thin (m < n), the complement of the row space.
    let mut unobservable = Vec::new();
    let describe = |v: DVector<f64>, s: f64| {
        let mut w: Vec<(String, f64)> = basis
            .columns
            .iter()
            .zip(v.iter())
            .map(|(c, x)| (basis.column_name(c), *x))
            .filter(|(_, x)| x.abs() > NULL_WEIGHT)
            .collect();
        w.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        w.truncate(8);
        Unobservable {
            singular_value: s,
            combination: w,
        }
    };
    let mut null_vectors: Vec<(DVector<f64>, f64)> = order
        .iter()
        .filter(|&&i| singular_values[i] <= tol)
        .map(|&i| (vt.row(i).transpose(), singular_values[i]))
        .collect();
    if m < n {
        // Complete the basis of the row space with Gram–Schmidt on unit vectors.
        let mut basis_vecs: Vec<DVector<f64>> = order
            .iter()
            .filter(|&&i| singular_values[i] > tol)
            .map(|&i| vt.row(i).transpose())
            .collect();
        basis_vecs.extend(null_vectors.iter().map(|(v, _)| v.clone()));
        let added = complete_basis(&mut basis_vecs, n);
        null_vectors.extend(added.into_iter().map(|v| (v, 0.0)));
    }
    let mut unobservable_terms = std::collections::BTreeSet::new();
    let null_space: Vec<Vec<f64>> = null_vectors
        .iter()
        .map(|(v, _)| (0..n).map(|j| v[j] / norms[j]).collect())
        .collect();
    for (v, s) in null_vectors {
        for (c, w) in basis.columns.iter().zip(v.iter()) {
            if w.abs() > NULL_WEIGHT {
                unobservable_terms.insert(c.label());
            }
        }
        unobservable.push(describe(v, s));
    }
    let condition_number = match sv.iter().rev().find(|s| **s > tol) {
        Some(smin) if rank == n => smax / smin,
        _ => f64::INFINITY,
    };
    Ok(Identification {
        errors: basis.errors(&x),
        basis,
        params: x,
        singular_values: sv,
        rank,
        condition_number,
        unobservable,
        unobservable_terms: unobservable_terms.into_iter().collect(),
        residual_rms_um,
        readings: m,
        null_space,
    })
}

/// Express a machine's errors in the identification's convention: the
/// end-point line of each straightness moved into squareness and the frame
/// orientation (which lines cannot see). Straightness values change by a
/// linear term, the squareness by the matching slopes (all in µrad).
pub fn to_reference_convention(e: &GeometricErrors, stroke_mm: [f64; 3]) -> GeometricErrors {
    let slope = |name: &str| -> f64 {
        let t = Term::parse(name).map(|t| (t, stroke_mm[t.axis.index()]));
        match t {
            // µm per mm = mrad: × 1e3 for µrad.
            Some((t, l)) => e.value(t, l) / l * 1e3,
            None => 0.0,
        }
    };
    let mut out = e.clone();
    let (s_yx, s_zx, s_xy, s_zy, s_xz, s_yz) = (
        slope("EYX"),
        slope("EZX"),
        slope("EXY"),
        slope("EZY"),
        slope("EXZ"),
        slope("EYZ"),
    );
    out.squareness = Squareness {
        c0y: e.squareness.c0y - s_xy - s_yx,
        b0z: e.squareness.b0z + s_xz + s_zx,
        a0z: e.squareness.a0z - s_yz - s_zy,
    };
    for t in Term::all().filter(|t| t.is_straightness()) {
        let l = stroke_mm[t.axis.index()];
        let mut p = e.get(t).clone();
        let k = e.value(t, l);
        if p.coeffs.is_empty() {
            continue;
        }
        // Subtract k·(q/l): in the poly's own scale that is k·(scale/l)·u.
        p.coeffs[0] -= k * p.scale_mm / l;
        out.set(t, p);
    }
    out
}

/// RMS of the readings minus the model `params` [µm], each line's free zero
/// removed (as in the identification).
pub fn residual_rms(st: &Structure, basis: &Basis, lines: &[LineObs], params: &[f64]) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for l in lines {
        let r: Vec<f64> = l
            .points
            .iter()
            .map(|p| {
                let row = basis.row(st, l.direction, p.pos_mm, l.tool_offset_mm);
                p.disp_um - row.iter().zip(params).map(|(a, b)| a * b).sum::<f64>()
            })
            .collect();
        if r.is_empty() {
            continue;
        }
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        ss += r.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        n += r.len();
    }
    (ss / n.max(1) as f64).sqrt()
}

/// The leave-one-line-out warning fires above this multiple of the noise …
pub const LOO_WARN_RATIO: f64 = 3.0;
/// … with the noise taken as at least this [µm] (readings are written to
/// 0.001 µm; a noise-free fit must not warn on rounding).
pub const LOO_NOISE_FLOOR_UM: f64 = 0.05;

/// Leave-one-line-out error well above the noise: the model does not hold
/// the machine, or the lines do not pin it down (one line).
pub fn loo_warning(loo_rms_um: f64, noise_um: f64) -> Option<String> {
    (loo_rms_um > LOO_WARN_RATIO * noise_um.max(LOO_NOISE_FLOOR_UM)).then(|| {
        format!(
            "leave-one-line-out prediction error {loo_rms_um:.2} µm is {:.0}× the noise ({noise_um:.3} µm): the lines do not pin the machine down; the model may not hold it",
            loo_rms_um / noise_um.max(LOO_NOISE_FLOOR_UM)
        )
    })
}

/// The adequacy warning also fires when the residual implies this multiple
/// of the readings' own noise (a model that holds the machine leaves the
/// noise: ratio 1.0 ± 0.05 at 560 readings).
pub const RESIDUAL_WARN_RATIO: f64 = 1.5;

/// Adequacy that can fail (issue 29): each line predicted by the model
/// identified from the other lines, beside the fit residual.
#[derive(Clone, Debug, Serialize)]
pub struct LeaveOneLineOut {
    /// RMS over every reading of each line predicted from the others [µm].
    pub rms_um: f64,
    /// Per line [µm].
    pub per_line_um: Vec<(String, f64)>,
    /// Directions only the left-out line saw, summed over the lines, fitted
    /// to that line rather than predicted.
    pub null_directions: usize,
    /// The noise of the readings themselves, from their fourth differences
    /// along each line (`noise_from_readings`; no model involved) [µm].
    pub noise_um: f64,
    /// The noise the fit implies: residual with its degrees of freedom
    /// (readings − one zero per line − rank) [µm]. Above `noise_um` when the
    /// model does not hold the machine.
    pub residual_noise_um: f64,
    /// One line when the prediction error is far above the noise.
    pub warning: Option<String>,
}

/// Leave one line out with the polynomial model: refit from the other
/// lines (same degrees, same rank threshold) and predict the line, its
/// zero removed. The plan has no line to spare: without any one line the
/// model leaves a direction undetermined (the 13-line refusal), which only
/// that line sees. Those directions (`null_directions` per line) are taken
/// from the left-out line itself; everything else is predicted. A model
/// that holds the machine then predicts each line to the noise; one that
/// does not has pushed what it cannot hold into terms the other lines
/// contradict.
pub fn leave_one_line_out(
    st: &Structure,
    lines: &[LineObs],
    id: &Identification,
) -> anyhow::Result<LeaveOneLineOut> {
    let (mut ss, mut n, mut per_line, mut fitted) = (0.0, 0usize, Vec::new(), 0usize);
    for (k, l) in lines.iter().enumerate() {
        if l.points.len() < 2 {
            continue;
        }
        let rest: Vec<LineObs> = lines
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != k)
            .map(|(_, l)| l.clone())
            .collect();
        let sub = identify(st, &rest, id.basis.degrees, id.basis.stroke_mm)?;
        let rows: Vec<Vec<f64>> = l
            .points
            .iter()
            .map(|p| sub.basis.row(st, l.direction, p.pos_mm, l.tool_offset_mm))
            .collect();
        let dot = |r: &[f64], x: &[f64]| r.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
        let centre = |v: Vec<f64>| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.into_iter().map(|x| x - m).collect::<Vec<f64>>()
        };
        let r = centre(
            l.points
                .iter()
                .zip(&rows)
                .map(|(p, row)| p.disp_um - dot(row, &sub.params))
                .collect(),
        );
        // The line's readings of the directions the others leave open.
        let cols: Vec<Vec<f64>> = sub
            .null_space
            .iter()
            .map(|v| centre(rows.iter().map(|row| dot(row, v)).collect()))
            .filter(|c| c.iter().any(|x| x.abs() > 1e-9))
            .collect();
        fitted += cols.len();
        let r = if cols.is_empty() {
            r
        } else {
            let a = DMatrix::from_fn(r.len(), cols.len(), |i, j| cols[j][i]);
            let b = DVector::from_vec(r.clone());
            let c = a
                .clone()
                .svd(true, true)
                .solve(&b, 1e-12)
                .map_err(|e| anyhow::anyhow!("internal: {e}"))?;
            (b - a * c).iter().copied().collect()
        };
        let s: f64 = r.iter().map(|x| x * x).sum();
        ss += s;
        n += r.len();
        per_line.push((l.id.clone(), (s / r.len() as f64).sqrt()));
    }
    let rms_um = (ss / n.max(1) as f64).sqrt();
    let dof = id.readings.saturating_sub(lines.len() + id.rank).max(1);
    let residual_noise_um = id.residual_rms_um * (id.readings as f64 / dof as f64).sqrt();
    let noise_um = noise_from_readings(lines);
    Ok(LeaveOneLineOut {
        rms_um,
        per_line_um: per_line,
        noise_um,
        residual_noise_um,
        null_directions: fitted,
        warning: loo_warning(rms_um, noise_um).or_else(|| {
            let floor = noise_um.max(LOO_NOISE_FLOOR_UM);
            (residual_noise_um > RESIDUAL_WARN_RATIO * floor).then(|| {
                format!(
                    "the fit residual implies {residual_noise_um:.2} µm of noise, the readings' own is {noise_um:.3} µm: the model does not hold the machine"
                )
            })
        }),
    })
}

/// The stated adequacy test (`adequacy::assess`) of an identification from
/// lines: the design with an explicit zero per line (the same fit as the
/// centring), each line's rows divided by its stated noise `line_sigma_um`
/// (σ per reading; σ/√2 for a line whose two runs were averaged), each
/// line held out in turn. Returns the verdict and the posterior covariance
/// of `id.params` for the stated noise (not yet inflated).
pub fn line_adequacy(
    st: &Structure,
    lines: &[LineObs],
    id: &Identification,
    line_sigma_um: &[f64],
    noise: super::adequacy::StatedNoise,
) -> anyhow::Result<(super::adequacy::Adequacy, DMatrix<f64>)> {
    let n = id.basis.columns.len();
    let nl = lines.len();
    let m: usize = lines.iter().map(|l| l.points.len()).sum();
    let mut a = DMatrix::<f64>::zeros(m, n + nl);
    let mut b = DVector::<f64>::zeros(m);
    let mut groups = Vec::new();
    let mut i = 0;
    for (k, l) in lines.iter().enumerate() {
        let s = line_sigma_um[k];
        let mut g = Vec::new();
        for p in &l.points {
            let row = id.basis.row(st, l.direction, p.pos_mm, l.tool_offset_mm);
            for (j, v) in row.iter().enumerate() {
                a[(i, j)] = v / s;
            }
            a[(i, n + k)] = 1.0 / s;
            b[i] = p.disp_um / s;
            g.push(i);
            i += 1;
        }
        groups.push(g);
    }
    let mut labels: Vec<String> = id.basis.columns.iter().map(|c| c.label()).collect();
    labels.extend((0..nl).map(|_| String::new()));
    let held = (line_sigma_um.iter().map(|s| s * s).sum::<f64>() / nl.max(1) as f64).sqrt();
    let p = super::adequacy::Problem {
        a: &a,
        b: &b,
        groups: &groups,
        rank_tol: RANK_TOL,
        holdout_sigma_um: held,
        labels: &labels,
        holdout: "leave-one-line-out",
    };
    let r = super::adequacy::assess(&p, noise)?;
    Ok((r.adequacy, r.covariance.view((0, 0), (n, n)).into_owned()))
}

/// Posterior standard deviation of `term` at axis position `q_mm` from the
/// parameters' covariance `cov` (basis order) [µm or µrad].
pub fn term_sigma(basis: &Basis, cov: &DMatrix<f64>, term: Term, q_mm: f64) -> f64 {
    let g: Vec<(usize, f64)> = basis
        .columns
        .iter()
        .enumerate()
        .filter_map(|(j, c)| match *c {
            Column::Term { term: t, power } if t == term => Some((j, basis.phi(t, power, q_mm))),
            _ => None,
        })
        .collect();
    let mut v = 0.0;
    for &(i, gi) in &g {
        for &(j, gj) in &g {
            v += gi * gj * cov[(i, j)];
        }
    }
    v.max(0.0).sqrt()
}

/// Posterior standard deviation of squareness `i` (EC0Y, EB0Z, EA0Z) [µrad].
pub fn squareness_sigma(basis: &Basis, cov: &DMatrix<f64>, i: usize) -> f64 {
    basis
        .columns
        .iter()
        .position(|c| *c == Column::Squareness(i))
        .map_or(0.0, |j| cov[(j, j)].max(0.0).sqrt())
}

/// The reading noise without a model: the fourth difference of successive
/// readings along a line takes out any shape up to a cubic (a wave of half
/// a stroke over 40 target steps keeps 1 % of itself) and leaves white
/// noise with variance 70 σ². Lines with fewer than 5 targets add nothing.
pub fn noise_from_readings(lines: &[LineObs]) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for l in lines {
        for w in l.points.windows(5) {
            let d = w[0].disp_um - 4.0 * w[1].disp_um + 6.0 * w[2].disp_um - 4.0 * w[3].disp_um
                + w[4].disp_um;
            ss += d * d;
            n += 1;
        }
    }
    (ss / (70.0 * n.max(1) as f64)).sqrt()
}

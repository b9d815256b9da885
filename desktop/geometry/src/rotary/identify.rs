//! Identification of the rotary axes from R-test files: the eight location
//! errors together with the component errors (low-order Fourier series in
//! the angle, first harmonics of the whirl pairs in the backward whirl, see
//! `rotary`), optionally each location error's linear drift with sensor
//! temperatures, and a constant per file and direction (the zeroing row
//! carries noise). The linear axes' errors, when given, are known input:
//! their tool-tip error is taken off the readings.
//!
//! One linear least-squares problem on the first-order sensitivities,
//! solved by SVD with unit-norm columns (as `identify.rs`): directions with
//! a singular value below [`RANK_TOL`]·σ_max are not observable; the terms
//! in them are listed with the reason, never reported as values.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

use super::identify::NULL_WEIGHT;
use super::kinematics::tool_tip_error_exact;
use super::rotary::{
    reading_sensitivity, Axis5, Drift, Linear, Location, ReadingSensitivity, RotaryModel,
    LOCATION_NAMES, LOCATION_UNITS,
};
use super::rtest::RTestFile;

/// Relative singular value (unit-norm columns) below which a direction is
/// not observable: a condition number above 10⁴ is refused. The default
/// plan's is about 60 (`tcomp geometry plan-rotary`); taking a nest away
/// drops directions to 1e-16.
pub const RANK_TOL: f64 = 1e-4;

/// What to fit.
#[derive(Clone, Debug)]
pub struct RotaryOptions {
    /// Harmonics of C's and A's component errors (0: location errors only).
    pub order_c: usize,
    pub order_a: usize,
    /// Drift of each location error with these sensors (names without
    /// `T_`; every file must have them); empty: none.
    pub sensors: Vec<String>,
}

impl Default for RotaryOptions {
    fn default() -> Self {
        RotaryOptions {
            order_c: 3,
            order_a: 2,
            sensors: Vec::new(),
        }
    }
}

/// An unknown of the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Col {
    Loc(usize),
    Drift(usize, usize),
    /// Harmonic `h` of component `k` of an axis, cos (false) or sin (true).
    Comp(Axis5, usize, usize, bool),
    /// First harmonic of a whirl pair (i, j): P: a_i = 1, b_j = −1; Q: b_i = 1, a_j = 1.
    Whirl(Axis5, usize, bool),
    Const(usize, usize),
    /// Correction of the linear model's parameter `j` (its basis order;
    /// joint fit with the 14 lines, `rotary_joint`).
    Lin(usize),
}

/// (axis, index in the six fixed-frame errors) of each location error.
const LOC_SLOT: [(Axis5, usize); 8] = [
    (Axis5::C, 0),
    (Axis5::C, 1),
    (Axis5::C, 3),
    (Axis5::C, 4),
    (Axis5::A, 1),
    (Axis5::A, 2),
    (Axis5::A, 4),
    (Axis5::A, 5),
];

/// What the joint fit (`rotary_joint`) did with the linear model.
#[derive(Clone, Debug, Serialize)]
pub struct JointLinear {
    /// Reading noise of each data set from its own fit [µm]: the lines'
    /// (forward/backward averaged) and the R-test readings'.
    pub sigma_lines_um: f64,
    pub sigma_rtest_um: f64,
    /// RMS over the R-test readings of the change of the linear model's
    /// predicted tool-tip error (the part that went into the location
    /// errors before) [µm].
    pub change_at_rtest_rms_um: f64,
    /// Residual RMS of the lines with the corrected model [µm] (the
    /// 14-line fit's own is `line_residual_rms_um_before`).
    pub line_residual_rms_um: f64,
    pub line_residual_rms_um_before: f64,
    /// Condition number of the joint problem (unit-norm columns of the
    /// weighted design); `condition_number` of the identification stays the
    /// R-test plan's own (as `plan-rotary` shows it).
    pub joint_condition_number: Option<f64>,
    /// Of the identification's `unknowns` and `readings`: the linear
    /// model's parameters and the lines' readings.
    pub linear_unknowns: usize,
    pub line_readings: usize,
}

/// One value with its standard uncertainty; `None` when not observable.
#[derive(Clone, Debug, Serialize)]
pub struct TermValue {
    pub name: String,
    pub unit: String,
    pub value: Option<f64>,
    pub sigma: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Unobservable {
    pub terms: Vec<String>,
    pub why: String,
    pub singular_value: f64,
    /// Largest weights of the unit-norm null direction.
    pub combination: Vec<(String, f64)>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RotaryIdentification {
    pub model: RotaryModel,
    pub location: Vec<TermValue>,
    pub drift: Vec<TermValue>,
    pub components: Vec<TermValue>,
    pub condition_number: Option<f64>,
    pub rank: usize,
    pub unknowns: usize,
    pub readings: usize,
    pub files: usize,
    pub nest_positions: usize,
    pub residual_rms_um: f64,
    pub unobservable: Vec<Unobservable>,
    /// Names (`XOC`, `EZC`, `XOC/T_ctable` …) in an unobservable direction.
    pub unobservable_terms: Vec<String>,
    /// Joint fit with the lines (`rotary_joint`): what it did to the linear model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub linear: Option<JointLinear>,
    /// Joint fit: the linear model's parameter corrections (basis order).
    #[serde(skip)]
    pub linear_delta: Vec<f64>,
    /// The stated adequacy test ([`RotaryIdentification::assess`]); the
    /// σ's of `location`, `drift`, `components` are then the stated
    /// noise's posterior σ × `sigma_inflation`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adequacy: Option<super::adequacy::Adequacy>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adequate: Option<bool>,
    /// The problem as solved, for `assess`.
    #[serde(skip)]
    pub(crate) design: Option<StoredDesign>,
}

/// The least-squares problem `solve` saw, with the weights it applied.
#[derive(Clone, Debug)]
pub(crate) struct StoredDesign {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub rtest_rows: usize,
    /// Weight already applied to the R-test rows (1/σ_R; 1 unweighted)
    /// and to any rows after them (the lines of a joint fit: 1/σ_L).
    pub weight_r: f64,
    pub weight_l: f64,
    /// Rows of each file (held out in turn).
    pub groups: Vec<Vec<usize>>,
    /// Error name of each unknown (empty for the files' offsets).
    pub labels: Vec<String>,
    pub cols: Vec<Col>,
}

impl RotaryIdentification {
    /// The stated adequacy test (`adequacy::assess`, each file held out in
    /// turn) at the stated noise of one R-test reading; the lines of a
    /// joint fit (averaged runs) at that noise / √2. Replaces the σ's by
    /// the stated noise's posterior σ × the inflation, and records the
    /// verdict here and in the model.
    pub fn assess(&mut self, noise: super::adequacy::StatedNoise) -> Result<()> {
        let Some(d) = self.design.as_ref() else {
            bail!("internal: identification without its design");
        };
        let (m, _) = d.a.shape();
        let mut a = d.a.clone();
        let mut b = d.b.clone();
        for i in 0..m {
            let f = if i < d.rtest_rows {
                1.0 / (d.weight_r * noise.um)
            } else {
                std::f64::consts::SQRT_2 / (d.weight_l * noise.um)
            };
            a.row_mut(i).scale_mut(f);
            b[i] *= f;
        }
        let p = super::adequacy::Problem {
            a: &a,
            b: &b,
            groups: &d.groups,
            rank_tol: RANK_TOL,
            holdout_sigma_um: noise.um,
            labels: &d.labels,
            holdout: "leave-one-file-out",
        };
        let r = super::adequacy::assess(&p, noise)?;
        let f = r.adequacy.sigma_inflation;
        let (mut il, mut id, mut ic) = (0, 0, 0);
        for (j, col) in d.cols.iter().enumerate() {
            let tv = match col {
                Col::Loc(_) => {
                    il += 1;
                    self.location.get_mut(il - 1)
                }
                Col::Drift(..) => {
                    id += 1;
                    self.drift.get_mut(id - 1)
                }
                Col::Comp(..) | Col::Whirl(..) => {
                    ic += 1;
                    self.components.get_mut(ic - 1)
                }
                _ => None,
            };
            if let Some(tv) = tv.filter(|t| t.sigma.is_some()) {
                tv.sigma = Some(f * r.covariance[(j, j)].max(0.0).sqrt());
            }
        }
        self.adequate = Some(r.adequacy.adequate);
        self.model.adequate = Some(r.adequacy.adequate);
        self.model.adequacy = Some(r.adequacy.clone());
        self.adequacy = Some(r.adequacy);
        Ok(())
    }
}

impl Col {
    fn name(&self, o: &RotaryOptions, files: &[RTestFile]) -> String {
        match *self {
            Col::Loc(j) => LOCATION_NAMES[j].to_string(),
            Col::Drift(j, s) => format!("{}/T_{}", LOCATION_NAMES[j], o.sensors[s]),
            Col::Comp(ax, k, h, sin) => {
                format!("{} {}{h}", ax.names()[k], if sin { 'b' } else { 'a' })
            }
            Col::Whirl(ax, p, q) => {
                let (i, j) = ax.whirl_pairs()[p];
                format!(
                    "{}/{} backward whirl {}",
                    ax.names()[i],
                    ax.names()[j],
                    if q { 'q' } else { 'p' }
                )
            }
            Col::Const(f, d) => format!("offset of {} d{}", files[f].name, ['x', 'y', 'z'][d]),
            Col::Lin(j) => format!("linear parameter {j}"),
        }
    }
    /// The error names this unknown belongs to (none for the file offsets).
    fn terms(&self, o: &RotaryOptions) -> Vec<String> {
        match *self {
            Col::Loc(j) => vec![LOCATION_NAMES[j].to_string()],
            Col::Drift(j, s) => vec![format!("{}/T_{}", LOCATION_NAMES[j], o.sensors[s])],
            Col::Comp(ax, k, _, _) => vec![ax.names()[k].to_string()],
            Col::Whirl(ax, p, _) => {
                let (i, j) = ax.whirl_pairs()[p];
                vec![ax.names()[i].to_string(), ax.names()[j].to_string()]
            }
            Col::Const(..) => vec![],
            Col::Lin(_) => vec!["linear axes".to_string()],
        }
    }
}

pub(crate) fn columns(o: &RotaryOptions, files: usize) -> Vec<Col> {
    let mut cols: Vec<Col> = (0..8).map(Col::Loc).collect();
    for s in 0..o.sensors.len() {
        cols.extend((0..8).map(|j| Col::Drift(j, s)));
    }
    for (ax, order) in [(Axis5::C, o.order_c), (Axis5::A, o.order_a)] {
        let in_pair = |k: usize| ax.whirl_pairs().iter().any(|(i, j)| *i == k || *j == k);
        for h in 1..=order {
            for k in 0..6 {
                if h == 1 && in_pair(k) {
                    continue;
                }
                cols.push(Col::Comp(ax, k, h, false));
                cols.push(Col::Comp(ax, k, h, true));
            }
            if h == 1 {
                for p in 0..2 {
                    cols.push(Col::Whirl(ax, p, false));
                    cols.push(Col::Whirl(ax, p, true));
                }
            }
        }
    }
    for f in 0..files {
        cols.extend((0..3).map(|d| Col::Const(f, d)));
    }
    cols
}

/// The reading (workpiece frame, µm) one unit of `col` produces at a pose
/// (zero for the linear model's columns: `rotary_joint` fills those).
pub(crate) fn effect(
    col: Col,
    s: &ReadingSensitivity,
    a: f64,
    c: f64,
    file: usize,
    dt: &[f64],
) -> Vector3<f64> {
    let side = |ax: Axis5| match ax {
        Axis5::A => (&s.a, a),
        Axis5::C => (&s.c, c),
    };
    match col {
        Col::Loc(j) | Col::Drift(j, _) => {
            let (ax, k) = LOC_SLOT[j];
            let (sens, deg) = side(ax);
            let mut u = Vector3::zeros();
            u[k % 3] = 1.0;
            let v = u - ax.rotation(deg) * u;
            let base = if k < 3 { 0 } else { 3 };
            let e: Vector3<f64> = (0..3).map(|i| sens[base + i] * v[i]).sum();
            match col {
                Col::Drift(_, sensor) => e * dt[sensor],
                _ => e,
            }
        }
        Col::Comp(ax, k, h, sin) => {
            let (sens, deg) = side(ax);
            let t = h as f64 * deg.to_radians();
            sens[k] * if sin { t.sin() } else { t.cos() - 1.0 }
        }
        Col::Whirl(ax, p, q) => {
            let (sens, deg) = side(ax);
            let (i, j) = ax.whirl_pairs()[p];
            let (cm, sn) = (deg.to_radians().cos() - 1.0, deg.to_radians().sin());
            if q {
                sens[i] * sn + sens[j] * cm
            } else {
                sens[i] * cm - sens[j] * sn
            }
        }
        Col::Const(f, d) => {
            let mut u = Vector3::zeros();
            if f == file {
                u[d] = 1.0;
            }
            u
        }
        Col::Lin(_) => Vector3::zeros(),
    }
}

/// Distinct nest positions of the files and how many of them are not collinear (1, 2 or 3).
fn nest_spread(files: &[RTestFile]) -> (usize, usize, bool) {
    let mut nests: Vec<[f64; 3]> = Vec::new();
    for f in files {
        if !nests
            .iter()
            .any(|n| (0..3).all(|k| (n[k] - f.nest_mm[k]).abs() < 0.5))
        {
            nests.push(f.nest_mm);
        }
    }
    let on_axis = nests.iter().all(|n| n[0].hypot(n[1]) < 1.0);
    let span = match nests.len() {
        0 | 1 => nests.len(),
        _ => {
            let d: Vec<Vector3<f64>> = nests[1..]
                .iter()
                .map(|n| Vector3::from(*n) - Vector3::from(nests[0]))
                .collect();
            let m = DMatrix::from_fn(3, d.len(), |i, j| d[j][i]);
            let sv = m.svd(false, false).singular_values;
            1 + sv.iter().filter(|s| **s > 1.0).count().min(2)
        }
    };
    (nests.len(), span, on_axis)
}

/// Solve for the rotary errors from `files` (same turntable geometry).
pub fn identify_rotary(
    files: &[RTestFile],
    lin: Option<Linear>,
    o: &RotaryOptions,
) -> Result<RotaryIdentification> {
    let d = design(files, lin, o)?;
    let rows = d.b.len();
    solve(files, o, &d.cols, d.a, d.b, &d.reference, rows, 1.0)
}

/// The R-test part of the least-squares problem.
pub(crate) struct Design {
    pub cols: Vec<Col>,
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    /// Reference temperatures of the drift (the files' means).
    pub reference: Vec<f64>,
    /// Sensitivities and pose of each reading (three rows each), in order.
    pub poses: Vec<(ReadingSensitivity, [f64; 3], [f64; 3])>,
}

/// Rows of every reading: unknowns, readings minus the linear model's
/// exact tool-tip error (`lin`).
pub(crate) fn design(
    files: &[RTestFile],
    lin: Option<Linear>,
    o: &RotaryOptions,
) -> Result<Design> {
    let Some(first) = files.first() else {
        bail!("no R-test files");
    };
    for f in files {
        if f.pivot_a_mm != first.pivot_a_mm || f.offset_c_mm != first.offset_c_mm {
            bail!(
                "{}: pivot_a_mm or offset_c_mm differ from {}'s; one turntable at a time",
                f.name,
                first.name
            );
        }
    }
    if o.order_c > 6 || o.order_a > 6 {
        bail!("component orders above 6 are not supported (the sweeps cannot carry them)");
    }
    // sensor columns of each file, and the reference temperatures (means)
    let mut idx: Vec<Vec<usize>> = Vec::new();
    for f in files {
        let mut v = Vec::new();
        for s in &o.sensors {
            let Some(i) = f.sensors.iter().position(|x| x == s) else {
                bail!(
                    "{}: no column T_{s} (drift is fitted with {})",
                    f.name,
                    o.sensors.join(", ")
                );
            };
            v.push(i);
        }
        idx.push(v);
    }
    let n_rows: usize = files.iter().map(|f| f.rows.len()).sum();
    let reference: Vec<f64> = (0..o.sensors.len())
        .map(|s| {
            files
                .iter()
                .zip(&idx)
                .flat_map(|(f, ix)| f.rows.iter().map(move |r| r.temps[ix[s]]))
                .sum::<f64>()
                / n_rows as f64
        })
        .collect();
    let cols = columns(o, files.len());
    let n = cols.len();
    let m = 3 * n_rows;
    let mut a = DMatrix::<f64>::zeros(m, n);
    let mut b = DVector::<f64>::zeros(m);
    let mut i = 0;
    let mut poses = Vec::with_capacity(n_rows);
    for (fi, f) in files.iter().enumerate() {
        for r in &f.rows {
            let s = reading_sensitivity(f.pivot_a_mm, f.offset_c_mm, f.nest_mm, r.a_deg, r.c_deg);
            let dt: Vec<f64> = (0..o.sensors.len())
                .map(|k| r.temps[idx[fi][k]] - reference[k])
                .collect();
            let lin_e = lin.map_or(Vector3::zeros(), |l| {
                s.lin_rot * tool_tip_error_exact(l.structure, l.errors, r.pos_mm, f.tool_mm)
            });
            for (j, col) in cols.iter().enumerate() {
                let e = effect(*col, &s, r.a_deg, r.c_deg, fi, &dt);
                for d in 0..3 {
                    a[(i + d, j)] = e[d];
                }
            }
            for d in 0..3 {
                b[i + d] = r.d_um[d] - lin_e[d];
            }
            poses.push((s, r.pos_mm, f.tool_mm));
            i += 3;
        }
    }
    Ok(Design {
        cols,
        a,
        b,
        reference,
        poses,
    })
}

/// Solve the weighted problem: the first `rtest_rows` rows are R-test
/// readings divided by `sigma_r` (1: unweighted), any rows after them other
/// data (the lines of a joint fit) in the same units of σ.
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve(
    files: &[RTestFile],
    o: &RotaryOptions,
    cols: &[Col],
    a: DMatrix<f64>,
    b: DVector<f64>,
    reference: &[f64],
    rtest_rows: usize,
    sigma_r: f64,
) -> Result<RotaryIdentification> {
    let (m, n) = a.shape();
    let norms: Vec<f64> = (0..n)
        .map(|j| a.column(j).norm())
        .map(|v| if v > 0.0 { v } else { 1.0 })
        .collect();
    let mut an = a.clone();
    for j in 0..n {
        an.column_mut(j).scale_mut(1.0 / norms[j]);
    }
    let svd = an.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        bail!("internal: SVD without U or Vᵀ");
    };
    let sv = &svd.singular_values;
    let smax = sv.max();
    if !(smax > 0.0) {
        bail!("the files carry no information on the rotary errors (every column is zero)");
    }
    let tol = RANK_TOL * smax;
    let keep: Vec<usize> = (0..sv.len()).filter(|&i| sv[i] > tol).collect();
    let rank = keep.len();
    let mut xn = DVector::zeros(n);
    for &i in &keep {
        xn += vt.row(i).transpose() * (u.column(i).dot(&b) / sv[i]);
    }
    let x: Vec<f64> = (0..n).map(|j| xn[j] / norms[j]).collect();
    let resid = &a * DVector::from_vec(x.clone()) - &b;
    let rt = resid.rows(0, rtest_rows.min(m));
    let residual_rms_um = sigma_r * (rt.norm_squared() / rt.len().max(1) as f64).sqrt();
    let dof = m.saturating_sub(rank).max(1);
    let sigma0 = (resid.norm_squared() / dof as f64).sqrt();
    let sigma: Vec<f64> = (0..n)
        .map(|j| {
            let var: f64 = keep.iter().map(|&i| (vt[(i, j)] / sv[i]).powi(2)).sum();
            sigma0 * var.sqrt() / norms[j]
        })
        .collect();
    let null = null_directions(sv.as_slice(), vt, tol, m, n);
    let (nests, _, _) = nest_spread(files);
    let (unobservable, unobs_terms, unobs_cols) = describe_null(files, o, cols, null);
    let value = |j: usize| (!unobs_cols.contains(&j)).then_some(x[j]);
    let sig = |j: usize| (!unobs_cols.contains(&j)).then_some(sigma[j]);
    let mut model = RotaryModel {
        pivot_a_mm: files[0].pivot_a_mm,
        offset_c_mm: files[0].offset_c_mm,
        ..Default::default()
    };
    let mut loc = [0.0; 8];
    let mut drift = vec![[0.0; 8]; o.sensors.len()];
    let (mut location, mut drift_v, mut comps) = (Vec::new(), Vec::new(), Vec::new());
    let mut linear_delta = Vec::new();
    for (j, col) in cols.iter().enumerate() {
        let tv = |name: String, unit: &str| TermValue {
            name,
            unit: unit.to_string(),
            value: value(j),
            sigma: sig(j),
        };
        match *col {
            Col::Loc(k) => {
                loc[k] = x[j];
                location.push(tv(LOCATION_NAMES[k].to_string(), LOCATION_UNITS[k]));
            }
            Col::Drift(k, s) => {
                drift[s][k] = x[j];
                drift_v.push(tv(col.name(o, files), &format!("{}/K", LOCATION_UNITS[k])));
            }
            Col::Comp(ax, k, h, sin) => {
                let f = model
                    .components
                    .entry(ax.names()[k].to_string())
                    .or_default();
                set_coef(f, h, sin, x[j]);
                comps.push(tv(col.name(o, files), if k < 3 { "µm" } else { "µrad" }));
            }
            Col::Whirl(ax, p, q) => {
                let (ii, jj) = ax.whirl_pairs()[p];
                let (ni, nj) = (ax.names()[ii].to_string(), ax.names()[jj].to_string());
                let unit = if ii < 3 { "µm" } else { "µrad" };
                if q {
                    add_coef(model.components.entry(ni).or_default(), true, x[j]);
                    add_coef(model.components.entry(nj).or_default(), false, x[j]);
                } else {
                    add_coef(model.components.entry(ni).or_default(), false, x[j]);
                    add_coef(model.components.entry(nj).or_default(), true, -x[j]);
                }
                comps.push(tv(col.name(o, files), unit));
            }
            Col::Const(..) => {}
            Col::Lin(_) => linear_delta.push(x[j]),
        }
    }
    model.location = Location::from_array(loc);
    model.drift = (o.sensors.iter().zip(reference).zip(&drift))
        .map(|((s, r), d)| Drift {
            sensor: s.clone(),
            reference_c: *r,
            per_kelvin: Location::from_array(*d),
        })
        .collect();
    model.unobservable = unobs_terms.iter().cloned().collect();
    let condition_number = (rank == n).then(|| {
        smax / sv
            .iter()
            .copied()
            .filter(|s| *s > tol)
            .fold(f64::INFINITY, f64::min)
    });
    let mut groups = Vec::new();
    let mut row = 0;
    for f in files {
        groups.push((row..row + 3 * f.rows.len()).collect());
        row += 3 * f.rows.len();
    }
    let labels = cols
        .iter()
        .map(|c| match c {
            Col::Const(..) => String::new(),
            _ => c.terms(o).join("/"),
        })
        .collect();
    let design = StoredDesign {
        a,
        b,
        rtest_rows,
        weight_r: 1.0 / sigma_r,
        weight_l: 1.0,
        groups,
        labels,
        cols: cols.to_vec(),
    };
    Ok(RotaryIdentification {
        adequacy: None,
        adequate: None,
        design: Some(design),
        model,
        location,
        drift: drift_v,
        components: comps,
        condition_number,
        rank,
        unknowns: n,
        readings: m,
        files: files.len(),
        nest_positions: nests,
        residual_rms_um,
        unobservable,
        unobservable_terms: unobs_terms.into_iter().collect(),
        linear: None,
        linear_delta,
    })
}

/// Null directions: right singular vectors with a small singular value,
/// and the complement of the row space when there are fewer rows than unknowns.
fn null_directions(
    sv: &[f64],
    vt: &DMatrix<f64>,
    tol: f64,
    m: usize,
    n: usize,
) -> Vec<(DVector<f64>, f64)> {
    let mut null: Vec<(DVector<f64>, f64)> = (0..sv.len())
        .filter(|&i| sv[i] <= tol)
        .map(|i| (vt.row(i).transpose(), sv[i]))
        .collect();
    if m < n {
        let mut basis: Vec<DVector<f64>> = (0..sv.len()).map(|i| vt.row(i).transpose()).collect();
        for k in 0..n {
            let mut v = DVector::zeros(n);
            v[k] = 1.0;
            for q in &basis {
                let d = q.dot(&v);
                v -= q * d;
            }
            if v.norm() > 1e-6 {
                v /= v.norm();
                basis.push(v.clone());
                null.push((v, 0.0));
            }
        }
    }
    null
}

/// The unobservable directions with their terms and reasons, every term
/// in one, and the columns in one.
fn describe_null(
    files: &[RTestFile],
    o: &RotaryOptions,
    cols: &[Col],
    null: Vec<(DVector<f64>, f64)>,
) -> (Vec<Unobservable>, BTreeSet<String>, BTreeSet<usize>) {
    let (nests, span, on_axis) = nest_spread(files);
    let moves = |f: fn(&super::rtest::RTestRow) -> f64| {
        files
            .iter()
            .flat_map(|f| f.rows.iter())
            .any(|r| f(r).abs() > 1e-6)
    };
    let (a_moves, c_moves) = (moves(|r| r.a_deg), moves(|r| r.c_deg));
    let mut unobservable = Vec::new();
    let mut unobs_terms = BTreeSet::new();
    let mut unobs_cols = BTreeSet::new();
    for (v, s) in null {
        let mut terms = BTreeSet::new();
        let mut comb: Vec<(String, f64)> = Vec::new();
        for (j, w) in v.iter().enumerate() {
            if w.abs() > NULL_WEIGHT {
                terms.extend(cols[j].terms(o));
                comb.push((cols[j].name(o, files), *w));
                unobs_cols.insert(j);
            }
        }
        comb.sort_by(|p, q| q.1.abs().total_cmp(&p.1.abs()));
        comb.truncate(8);
        let why = reason(&terms, nests, span, on_axis, a_moves, c_moves, s);
        unobs_terms.extend(terms.iter().cloned());
        unobservable.push(Unobservable {
            terms: terms.into_iter().collect(),
            why,
            singular_value: s,
            combination: comb,
        });
    }
    (unobservable, unobs_terms, unobs_cols)
}

fn ensure(f: &mut super::five_axis::Fourier, h: usize) {
    if f.cos.len() < h {
        f.cos.resize(h, 0.0);
    }
    if f.sin.len() < h {
        f.sin.resize(h, 0.0);
    }
}

fn set_coef(f: &mut super::five_axis::Fourier, h: usize, sin: bool, v: f64) {
    ensure(f, h);
    if sin {
        f.sin[h - 1] = v;
    } else {
        f.cos[h - 1] = v;
    }
}

fn add_coef(f: &mut super::five_axis::Fourier, sin: bool, v: f64) {
    ensure(f, 1);
    if sin {
        f.sin[0] += v;
    } else {
        f.cos[0] += v;
    }
}

/// Why the terms of one null direction cannot be told apart (rtest.md's known cases first).
fn reason(
    terms: &BTreeSet<String>,
    nests: usize,
    span: usize,
    on_axis: bool,
    a_moves: bool,
    c_moves: bool,
    s: f64,
) -> String {
    let has = |names: &[&str]| names.iter().any(|n| terms.iter().any(|t| t.starts_with(n)));
    let a_terms = terms.iter().any(|t| t.ends_with('A') || t.contains("OA"));
    let c_terms = terms.iter().any(|t| t.ends_with('C') || t.contains("OC"));
    if !a_moves && a_terms {
        return "A never moves in these files: the A axis's errors are not seen".into();
    }
    if !c_moves && c_terms {
        return "C never moves in these files: the C axis's errors are not seen".into();
    }
    if on_axis && has(&["XOC", "YOC", "AOC", "BOC"]) {
        return "the nest is on the C axis: it sees only XOC + h·BOC and YOC − h·AOC".into();
    }
    if span < 3 && has(&["XOC", "YOC", "AOC", "BOC", "EZC", "ECC"]) {
        return format!(
            "{nests} nest position(s), {span} not collinear: with error motions modelled, fewer than three non-collinear nest positions cannot separate XOC, YOC, AOC, BOC from EZC/ECC"
        );
    }
    if terms.iter().any(|t| t.contains("/T_")) {
        return "the sensors' temperatures move together (or not at all) in these files: their drift coefficients cannot be told apart".into();
    }
    format!("the poses do not separate these terms (relative singular value {s:.1e}); add sweeps or lower the component order")
}

#[cfg(test)]
#[path = "rotary_identify_tests.rs"]
mod tests;

/// The location errors only: a name → value map for reports.
pub fn location_map(l: &Location) -> BTreeMap<String, f64> {
    LOCATION_NAMES
        .iter()
        .map(|n| n.to_string())
        .zip(l.to_array())
        .collect()
}

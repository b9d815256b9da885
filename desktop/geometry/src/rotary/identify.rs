//! Identification of the rotary axes from R-test files: the eight location
//! errors together with the component errors (low-order Fourier series in
//! the angle, first harmonics of the whirl pairs in the backward whirl, see
//! `model`), optionally each location error's linear drift with sensor
//! temperatures, and a constant per file and direction (the zeroing row
//! carries noise). The linear axes' errors, when given, are known input:
//! their tool-tip error is taken off the readings.
//!
//! One linear least-squares problem on the first-order sensitivities,
//! solved by SVD with unit-norm columns (as `crate::identify`): directions with
//! a singular value below [`RANK_TOL`]·σ_max are not observable; the terms
//! in them are listed with the reason, never reported as values.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

use super::columns::{columns, effect, prior_rows, spindle_effect, Col, SPINDLE_NAMES};
pub use super::columns::{HarmonicPrior, RotaryOptions, TermValue};
use super::model::{
    reading_sensitivity, Drift, Linear, Location, ReadingSensitivity, RotaryModel, Spindle,
    LOCATION_NAMES, LOCATION_UNITS,
};
use super::spindle::mean_tool;
pub use super::spindle::SpindleReport;
pub use super::unobservable::Unobservable;
use super::unobservable::{describe_null, nest_spread, null_directions};
use crate::kinematics::tool_tip_error_exact;
use crate::rtest::RTestFile;
use crate::unit_svd::unit_svd;

/// Relative singular value (unit-norm columns) below which a direction is
/// not observable: a condition number above 10⁴ is refused. The default
/// plan's is about 60 (`tcomp geometry plan-rotary`); taking a nest away
/// drops directions to 1e-16.
pub const RANK_TOL: f64 = 1e-4;

/// What the joint fit (`joint`) did with the linear model.
#[derive(Clone, Debug, Serialize)]
pub struct JointLinear {
    /// The linear model fitted: `poly` (the lines' rows in the problem,
    /// `joint`) or `generic` (the generic identifier's posterior as prior
    /// rows, `joint_generic`).
    pub linear_model: &'static str,
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
    /// model's parameters and the lines' readings (generic: its posterior's
    /// modes and their prior rows, one per mode).
    pub linear_unknowns: usize,
    pub line_readings: usize,
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
    /// The spindle's direction relative to the lines' frame: identified
    /// (several tool lengths) or undetermined (one), with the reason.
    pub spindle: SpindleReport,
    /// Joint fit with the lines (`joint`): what it did to the linear model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub linear: Option<JointLinear>,
    /// Joint fit: the linear model's parameter corrections (basis order).
    #[serde(skip)]
    pub linear_delta: Vec<f64>,
    /// The stated adequacy test ([`RotaryIdentification::assess`]); the
    /// σ's of `location`, `drift`, `components` are then the stated
    /// noise's posterior σ × `sigma_inflation`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adequacy: Option<crate::adequacy::Adequacy>,
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
    /// The rows after the R-test ones are a prior in units of its own σ
    /// (`joint_generic`), kept as they are by the adequacy test.
    pub prior_rows: bool,
    /// The last rows: the harmonic coefficients' prior (`prior_rows` of
    /// `columns`), weighted as R-test rows and never held out.
    pub harmonic_rows: usize,
    /// Rows of each file (held out in turn).
    pub groups: Vec<Vec<usize>>,
    /// Error name of each unknown (empty for the files' offsets).
    pub labels: Vec<String>,
    pub cols: Vec<Col>,
}

impl StoredDesign {
    /// The problem in units of the stated noise `noise_um` of one R-test
    /// reading: R-test rows at that σ, the lines of a joint fit (averaged
    /// runs) at σ / √2, prior rows as they are (in units of their own σ).
    pub(crate) fn at_noise(&self, noise_um: f64) -> (DMatrix<f64>, DVector<f64>) {
        let (mut a, mut b) = (self.a.clone(), self.b.clone());
        let first_harmonic = a.nrows() - self.harmonic_rows;
        for i in 0..a.nrows() {
            let f = if i < self.rtest_rows || i >= first_harmonic {
                1.0 / (self.weight_r * noise_um)
            } else if self.prior_rows {
                1.0
            } else {
                std::f64::consts::SQRT_2 / (self.weight_l * noise_um)
            };
            a.row_mut(i).scale_mut(f);
            b[i] *= f;
        }
        (a, b)
    }
}

impl RotaryIdentification {
    /// The stated adequacy test (`adequacy::assess`, each file held out in
    /// turn) at the stated noise of one R-test reading; the lines of a
    /// joint fit (averaged runs) at that noise / √2. Replaces the σ's by
    /// the stated noise's posterior σ × the inflation, and records the
    /// verdict here and in the model.
    pub fn assess(&mut self, noise: crate::adequacy::StatedNoise) -> Result<()> {
        let Some(d) = self.design.as_ref() else {
            bail!("internal: identification without its design");
        };
        let (a, b) = d.at_noise(noise.um);
        let p = crate::adequacy::Problem {
            a: &a,
            b: &b,
            groups: &d.groups,
            rank_tol: RANK_TOL,
            holdout_sigma_um: noise.um,
            labels: &d.labels,
            holdout: "leave-one-file-out",
        };
        let r = crate::adequacy::assess(&p, noise)?;
        let f = r.adequacy.sigma_inflation;
        let (mut il, mut id, mut ic, mut is) = (0, 0, 0, 0);
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
                Col::Spindle(_) => {
                    is += 1;
                    self.spindle.angles.get_mut(is - 1)
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
    let cols = columns(o, files);
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
                let e = match *col {
                    Col::Spindle(k) => spindle_effect(k, &s, f.tool_mm),
                    _ => effect(*col, &s, r.a_deg, r.c_deg, fi, &dt),
                };
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
/// data (the lines of a joint fit) in the same units of σ. With a harmonic
/// prior (`o.harmonic_prior`, an order chosen by the evidence) its rows
/// are appended (`columns::prior_rows`) and the values are the posterior
/// mean; rank, conditioning and the unobservable directions stay the
/// readings' own.
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
    // what the readings alone see: rank, conditioning, unobservable
    // directions (a prior does not make a direction observable)
    let mut sol = least_squares(&a, &b, rtest_rows, sigma_r)?;
    // the harmonic coefficients' prior (an `auto` order): the values and
    // σ's are the posterior's
    let prior = prior_rows(o, cols, 1.0 / sigma_r);
    let (a, b) = if prior.is_empty() {
        (a, b)
    } else {
        let rows = m + prior.len();
        let (mut a, b) = (
            a.resize_vertically(rows, 0.0),
            b.resize_vertically(rows, 0.0),
        );
        for (i, (j, w)) in prior.iter().enumerate() {
            a[(m + i, *j)] = *w;
        }
        let post = least_squares(&a, &b, rtest_rows, sigma_r)?;
        (sol.x, sol.sigma, sol.residual_rms_um) = (post.x, post.sigma, post.residual_rms_um);
        (a, b)
    };
    let (nests, _, _) = nest_spread(files);
    let null = std::mem::take(&mut sol.null);
    let (unobservable, unobs_terms, unobs_cols) = describe_null(files, o, cols, null);
    let mut v = values(files, o, cols, reference, &sol, &unobs_cols);
    v.model.unobservable = unobs_terms.iter().cloned().collect();
    let mut design = stored_design(files, o, cols, a, b, rtest_rows, sigma_r);
    design.harmonic_rows = prior.len();
    let spindle = SpindleReport::new(files, v.spindle, &unobs_terms);
    Ok(RotaryIdentification {
        spindle,
        adequacy: None,
        adequate: None,
        design: Some(design),
        model: v.model,
        location: v.location,
        drift: v.drift,
        components: v.components,
        condition_number: sol.condition_number,
        rank: sol.rank,
        unknowns: n,
        readings: m,
        files: files.len(),
        nest_positions: nests,
        residual_rms_um: sol.residual_rms_um,
        unobservable,
        unobservable_terms: unobs_terms.into_iter().collect(),
        linear: None,
        linear_delta: v.linear_delta,
    })
}

/// The truncated-SVD solution of a weighted problem.
struct Solution {
    /// Every unknown's value and standard deviation (σ from the residual).
    x: Vec<f64>,
    sigma: Vec<f64>,
    rank: usize,
    /// Directions below [`RANK_TOL`]·σ_max, with their singular values.
    null: Vec<(DVector<f64>, f64)>,
    /// σ_max / σ_min when every direction is kept.
    condition_number: Option<f64>,
    /// RMS of the R-test rows' residual, back in µm.
    residual_rms_um: f64,
}

/// The least-squares solution on unit-norm columns: directions with a
/// singular value below [`RANK_TOL`]·σ_max are left out (and returned as
/// null directions).
fn least_squares(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    rtest_rows: usize,
    sigma_r: f64,
) -> Result<Solution> {
    let (m, n) = a.shape();
    let (norms, u, vt, sv) = unit_svd(a)?;
    let smax = sv.max();
    if !(smax > 0.0) {
        bail!("the files carry no information on the rotary errors (every column is zero)");
    }
    let tol = RANK_TOL * smax;
    let keep: Vec<usize> = (0..sv.len()).filter(|&i| sv[i] > tol).collect();
    let rank = keep.len();
    let mut xn = DVector::zeros(n);
    for &i in &keep {
        xn += vt.row(i).transpose() * (u.column(i).dot(b) / sv[i]);
    }
    let x: Vec<f64> = (0..n).map(|j| xn[j] / norms[j]).collect();
    let resid = a * DVector::from_vec(x.clone()) - b;
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
    let null = null_directions(sv.as_slice(), &vt, tol, m, n);
    let condition_number = (rank == n).then(|| {
        smax / sv
            .iter()
            .copied()
            .filter(|s| *s > tol)
            .fold(f64::INFINITY, f64::min)
    });
    Ok(Solution {
        x,
        sigma,
        rank,
        null,
        condition_number,
        residual_rms_um,
    })
}

/// The solution as a model and as reported values.
struct Values {
    model: RotaryModel,
    location: Vec<TermValue>,
    drift: Vec<TermValue>,
    components: Vec<TermValue>,
    /// Joint fit: the linear model's parameter corrections.
    linear_delta: Vec<f64>,
    /// The spindle's two angles (when the files have several tools).
    spindle: Vec<TermValue>,
}

/// The model (every column's value, whirl pairs split into their two
/// components) and the reported values: a column in an unobservable
/// direction (`unobs_cols`) has neither value nor σ.
fn values(
    files: &[RTestFile],
    o: &RotaryOptions,
    cols: &[Col],
    reference: &[f64],
    sol: &Solution,
    unobs_cols: &BTreeSet<usize>,
) -> Values {
    let x = &sol.x;
    let value = |j: usize| (!unobs_cols.contains(&j)).then_some(x[j]);
    let sig = |j: usize| (!unobs_cols.contains(&j)).then_some(sol.sigma[j]);
    let mut model = RotaryModel {
        pivot_a_mm: files[0].pivot_a_mm,
        offset_c_mm: files[0].offset_c_mm,
        ..Default::default()
    };
    let mut loc = [0.0; 8];
    let mut drift = vec![[0.0; 8]; o.sensors.len()];
    let (mut location, mut drift_v, mut comps) = (Vec::new(), Vec::new(), Vec::new());
    let mut linear_delta = Vec::new();
    let (mut eps, mut spindle) = ([0.0; 2], Vec::new());
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
            Col::Spindle(k) => {
                eps[k] = x[j];
                spindle.push(tv(SPINDLE_NAMES[k].to_string(), "µrad"));
            }
        }
    }
    model.location = Location::from_array(loc);
    if spindle.len() == 2 && spindle.iter().all(|t| t.value.is_some()) {
        // the model holds the location errors as they appear at the files'
        // mean tool, the spindle's tilt relative to it (model::Spindle)
        let s = Spindle {
            about_x_urad: eps[0],
            about_y_urad: eps[1],
            reference_tool_mm: mean_tool(files),
        };
        model.location = s.move_location(&model.location, [0.0; 3], s.reference_tool_mm);
        model.spindle = Some(s);
    }
    model.drift = (o.sensors.iter().zip(reference).zip(&drift))
        .map(|((s, r), d)| Drift {
            sensor: s.clone(),
            reference_c: *r,
            per_kelvin: Location::from_array(*d),
        })
        .collect();
    Values {
        model,
        location,
        drift: drift_v,
        components: comps,
        linear_delta,
        spindle,
    }
}

/// The problem as solved, kept for the adequacy test: each file's rows
/// (held out in turn) and each unknown's error name.
fn stored_design(
    files: &[RTestFile],
    o: &RotaryOptions,
    cols: &[Col],
    a: DMatrix<f64>,
    b: DVector<f64>,
    rtest_rows: usize,
    sigma_r: f64,
) -> StoredDesign {
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
    StoredDesign {
        a,
        b,
        rtest_rows,
        weight_r: 1.0 / sigma_r,
        weight_l: 1.0,
        prior_rows: false,
        harmonic_rows: 0,
        groups,
        labels,
        cols: cols.to_vec(),
    }
}

fn ensure(f: &mut crate::five_axis::Fourier, h: usize) {
    if f.cos.len() < h {
        f.cos.resize(h, 0.0);
    }
    if f.sin.len() < h {
        f.sin.resize(h, 0.0);
    }
}

fn set_coef(f: &mut crate::five_axis::Fourier, h: usize, sin: bool, v: f64) {
    ensure(f, h);
    if sin {
        f.sin[h - 1] = v;
    } else {
        f.cos[h - 1] = v;
    }
}

fn add_coef(f: &mut crate::five_axis::Fourier, sin: bool, v: f64) {
    ensure(f, 1);
    if sin {
        f.sin[0] += v;
    } else {
        f.cos[0] += v;
    }
}

#[cfg(test)]
#[path = "identify_tests.rs"]
mod tests;

/// The location errors only: a name → value map for reports.
pub fn location_map(l: &Location) -> BTreeMap<String, f64> {
    LOCATION_NAMES
        .iter()
        .map(|n| n.to_string())
        .zip(l.to_array())
        .collect()
}

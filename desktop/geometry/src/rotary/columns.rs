//! The unknowns of the rotary fit (`identify`, `joint`, `bias`): what to
//! fit, one column per unknown (location errors, their drift, component
//! harmonics, backward-whirl pairs, the spindle's direction, file offsets,
//! the linear model's corrections), each column's name and the reading one
//! unit of it produces at a pose.

use nalgebra::Vector3;
use serde::Serialize;

use super::model::{spindle_offset_um, Axis5, ReadingSensitivity, LOCATION_NAMES};
use crate::rtest::RTestFile;

/// What to fit.
#[derive(Clone, Debug)]
pub struct RotaryOptions {
    /// Harmonics of C's and A's component errors (0: location errors only).
    pub order_c: usize,
    pub order_a: usize,
    /// Drift of each location error with these sensors (names without
    /// `T_`; every file must have them); empty: none.
    pub sensors: Vec<String>,
    /// The Gaussian prior on an axis's harmonic coefficients that the
    /// evidence chose its order with (`orders::choose_orders` sets it for
    /// an `auto` axis): the fit is then that order's posterior, its σ's the
    /// posterior covariance's. None for an axis (a given order): plain
    /// least squares.
    pub harmonic_prior: Vec<HarmonicPrior>,
}

/// An axis's harmonic coefficients a priori: harmonic k's coefficients
/// N(0, (τ ρ^(k−1))²), τ per unit group (`orders` module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HarmonicPrior {
    pub axis: Axis5,
    /// τ of the translations [µm] and of the rotations [µrad]
    /// (infinite: the axis has no such coefficient).
    pub tau_um: f64,
    pub tau_urad: f64,
    /// ρ, the size of each harmonic over the one before.
    pub ratio: f64,
    /// The stated noise of one R-test reading the evidence was judged at
    /// [µm]: the prior's weight against the readings.
    pub noise_um: f64,
}

impl HarmonicPrior {
    /// The prior σ of a coefficient of harmonic `h` (µrad: `urad`).
    pub fn sd(&self, h: usize, urad: bool) -> f64 {
        let tau = if urad { self.tau_urad } else { self.tau_um };
        tau * self.ratio.powi(h as i32 - 1)
    }
}

/// The harmonic and unit (true: µrad) of a column of `ax`'s error motions.
pub(crate) fn harmonic(col: &Col, ax: Axis5) -> Option<(usize, bool)> {
    match *col {
        Col::Comp(a, k, h, _) if a == ax => Some((h, k >= 3)),
        Col::Whirl(a, p, _) if a == ax => Some((1, p == 1)),
        _ => None,
    }
}

/// The prior rows of `o.harmonic_prior` in the units of R-test rows
/// weighted by `weight_r` (1/σ of the solve): one per harmonic
/// coefficient, (column, weight_r · σ_stated / σ_prior), right side 0.
/// Whitened at the stated noise (every row × 1/(weight_r σ_stated), as
/// `StoredDesign::at_noise` does to R-test rows) each is 1/σ_prior: the
/// evidence's prior exactly.
pub(crate) fn prior_rows(o: &RotaryOptions, cols: &[Col], weight_r: f64) -> Vec<(usize, f64)> {
    let mut rows = Vec::new();
    for p in &o.harmonic_prior {
        for (j, c) in cols.iter().enumerate() {
            if let Some((h, urad)) = harmonic(c, p.axis) {
                let sd = p.sd(h, urad);
                if sd.is_finite() && sd > 0.0 {
                    rows.push((j, weight_r * p.noise_um / sd));
                }
            }
        }
    }
    rows
}

impl Default for RotaryOptions {
    fn default() -> Self {
        RotaryOptions {
            order_c: 3,
            order_a: 2,
            sensors: Vec::new(),
            harmonic_prior: Vec::new(),
        }
    }
}

/// One unknown's value with its standard uncertainty; `None` when not observable (as `identify` reports it).
#[derive(Clone, Debug, Serialize)]
pub struct TermValue {
    pub name: String,
    pub unit: String,
    pub value: Option<f64>,
    pub sigma: Option<f64>,
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
    /// joint fit with the 14 lines, `joint`).
    Lin(usize),
    /// The spindle's tilt about x (0) or y (1) relative to the lines'
    /// frame [µrad]: only with several tool lengths ([`tools`]).
    Spindle(usize),
}

/// Names of the spindle's two angles, in [`Col::Spindle`] order.
pub const SPINDLE_NAMES: [&str; 2] = ["spindle about x", "spindle about y"];

/// Tools closer than this [mm] count as one (as nest positions do).
const SAME_TOOL_MM: f64 = 0.5;

/// The distinct tool vectors of the files. With one, a spindle tilt is a
/// constant tool offset that the location errors absorb exactly (`model`'s
/// `Spindle`): its two angles are not identifiable and get no column.
pub(crate) fn tools(files: &[RTestFile]) -> Vec<[f64; 3]> {
    let mut out: Vec<[f64; 3]> = Vec::new();
    for f in files {
        let same = |t: &[f64; 3]| (0..3).all(|k| (t[k] - f.tool_mm[k]).abs() < SAME_TOOL_MM);
        if !out.iter().any(same) {
            out.push(f.tool_mm);
        }
    }
    out
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

impl Col {
    pub(crate) fn name(&self, o: &RotaryOptions, files: &[RTestFile]) -> String {
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
            Col::Spindle(k) => SPINDLE_NAMES[k].to_string(),
        }
    }
    /// The error names this unknown belongs to (none for the file offsets).
    pub(crate) fn terms(&self, o: &RotaryOptions) -> Vec<String> {
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
            Col::Spindle(k) => vec![SPINDLE_NAMES[k].to_string()],
        }
    }
}

pub(crate) fn columns(o: &RotaryOptions, files: &[RTestFile]) -> Vec<Col> {
    let mut cols: Vec<Col> = (0..8).map(Col::Loc).collect();
    if tools(files).len() > 1 {
        cols.extend((0..2).map(Col::Spindle));
    }
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
    for f in 0..files.len() {
        cols.extend((0..3).map(|d| Col::Const(f, d)));
    }
    cols
}

/// The reading (workpiece frame, µm) one µrad of spindle tilt `k` produces
/// with tool `tool_mm`: the tool offset `ε × t` turned into the workpiece
/// frame (its constant part goes into the file's offsets).
pub(crate) fn spindle_effect(k: usize, s: &ReadingSensitivity, tool_mm: [f64; 3]) -> Vector3<f64> {
    let mut eps = [0.0; 2];
    eps[k] = 1.0;
    s.lin_rot * spindle_offset_um(eps, Vector3::from(tool_mm))
}

/// The reading (workpiece frame, µm) one unit of `col` produces at a pose
/// (zero for the linear model's columns, `joint` fills those, and for the
/// spindle's, [`spindle_effect`]: they need the file's tool).
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
        Col::Lin(_) | Col::Spindle(_) => Vector3::zeros(),
    }
}

//! The rotary axes of a table-tilting XYZ-A-C machine in the R-test
//! convention of `shared/formats/rtest.md` (copied to
//! docs/formats/rtest.md): eight ISO 230-7 location errors, the six
//! component errors (error motions) of each rotary axis as Fourier series
//! in its angle, and the location errors' drift with sensor temperatures.
//!
//! Chain (workpiece frame → machine frame, linear axes at zero):
//!
//! ```text
//! W(a, c) = Trans(pivot_A) · M_A(a) · Trans(offset_C) · M_C(c)
//! M_k(θ)  = E_k(θ) · L_k · R_k(θ) · L_k⁻¹
//! ```
//!
//! `R_k` is the nominal rotation (A about x, C about z), `L_k` the location
//! error (a shift and a tilt of the axis line at the axis's nominal origin),
//! so `L_k·R_k·L_k⁻¹` is a rotation about the actual axis line; `E_k(θ)` the
//! component errors in **fixed** directions at the axis origin (the frame
//! that does not turn with the axis), zero at θ = 0. At A = C = 0 the chain
//! is the nominal one: R-test readings are relative to that pose.
//!
//! To first order the error of axis k at angle θ, in its fixed frame, is
//! `δ = (I − R(θ))·δ_L + E_t(θ)` and `ε = (I − R(θ))·ε_L + E_r(θ)`. The
//! location errors therefore produce a once-per-revolution "forward whirl"
//! in the radial pair (EXC, EYC), the tilt pair (EAC, EBC) and, for A, the
//! pairs (EYA, EZA) and (EBA, ECA). As rtest.md says, that part belongs to
//! the location error: a model's first harmonic of those pairs is kept in
//! the complementary "backward whirl" (`a_X = −b_Y`, `b_X = a_Y` for the
//! pair (X, Y)); [`RotaryModel::canonical`] moves any forward-whirl part
//! into the location errors.

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

use crate::errors::GeometricErrors;
use crate::five_axis::Fourier;
use crate::kinematics::{tool_tip_error_exact, Structure};

const UM_PER_MM: f64 = 1e3;
const RAD_PER_URAD: f64 = 1e-6;

/// ISO 230-7 names of the eight location errors, in [`Location::to_array`] order.
pub const LOCATION_NAMES: [&str; 8] = ["XOC", "YOC", "AOC", "BOC", "YOA", "ZOA", "BOA", "COA"];

/// Units of the location errors, same order.
pub const LOCATION_UNITS: [&str; 8] = ["µm", "µm", "µrad", "µrad", "µm", "µm", "µrad", "µrad"];

/// Component-error names of C then A (ISO 230-1 `E{X..C}{axis}`).
pub const COMPONENT_NAMES: [&str; 12] = [
    "EXC", "EYC", "EZC", "EAC", "EBC", "ECC", "EXA", "EYA", "EZA", "EAA", "EBA", "ECA",
];

/// The eight location errors (µm, µrad).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Location {
    /// Where the C axis crosses the plane of `offset_c_mm` in the A frame (A = 0), x and y.
    pub xoc_um: f64,
    pub yoc_um: f64,
    /// Tilt of the C axis about x and y.
    pub aoc_urad: f64,
    pub boc_urad: f64,
    /// Where the A axis crosses the plane x = `pivot_a_mm`.x, y and z.
    pub yoa_um: f64,
    pub zoa_um: f64,
    /// Tilt of the A axis about y and z.
    pub boa_urad: f64,
    pub coa_urad: f64,
}

impl Location {
    pub fn to_array(&self) -> [f64; 8] {
        [
            self.xoc_um,
            self.yoc_um,
            self.aoc_urad,
            self.boc_urad,
            self.yoa_um,
            self.zoa_um,
            self.boa_urad,
            self.coa_urad,
        ]
    }
    pub fn from_array(v: [f64; 8]) -> Location {
        Location {
            xoc_um: v[0],
            yoc_um: v[1],
            aoc_urad: v[2],
            boc_urad: v[3],
            yoa_um: v[4],
            zoa_um: v[5],
            boa_urad: v[6],
            coa_urad: v[7],
        }
    }
    pub fn add_scaled(&self, o: &Location, f: f64) -> Location {
        let (a, b) = (self.to_array(), o.to_array());
        Location::from_array(std::array::from_fn(|i| a[i] + f * b[i]))
    }
}

/// Linear drift of the location errors with one sensor: per kelvin of
/// `sensor` above `reference_c` (µm/K, µrad/K).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Drift {
    /// Temperature column without `T_`.
    pub sensor: String,
    pub reference_c: f64,
    pub per_kelvin: Location,
}

/// A rotary-axis model: where the axes sit nominally, their errors.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RotaryModel {
    /// Nominal point on the A axis, machine frame, linear axes at zero [mm].
    pub pivot_a_mm: [f64; 3],
    /// Nominal C-axis origin relative to the pivot, A frame [mm].
    pub offset_c_mm: [f64; 3],
    /// Location errors at the reference temperatures (or without drift).
    pub location: Location,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub drift: Vec<Drift>,
    /// Component errors by ISO name (`EXC` … `ECA`), Fourier series
    /// `Σ a_k(cos kθ − 1) + b_k sin kθ` in µm or µrad; missing names are zero.
    #[serde(default)]
    pub components: BTreeMap<String, Fourier>,
    /// Terms the measurements did not determine (`identify-rotary
    /// --partial`): their values here are placeholders (zero), not errors.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unobservable: Vec<String>,
    /// The identification's adequacy verdict (issue 49; `identify-rotary`
    /// writes it). Absent in older files: unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequate: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequacy: Option<crate::adequacy::Adequacy>,
    /// The spindle's direction relative to the linear axes' frame (issue
    /// 49 item 3), when R-test files with several tool lengths determined
    /// it; absent: not determined (with one tool length it is absorbed
    /// into `location`, which is then the apparent one at that tool).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spindle: Option<Spindle>,
}

/// The spindle axis's direction relative to the frame the linear axes
/// (the lines) define: right-handed tilts about x and y, the tool vector
/// `t` becoming `Rx(about_x)·Ry(about_y)·t`, i.e. the tool point moving by
/// `ε × t` with `ε = (about_x, about_y, 0)` in the machine frame.
///
/// A constant tool offset `d` is exactly the location shift `XOC, YOC,
/// YOA, ZOA −= d` (the whole table moved by −d: `T(−d)·W·T(d)`) up to a
/// constant reading. So the model's `location` is the location errors as
/// they appear at `reference_tool_mm` (what the board serves: it has no
/// tool length for the rotary section), and the chain adds only
/// `ε × (t − reference_tool_mm)`; the constant `ε × reference_tool_mm`,
/// the same at every pose, is left out (no R-test or line sees it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Spindle {
    pub about_x_urad: f64,
    pub about_y_urad: f64,
    /// The tool at which `location` holds [mm]; zero: the true location
    /// errors relative to the lines' frame.
    pub reference_tool_mm: [f64; 3],
}

impl Spindle {
    /// Tool-point offset [µm, machine frame] of tool `t` [mm] relative to
    /// the reference tool.
    pub fn offset_um(&self, tool_mm: [f64; 3]) -> Vector3<f64> {
        let t = Vector3::from(tool_mm) - Vector3::from(self.reference_tool_mm);
        spindle_offset_um([self.about_x_urad, self.about_y_urad], t)
    }
    /// Location errors `loc` as they appear at tool `from_mm`, moved to
    /// how they appear at tool `to_mm`.
    pub fn move_location(&self, loc: &Location, from_mm: [f64; 3], to_mm: [f64; 3]) -> Location {
        let t = Vector3::from(to_mm) - Vector3::from(from_mm);
        let d = spindle_offset_um([self.about_x_urad, self.about_y_urad], t);
        loc.add_scaled(&location_shift_of_offset(d), 1.0)
    }
}

/// `ε × t` [µm] for tilts `eps` [µrad] about x and y and a tool `t` [mm].
pub fn spindle_offset_um(eps: [f64; 2], t: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(eps[0], eps[1], 0.0).cross(&t) * (RAD_PER_URAD * UM_PER_MM)
}

/// The location errors that a constant tool offset `d` [µm, machine
/// frame] reads as (`Spindle`'s doc): `XOC, YOC, YOA, ZOA` shifted by −d.
pub fn location_shift_of_offset(d: Vector3<f64>) -> Location {
    Location {
        xoc_um: -d.x,
        yoc_um: -d.y,
        yoa_um: -d.y,
        zoa_um: -d.z,
        ..Default::default()
    }
}

/// A rotary axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis5 {
    A,
    C,
}

impl Axis5 {
    pub fn rotation(self, deg: f64) -> Rotation3<f64> {
        let axis = match self {
            Axis5::A => Vector3::x_axis(),
            Axis5::C => Vector3::z_axis(),
        };
        Rotation3::from_axis_angle(&axis, deg.to_radians())
    }
    /// Component-error names of this axis, in x, y, z, a, b, c order.
    pub fn names(self) -> &'static [&'static str] {
        match self {
            Axis5::C => &COMPONENT_NAMES[..6],
            Axis5::A => &COMPONENT_NAMES[6..],
        }
    }
    /// The two pairs (indices into `names`) whose first harmonic a location
    /// error produces: translations and rotations across the axis.
    pub fn whirl_pairs(self) -> [(usize, usize); 2] {
        match self {
            Axis5::C => [(0, 1), (3, 4)],
            Axis5::A => [(1, 2), (4, 5)],
        }
    }
}

impl RotaryModel {
    pub fn read(path: &Path) -> Result<RotaryModel> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let m: RotaryModel = serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: not a rotary model file: {e}", path.display()))?;
        m.check().with_context(|| path.display().to_string())?;
        Ok(m)
    }

    pub fn check(&self) -> Result<()> {
        for k in self.components.keys() {
            if !COMPONENT_NAMES.contains(&k.as_str()) {
                bail!(
                    "unknown component error {k:?} (expected one of {})",
                    COMPONENT_NAMES.join(", ")
                );
            }
        }
        let finite = self
            .pivot_a_mm
            .iter()
            .chain(&self.offset_c_mm)
            .all(|v| v.is_finite())
            && self.location.to_array().iter().all(|v| v.is_finite())
            && self.drift.iter().all(|d| {
                d.reference_c.is_finite() && d.per_kelvin.to_array().iter().all(|v| v.is_finite())
            })
            && (self.components.values())
                .all(|f| f.cos.iter().chain(&f.sin).all(|v| v.is_finite()));
        if !finite {
            bail!("a value of the rotary model is not finite");
        }
        Ok(())
    }

    /// Location errors at sensor temperatures `temps` (by sensor name; a
    /// sensor the model drifts with but `temps` lacks is an error).
    pub fn location_at(&self, temps: &BTreeMap<String, f64>) -> Result<Location> {
        let mut l = self.location;
        for d in &self.drift {
            let Some(t) = temps.get(&d.sensor) else {
                bail!(
                    "the model drifts with sensor {} but no T_{} is given",
                    d.sensor,
                    d.sensor
                );
            };
            l = l.add_scaled(&d.per_kelvin, t - d.reference_c);
        }
        Ok(l)
    }

    /// Location errors `loc` (the model's, at some temperature state) as
    /// they appear at tool `tool_mm`: without a spindle as given, with one
    /// moved from its reference tool (zero tool: relative to the lines' frame).
    pub fn location_for_tool(&self, loc: &Location, tool_mm: [f64; 3]) -> Location {
        match self.spindle {
            None => *loc,
            Some(s) => s.move_location(loc, s.reference_tool_mm, tool_mm),
        }
    }

    /// Component errors of `axis` at `deg`: [δx, δy, δz µm, εa, εb, εc µrad].
    pub fn components_at(&self, axis: Axis5, deg: f64) -> [f64; 6] {
        let names = axis.names();
        std::array::from_fn(|k| self.components.get(names[k]).map_or(0.0, |f| f.eval(deg)))
    }

    /// The same model with every forward-whirl first harmonic of the
    /// component errors moved into the location errors (the convention
    /// identification reports in; the errors the chain produces unchanged).
    pub fn canonical(&self) -> RotaryModel {
        let mut m = self.clone();
        let mut loc = m.location.to_array();
        for axis in [Axis5::C, Axis5::A] {
            let names = axis.names();
            for (pair, (i, j)) in axis.whirl_pairs().into_iter().enumerate() {
                let first = |m: &RotaryModel, n: &str| {
                    m.components.get(n).map_or((0.0, 0.0), |f| {
                        (
                            f.cos.first().copied().unwrap_or(0.0),
                            f.sin.first().copied().unwrap_or(0.0),
                        )
                    })
                };
                let ((ax, bx), (ay, by)) = (first(&m, names[i]), first(&m, names[j]));
                // Forward whirl of a location (u, v) across the axis:
                // a_X = −u, b_X = v, a_Y = −v, b_Y = −u.
                let u = -(ax + by) / 2.0;
                let v = (bx - ay) / 2.0;
                let set = |m: &mut RotaryModel, n: &str, da: f64, db: f64| {
                    let f = m.components.entry(n.to_string()).or_default();
                    if f.cos.is_empty() {
                        f.cos.push(0.0);
                    }
                    if f.sin.is_empty() {
                        f.sin.push(0.0);
                    }
                    f.cos[0] -= da;
                    f.sin[0] -= db;
                };
                set(&mut m, names[i], -u, v);
                set(&mut m, names[j], -v, -u);
                let slot = match (axis, pair) {
                    (Axis5::C, 0) => 0,
                    (Axis5::C, _) => 2,
                    (Axis5::A, 0) => 4,
                    (Axis5::A, _) => 6,
                };
                loc[slot] += u;
                loc[slot + 1] += v;
            }
        }
        m.location = Location::from_array(loc);
        m
    }
}

/// Location error of `axis` as a shift and tilt vector of its axis line at
/// its origin (µm, µrad), from the eight errors.
fn location_vectors(l: &Location, axis: Axis5) -> (Vector3<f64>, Vector3<f64>) {
    match axis {
        Axis5::C => (
            Vector3::new(l.xoc_um, l.yoc_um, 0.0),
            Vector3::new(l.aoc_urad, l.boc_urad, 0.0),
        ),
        Axis5::A => (
            Vector3::new(0.0, l.yoa_um, l.zoa_um),
            Vector3::new(0.0, l.boa_urad, l.coa_urad),
        ),
    }
}

/// `M_k(θ)` exactly: component errors times the rotation about the actual axis line.
fn axis_motion(axis: Axis5, deg: f64, l: &Location, comp: [f64; 6]) -> Isometry3<f64> {
    let (d, e) = location_vectors(l, axis);
    let tilt = Isometry3::from_parts(
        Translation3::from(d / UM_PER_MM),
        UnitQuaternion::from_scaled_axis(e * RAD_PER_URAD),
    );
    let r = Isometry3::from_parts(Translation3::identity(), axis.rotation(deg).into());
    let e_iso = Isometry3::from_parts(
        Translation3::new(
            comp[0] / UM_PER_MM,
            comp[1] / UM_PER_MM,
            comp[2] / UM_PER_MM,
        ),
        UnitQuaternion::from_euler_angles(
            comp[3] * RAD_PER_URAD,
            comp[4] * RAD_PER_URAD,
            comp[5] * RAD_PER_URAD,
        ),
    );
    e_iso * tilt * r * tilt.inverse()
}

fn trans(v: [f64; 3]) -> Isometry3<f64> {
    Isometry3::translation(v[0], v[1], v[2])
}

/// Nominal chain W₀(a, c).
pub fn nominal_chain(
    pivot: [f64; 3],
    offset_c: [f64; 3],
    a_deg: f64,
    c_deg: f64,
) -> Isometry3<f64> {
    let r =
        |ax: Axis5, d: f64| Isometry3::from_parts(Translation3::identity(), ax.rotation(d).into());
    trans(pivot) * r(Axis5::A, a_deg) * trans(offset_c) * r(Axis5::C, c_deg)
}

/// The commanded linear positions that put the sphere (tool point
/// `tool_mm` from the gauge point) at `nest_mm` in the workpiece frame.
pub fn rtcp_position(
    pivot: [f64; 3],
    offset_c: [f64; 3],
    nest: [f64; 3],
    tool: [f64; 3],
    a_deg: f64,
    c_deg: f64,
) -> [f64; 3] {
    let p = nominal_chain(pivot, offset_c, a_deg, c_deg) * Point3::from(Vector3::from(nest));
    [p.x - tool[0], p.y - tool[1], p.z - tool[2]]
}

/// The linear axes' part of a machine: structure and errors (tool relative
/// to the A table's base).
#[derive(Clone, Copy)]
pub struct Linear<'a> {
    pub structure: &'a Structure,
    pub errors: &'a GeometricErrors,
}

/// A pose of the five axes and the tool.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub pos_mm: [f64; 3],
    pub a_deg: f64,
    pub c_deg: f64,
    pub tool_mm: [f64; 3],
}

/// Tool-tip error in the workpiece frame [µm], exact rigid-body form:
/// actual minus nominal tool point relative to the workpiece, with the
/// location errors `loc` (the model's at some temperature state) and the
/// spindle's tilt, when the model has one, as a tool offset in the
/// machine frame relative to its reference tool ([`Spindle`]).
pub fn tool_tip_error(
    m: &RotaryModel,
    loc: &Location,
    lin: Option<Linear>,
    p: &Pose,
) -> Vector3<f64> {
    let w = trans(m.pivot_a_mm)
        * axis_motion(Axis5::A, p.a_deg, loc, m.components_at(Axis5::A, p.a_deg))
        * trans(m.offset_c_mm)
        * axis_motion(Axis5::C, p.c_deg, loc, m.components_at(Axis5::C, p.c_deg));
    let w0 = nominal_chain(m.pivot_a_mm, m.offset_c_mm, p.a_deg, p.c_deg);
    let p0 = Vector3::from(p.pos_mm) + Vector3::from(p.tool_mm);
    let e_lin = lin.map_or(Vector3::zeros(), |l| {
        tool_tip_error_exact(l.structure, l.errors, p.pos_mm, p.tool_mm)
    }) + m
        .spindle
        .map_or(Vector3::zeros(), |s| s.offset_um(p.tool_mm));
    let actual = w.inverse() * Point3::from(p0 + e_lin / UM_PER_MM);
    let nominal = w0.inverse() * Point3::from(p0);
    (actual - nominal) * UM_PER_MM
}

/// First-order sensitivity of an R-test reading (workpiece frame, µm) to
/// the fixed-frame error of each rotary axis at a pose: `a[k]`, `c[k]` for
/// k = δx, δy, δz (per µm), εa, εb, εc (per µrad); `lin_rot` turns the
/// linear axes' tool-tip error (machine frame) into the workpiece frame.
pub struct ReadingSensitivity {
    pub a: [Vector3<f64>; 6],
    pub c: [Vector3<f64>; 6],
    pub lin_rot: Rotation3<f64>,
}

pub fn reading_sensitivity(
    pivot: [f64; 3],
    offset_c: [f64; 3],
    nest: [f64; 3],
    a_deg: f64,
    c_deg: f64,
) -> ReadingSensitivity {
    let (ra, rc) = (Axis5::A.rotation(a_deg), Axis5::C.rotation(c_deg));
    let n = Vector3::from(nest);
    let q_c = rc * n; // mm, C's fixed frame at its origin
    let q_a = ra * (Vector3::from(offset_c) + q_c); // mm, base frame at the pivot
    let _ = pivot; // the pivot only places the A frame; readings are relative
    let k = RAD_PER_URAD * UM_PER_MM;
    let side = |q: Vector3<f64>, back: Rotation3<f64>| -> [Vector3<f64>; 6] {
        std::array::from_fn(|i| {
            let mut u = Vector3::zeros();
            u[i % 3] = 1.0;
            if i < 3 {
                -(back * u)
            } else {
                -(back * u.cross(&q)) * k
            }
        })
    };
    let back_a = (ra * rc).inverse();
    ReadingSensitivity {
        a: side(q_a, back_a),
        c: side(q_c, rc.inverse()),
        lin_rot: back_a,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> RotaryModel {
        RotaryModel {
            pivot_a_mm: [400.0, 250.0, -150.0],
            offset_c_mm: [0.0, 0.0, 120.0],
            location: Location::from_array([8.0, -6.0, 15.0, -12.0, 5.0, -9.0, 20.0, -14.0]),
            drift: vec![],
            components: [
                ("EXC", vec![1.5, 0.4], vec![-0.8, 0.3]),
                ("EZC", vec![2.0], vec![1.0]),
                ("ECC", vec![3.0, -1.0], vec![4.0, 0.5]),
                ("EYA", vec![1.0], vec![-2.0]),
                ("EAA", vec![5.0], vec![2.0]),
                ("EBA", vec![-3.0], vec![1.0]),
            ]
            .into_iter()
            .map(|(n, c, s)| (n.to_string(), Fourier { cos: c, sin: s }))
            .collect(),
            unobservable: vec![],
            ..Default::default()
        }
    }

    /// First-order reading from the sensitivities, for a model.
    fn linear_reading(m: &RotaryModel, nest: [f64; 3], a: f64, c: f64) -> Vector3<f64> {
        let s = reading_sensitivity(m.pivot_a_mm, m.offset_c_mm, nest, a, c);
        let mut d = Vector3::zeros();
        for (axis, sens, deg) in [(Axis5::A, &s.a, a), (Axis5::C, &s.c, c)] {
            let (dl, el) = location_vectors(&m.location, axis);
            let r = axis.rotation(deg);
            let (dl, el) = (dl - r * dl, el - r * el);
            let comp = m.components_at(axis, deg);
            for k in 0..6 {
                let loc = if k < 3 { dl[k] } else { el[k - 3] };
                d += sens[k] * (loc + comp[k]);
            }
        }
        d
    }

    #[test]
    fn exact_and_first_order_readings_agree_to_second_order() {
        let m = model();
        let nest = [150.0, 40.0, 80.0];
        let tool = [0.0, 0.0, 100.0];
        for (a, c) in [(0.0, 90.0), (-60.0, 30.0), (45.0, 200.0), (90.0, 315.0)] {
            let pos = rtcp_position(m.pivot_a_mm, m.offset_c_mm, nest, tool, a, c);
            let pose = Pose {
                pos_mm: pos,
                a_deg: a,
                c_deg: c,
                tool_mm: tool,
            };
            let ex = tool_tip_error(&m, &m.location, None, &pose);
            let li = linear_reading(&m, nest, a, c);
            assert!(ex.norm() > 5.0, "errors too small to test: {ex}");
            assert!(
                (ex - li).norm() < 0.01,
                "a={a} c={c}: exact {ex} vs first order {li}"
            );
        }
    }

    #[test]
    fn at_the_zero_pose_every_rotary_error_vanishes() {
        let m = model();
        let pose = Pose {
            pos_mm: [500.0, 200.0, 50.0],
            a_deg: 0.0,
            c_deg: 0.0,
            tool_mm: [0.0, 0.0, 100.0],
        };
        assert!(tool_tip_error(&m, &m.location, None, &pose).norm() < 1e-9);
    }

    #[test]
    fn c_offset_reads_as_the_table_turning_about_a_shifted_axis() {
        let mut m = RotaryModel {
            pivot_a_mm: [0.0; 3],
            ..Default::default()
        };
        m.location.xoc_um = 10.0;
        let nest = [100.0, 0.0, 0.0];
        let pos = rtcp_position(m.pivot_a_mm, m.offset_c_mm, nest, [0.0; 3], 0.0, 180.0);
        let pose = Pose {
            pos_mm: pos,
            a_deg: 0.0,
            c_deg: 180.0,
            tool_mm: [0.0; 3],
        };
        // Turning 180° about x = 10 µm puts the table point 20 µm further
        // along +x in the machine; the tool (at the nominal point) is then
        // 20 µm short along machine −x = workpiece +x at C = 180°.
        let e = tool_tip_error(&m, &m.location, None, &pose);
        assert!((e - Vector3::new(20.0, 0.0, 0.0)).norm() < 1e-6, "{e}");
    }

    #[test]
    fn canonical_moves_the_forward_whirl_into_the_location_and_keeps_the_errors() {
        let mut m = model();
        // a forward whirl of a 7 µm / −4 µm C offset written as component errors
        m.components.insert(
            "EYC".into(),
            Fourier {
                cos: vec![4.0],
                sin: vec![-7.0],
            },
        );
        let f = m.components.get_mut("EXC").unwrap();
        f.cos[0] += -7.0;
        f.sin[0] += -4.0;
        let c = m.canonical();
        // the base model's own first harmonics move too; the added whirl adds (7, −4)
        let base = model().canonical();
        assert!((c.location.xoc_um - (base.location.xoc_um + 7.0)).abs() < 1e-12);
        assert!((c.location.yoc_um - (base.location.yoc_um - 4.0)).abs() < 1e-12);
        assert_eq!(c.location.aoc_urad, base.location.aoc_urad);
        let nest = [120.0, -50.0, 60.0];
        for (a, cc) in [(30.0, 45.0), (-75.0, 250.0)] {
            let pos = rtcp_position(m.pivot_a_mm, m.offset_c_mm, nest, [0.0, 0.0, 100.0], a, cc);
            let pose = Pose {
                pos_mm: pos,
                a_deg: a,
                c_deg: cc,
                tool_mm: [0.0, 0.0, 100.0],
            };
            let (e1, e2) = (
                tool_tip_error(&m, &m.location, None, &pose),
                tool_tip_error(&c, &c.location, None, &pose),
            );
            assert!((e1 - e2).norm() < 0.01, "{e1} vs {e2}");
        }
        // idempotent: nothing left to move
        let cc = c.canonical();
        assert!((cc.location.xoc_um - c.location.xoc_um).abs() < 1e-12);
    }

    #[test]
    fn drift_is_linear_in_the_named_sensors() {
        let mut m = model();
        m.drift.push(Drift {
            sensor: "table".into(),
            reference_c: 20.0,
            per_kelvin: Location {
                xoc_um: 1.5,
                ..Default::default()
            },
        });
        let t: BTreeMap<String, f64> = [("table".to_string(), 24.0)].into();
        assert!((m.location_at(&t).unwrap().xoc_um - (8.0 + 6.0)).abs() < 1e-12);
        let err = m.location_at(&BTreeMap::new()).unwrap_err().to_string();
        assert!(err.contains("T_table"), "{err}");
    }
}

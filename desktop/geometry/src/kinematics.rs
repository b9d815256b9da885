//! Kinematics of a three-axis machine with its 21 geometric errors:
//! the tool point relative to the workpiece, exact (homogeneous transforms)
//! and to first order (small angles).
//!
//! Convention (docs/geometry.md): each axis's errors are the error motion of
//! the tool relative to the workpiece that the axis commands (as in
//! docs/formats/displacement-lines.md). Then the tool point relative to the
//! workpiece is one chain of joint transforms, workpiece-side axes first
//! (from the workpiece outwards), then the tool-side axes (from the base
//! outwards):
//!
//! ```text
//! p_actual = M_1 · M_2 · M_3 · p_tool,   M_k = Trans(q_k u_k + δ_k) · Rot(ε_k)
//! ```
//!
//! with `u_k` the axis direction (squareness included), `δ_k` its three
//! translational errors and `ε_k` its three angles (`Rot = Rz·Ry·Rx`). An
//! angle of axis k turns everything after it in the chain about the origin
//! of frame k, so its Abbe arm is the nominal travel of the later axes plus
//! the tool offset: a workpiece-side carriage "sees" the tool-side motion.

use anyhow::{bail, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::errors::{Axis, Component, GeometricErrors, Term};

/// µm per mm, and rad per µrad.
const UM_PER_MM: f64 = 1e3;
const RAD_PER_URAD: f64 = 1e-6;

/// Which axes carry the workpiece and which the tool, e.g. `XY/Z`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Structure {
    /// From the workpiece down to the base (`XY/Z`: X, Y).
    pub workpiece: Vec<Axis>,
    /// From the base out to the tool (`XY/Z`: Z).
    pub tool: Vec<Axis>,
}

impl Structure {
    pub fn parse(s: &str) -> Result<Structure> {
        let Some((w, t)) = s.trim().split_once('/') else {
            bail!("structure {s:?}: expected workpiece axes '/' tool axes, e.g. XY/Z");
        };
        let side = |part: &str| -> Result<Vec<Axis>> {
            part.chars()
                .map(|c| {
                    Axis::from_letter(c).ok_or_else(|| {
                        anyhow::anyhow!("structure {s:?}: {c:?} is not a linear axis X, Y or Z")
                    })
                })
                .collect()
        };
        let st = Structure {
            workpiece: side(w.trim())?,
            tool: side(t.trim())?,
        };
        let mut seen = st.chain_vec();
        seen.sort();
        if seen != Axis::ALL {
            bail!("structure {s:?}: name each of X, Y, Z exactly once");
        }
        Ok(st)
    }

    fn chain_vec(&self) -> Vec<Axis> {
        self.workpiece.iter().chain(&self.tool).copied().collect()
    }

    /// The joint order from the workpiece to the tool.
    pub fn chain(&self) -> [Axis; 3] {
        let v = self.chain_vec();
        [v[0], v[1], v[2]]
    }

    /// The error axes' position in the chain (0 = next to the workpiece).
    pub fn rank(&self, axis: Axis) -> usize {
        self.chain().iter().position(|a| *a == axis).unwrap_or(0)
    }
}

impl std::fmt::Display for Structure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = |v: &[Axis]| v.iter().map(|a| a.letter()).collect::<String>();
        write!(f, "{}/{}", s(&self.workpiece), s(&self.tool))
    }
}

fn unit(i: usize) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    v[i] = 1.0;
    v
}

/// Exact direction of an axis with the squareness errors.
pub fn axis_direction(axis: Axis, e: &GeometricErrors) -> Vector3<f64> {
    let s = e.squareness;
    match axis {
        Axis::X => Vector3::x(),
        Axis::Y => UnitQuaternion::from_euler_angles(0.0, 0.0, s.c0y * RAD_PER_URAD) * Vector3::y(),
        Axis::Z => {
            UnitQuaternion::from_euler_angles(0.0, s.b0z * RAD_PER_URAD, 0.0)
                * (UnitQuaternion::from_euler_angles(s.a0z * RAD_PER_URAD, 0.0, 0.0) * Vector3::z())
        }
    }
}

/// Joint transform `M_k` of one axis at position `q` [mm].
fn joint(axis: Axis, q: f64, e: &GeometricErrors) -> Isometry3<f64> {
    let v = |c: Component| e.value(Term { axis, component: c }, q);
    let delta = Vector3::new(v(Component::Ex), v(Component::Ey), v(Component::Ez)) / UM_PER_MM;
    let rot = UnitQuaternion::from_euler_angles(
        v(Component::Ea) * RAD_PER_URAD,
        v(Component::Eb) * RAD_PER_URAD,
        v(Component::Ec) * RAD_PER_URAD,
    );
    let travel = axis_direction(axis, e) * q + delta;
    Isometry3::from_parts(Translation3::from(travel), rot)
}

/// Tool-point error relative to the workpiece [µm], exact rigid-body form:
/// actual minus nominal position of the point at `tool_mm` from the spindle
/// gauge point, with the axes at `pos_mm` (x, y, z).
pub fn tool_tip_error_exact(
    st: &Structure,
    e: &GeometricErrors,
    pos_mm: [f64; 3],
    tool_mm: [f64; 3],
) -> Vector3<f64> {
    let chain = st.chain();
    let m = chain.iter().fold(Isometry3::identity(), |acc, a| {
        acc * joint(*a, pos_mm[a.index()], e)
    });
    let actual = m * Point3::from(Vector3::from(tool_mm));
    let nominal = Vector3::from(pos_mm) + Vector3::from(tool_mm);
    (actual.coords - nominal) * UM_PER_MM
}

/// How the first-order tool-point error depends on each error value at the
/// current position: `Δ = Σ terms[a][c] · E_ca(q_a) + Σ squareness[i] · S_i`.
/// Units: µm per µm for translations, µm per µrad for angles and squareness.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensitivity {
    pub terms: [[Vector3<f64>; 6]; 3],
    /// In the order EC0Y, EB0Z, EA0Z.
    pub squareness: [Vector3<f64>; 3],
}

/// Abbe arm of each axis's angular errors [mm]: nominal travel of the axes
/// after it in the chain plus the tool offset.
pub fn abbe_arm(st: &Structure, axis: Axis, pos_mm: [f64; 3], tool_mm: [f64; 3]) -> Vector3<f64> {
    let chain = st.chain();
    let k = st.rank(axis);
    chain[k + 1..].iter().fold(Vector3::from(tool_mm), |r, a| {
        r + unit(a.index()) * pos_mm[a.index()]
    })
}

pub fn sensitivity(st: &Structure, pos_mm: [f64; 3], tool_mm: [f64; 3]) -> Sensitivity {
    let mut terms = [[Vector3::zeros(); 6]; 3];
    for axis in Axis::ALL {
        let r = abbe_arm(st, axis, pos_mm, tool_mm);
        for c in Component::ALL {
            terms[axis.index()][c.index()] = if c.is_angular() {
                // ε × r with ε in µrad and r in mm gives nm: /1e3 for µm.
                unit(c.index() - 3).cross(&r) * (RAD_PER_URAD * UM_PER_MM)
            } else {
                unit(c.index())
            };
        }
    }
    // d(u_Y)/d(EC0Y) = -x̂; d(u_Z)/d(EB0Z) = +x̂; d(u_Z)/d(EA0Z) = -ŷ.
    let k = RAD_PER_URAD * UM_PER_MM;
    let squareness = [
        Vector3::new(-pos_mm[1] * k, 0.0, 0.0),
        Vector3::new(pos_mm[2] * k, 0.0, 0.0),
        Vector3::new(0.0, -pos_mm[2] * k, 0.0),
    ];
    Sensitivity { terms, squareness }
}

/// Tool-point error relative to the workpiece [µm] to first order in the
/// errors (small angles; products of two errors dropped).
pub fn tool_tip_error_linear(
    st: &Structure,
    e: &GeometricErrors,
    pos_mm: [f64; 3],
    tool_mm: [f64; 3],
) -> Vector3<f64> {
    let s = sensitivity(st, pos_mm, tool_mm);
    let mut d = Vector3::zeros();
    for t in Term::all() {
        d += s.terms[t.axis.index()][t.component.index()] * e.value(t, pos_mm[t.axis.index()]);
    }
    for i in 0..3 {
        d += s.squareness[i] * e.squareness.get(i);
    }
    d
}

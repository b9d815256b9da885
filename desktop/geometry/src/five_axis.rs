//! The five-axis double-turntable chain of seed 001: X, Y, Z as in
//! [`super::kinematics`] (the tool relative to the frame the rotary tables
//! stand on), then the tilting A table (about x) carrying the C rotary table
//! (about z), which carries the workpiece. Each rotary joint is an ideal
//! motion times error transforms, as the seed writes the chain:
//!
//! ```text
//! W(a, c) = Trans(pivot_A) · L_A · Rx(a) · E_A(a) · Trans(offset_C) · L_C · Rz(c) · E_C(c)
//! p_workpiece = W⁻¹ · M_xyz · p_tool
//! ```
//!
//! `L_k` is the axis's constant location error (ISO 230-1 location errors:
//! offsets of the axis line, its squareness; stored as three offsets and
//! three angles, unused ones zero), `E_k(θ)` its error motion (ISO 230-1
//! component errors of a rotary axis: two radial, one axial, two tilt, one
//! angular positioning) as a function of the axis angle. The tool-tip error
//! is actual minus nominal tool point **in the workpiece frame** (what the
//! part sees), µm. Angles of the axes in degrees, errors in µm and µrad.
//!
//! Error motions of a rotary axis are periodic in its angle, so they are
//! Fourier series without a constant term, zero at the axis's zero:
//! `f(θ) = Σ_k a_k·(cos kθ − 1) + b_k·sin kθ`.

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

use super::errors::GeometricErrors;
use super::kinematics::{tool_tip_error_exact, tool_tip_error_linear, Structure};

const UM_PER_MM: f64 = 1e3;
const RAD_PER_URAD: f64 = 1e-6;

/// A rotary axis of the double turntable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Rotary {
    /// Tilting table, turns about x, stands on the base.
    A,
    /// Rotary table, turns about z, stands on the A table.
    C,
}

impl Rotary {
    pub const ALL: [Rotary; 2] = [Rotary::A, Rotary::C];
    pub fn letter(self) -> char {
        match self {
            Rotary::A => 'A',
            Rotary::C => 'C',
        }
    }
    /// Unit vector of the axis of rotation in its own frame.
    fn direction(self) -> Vector3<f64> {
        match self {
            Rotary::A => Vector3::x(),
            Rotary::C => Vector3::z(),
        }
    }
    /// ISO 230-1 names of the six error motions: E{X,Y,Z,A,B,C}{axis}.
    pub fn term_names(self) -> [String; 6] {
        ['X', 'Y', 'Z', 'A', 'B', 'C'].map(|c| format!("E{c}{}", self.letter()))
    }
}

/// A periodic error function of an axis angle, zero at 0°.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Fourier {
    /// a_1 … a_n, the term's unit (µm or µrad).
    #[serde(default)]
    pub cos: Vec<f64>,
    /// b_1 … b_n.
    #[serde(default)]
    pub sin: Vec<f64>,
}

impl Fourier {
    pub fn eval(&self, angle_deg: f64) -> f64 {
        let t = angle_deg.to_radians();
        let c: f64 = (self.cos.iter().enumerate())
            .map(|(k, a)| a * (((k + 1) as f64 * t).cos() - 1.0))
            .sum();
        let s: f64 = (self.sin.iter().enumerate())
            .map(|(k, b)| b * ((k + 1) as f64 * t).sin())
            .sum();
        c + s
    }
    fn scaled(&self, f: f64) -> Fourier {
        Fourier {
            cos: self.cos.iter().map(|v| v * f).collect(),
            sin: self.sin.iter().map(|v| v * f).collect(),
        }
    }
}

/// Errors of one rotary axis.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RotaryErrors {
    /// Location errors: offsets of the axis frame [µm] (x, y, z) and its
    /// angles [µrad] (about x, y, z), constant.
    #[serde(default)]
    pub location: [f64; 6],
    /// Error motions by ISO name (`EXC`, `EYC`, `EZC`, `EAC`, `EBC`, `ECC`
    /// for C), µm or µrad; missing names are zero.
    #[serde(default)]
    pub motion: BTreeMap<String, Fourier>,
}

impl RotaryErrors {
    fn motion_at(&self, axis: Rotary, angle_deg: f64) -> [f64; 6] {
        let names = axis.term_names();
        let mut v = [0.0; 6];
        for (k, name) in names.iter().enumerate() {
            if let Some(f) = self.motion.get(name) {
                v[k] = f.eval(angle_deg);
            }
        }
        v
    }
    fn check(&self, axis: Rotary) -> Result<()> {
        let names = axis.term_names();
        for key in self.motion.keys() {
            if !names.contains(key) {
                bail!(
                    "rotary axis {}: unknown error motion {key:?} (expected one of {})",
                    axis.letter(),
                    names.join(", ")
                );
            }
        }
        let all = self.location.iter().chain(
            self.motion
                .values()
                .flat_map(|f| f.cos.iter().chain(&f.sin)),
        );
        for v in all {
            if !v.is_finite() {
                bail!(
                    "rotary axis {}: an error value is not finite",
                    axis.letter()
                );
            }
        }
        Ok(())
    }
}

/// The double turntable: where its axes sit, and their errors.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Turntable {
    /// Origin of the A axis in the frame of the linear axes [mm].
    pub pivot_a_mm: [f64; 3],
    /// Origin of the C axis in the A table's frame [mm].
    pub offset_c_mm: [f64; 3],
    #[serde(default, rename = "A")]
    pub a: RotaryErrors,
    #[serde(default, rename = "C")]
    pub c: RotaryErrors,
}

/// `tooltip --turntable` takes a turntable description (`pivot_a_mm`,
/// `offset_c_mm`, `A`, `C`) and nothing else: any other key means another
/// kind of file, named in the refusal (an `identify-rotary` model read as a
/// turntable would be an error-free one, 11–28 µm off: issue 49).
pub fn refuse_non_turntable(path: &Path) -> Result<()> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: not a turntable file: {e}", path.display()))?;
    let Some(o) = v.as_object() else {
        bail!(
            "{}: not a turntable file (not a JSON object)",
            path.display()
        );
    };
    let has = |k: &str| o.contains_key(k);
    let what = if has("location") || has("components") {
        Some("an identify-rotary model (R-test convention: location, components), not a turntable description; it is what `export --rotary` and `check-rotary --model` read")
    } else if has("errors") && has("structure") {
        Some("an errors file of the linear axes; give it as --errors")
    } else if has("terms") && has("stroke_mm") {
        Some("a volumetric table (`geometry table --json`), not a turntable description")
    } else {
        None
    };
    if let Some(w) = what {
        bail!("{}: this is {w}", path.display());
    }
    let extra: Vec<&String> = o
        .keys()
        .filter(|k| !["pivot_a_mm", "offset_c_mm", "A", "C"].contains(&k.as_str()))
        .collect();
    if !extra.is_empty() {
        bail!(
            "{}: not a turntable file: unknown key(s) {} (a turntable has pivot_a_mm, offset_c_mm, A, C)",
            path.display(),
            extra.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    Ok(())
}

impl Turntable {
    pub fn read(path: &Path) -> Result<Turntable> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let t: Turntable = serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: not a turntable file: {e}", path.display()))?;
        t.check()?;
        Ok(t)
    }
    pub fn check(&self) -> Result<()> {
        if !self
            .pivot_a_mm
            .iter()
            .chain(&self.offset_c_mm)
            .all(|v| v.is_finite())
        {
            bail!("turntable: pivot or offset is not finite");
        }
        self.a.check(Rotary::A)?;
        self.c.check(Rotary::C)
    }
    fn errors(&self, axis: Rotary) -> &RotaryErrors {
        match axis {
            Rotary::A => &self.a,
            Rotary::C => &self.c,
        }
    }
    /// Every error multiplied by `f` (geometry kept).
    pub fn scaled(&self, f: f64) -> Turntable {
        let s = |r: &RotaryErrors| RotaryErrors {
            location: r.location.map(|v| v * f),
            motion: r
                .motion
                .iter()
                .map(|(k, v)| (k.clone(), v.scaled(f)))
                .collect(),
        };
        Turntable {
            a: s(&self.a),
            c: s(&self.c),
            ..self.clone()
        }
    }
}

/// Angles of the rotary axes [deg].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RotaryPos {
    pub a_deg: f64,
    pub c_deg: f64,
}

/// One factor of the workpiece chain W: a nominal transform or an error
/// transform (translation µm, angles µrad).
enum Factor {
    Nominal(Isometry3<f64>),
    Error([f64; 6]),
}

fn error_iso(e: &[f64; 6]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(e[0] / UM_PER_MM, e[1] / UM_PER_MM, e[2] / UM_PER_MM),
        UnitQuaternion::from_euler_angles(
            e[3] * RAD_PER_URAD,
            e[4] * RAD_PER_URAD,
            e[5] * RAD_PER_URAD,
        ),
    )
}

fn rotation(axis: Rotary, deg: f64) -> Isometry3<f64> {
    Isometry3::rotation(axis.direction() * deg.to_radians())
}

fn translation(v: [f64; 3]) -> Isometry3<f64> {
    Isometry3::translation(v[0], v[1], v[2])
}

/// The workpiece chain W (base of the turntable → workpiece) as factors.
fn workpiece_chain(t: &Turntable, r: RotaryPos) -> Vec<Factor> {
    let mut f = Vec::with_capacity(8);
    for (axis, origin, deg) in [
        (Rotary::A, t.pivot_a_mm, r.a_deg),
        (Rotary::C, t.offset_c_mm, r.c_deg),
    ] {
        let e = t.errors(axis);
        f.push(Factor::Nominal(translation(origin)));
        f.push(Factor::Error(e.location));
        f.push(Factor::Nominal(rotation(axis, deg)));
        f.push(Factor::Error(e.motion_at(axis, deg)));
    }
    f
}

fn compose(factors: &[Factor], with_errors: bool) -> Isometry3<f64> {
    factors
        .iter()
        .fold(Isometry3::identity(), |acc, f| match f {
            Factor::Nominal(m) => acc * m,
            Factor::Error(e) if with_errors => acc * error_iso(e),
            Factor::Error(_) => acc,
        })
}

/// Nominal tool point in the workpiece frame [mm] for the linear axes at
/// `pos_mm`, the rotary axes at `r`, tool offset `tool_mm`.
pub fn nominal_point(
    t: &Turntable,
    pos_mm: [f64; 3],
    r: RotaryPos,
    tool_mm: [f64; 3],
) -> Vector3<f64> {
    let w0 = compose(&workpiece_chain(t, r), false);
    let p0 = Vector3::from(pos_mm) + Vector3::from(tool_mm);
    (w0.inverse() * Point3::from(p0)).coords
}

/// Tool-tip error in the workpiece frame [µm], exact rigid-body form.
pub fn tool_tip_error_exact5(
    st: &Structure,
    lin: &GeometricErrors,
    t: &Turntable,
    pos_mm: [f64; 3],
    r: RotaryPos,
    tool_mm: [f64; 3],
) -> Vector3<f64> {
    let chain = workpiece_chain(t, r);
    let w = compose(&chain, true);
    let p0 = Vector3::from(pos_mm) + Vector3::from(tool_mm);
    // The linear chain's actual tool point in the turntable's base frame.
    let p = p0 + tool_tip_error_exact(st, lin, pos_mm, tool_mm) / UM_PER_MM;
    let actual = w.inverse() * Point3::from(p);
    (actual.coords - nominal_point(t, pos_mm, r, tool_mm)) * UM_PER_MM
}

/// The same to first order in the errors (small angles, products of two
/// errors dropped). For an error transform E between the nominal prefix A
/// and suffix B of W, p_w = B⁻¹·E⁻¹·A⁻¹·p, so its first-order effect is
/// −R_B⁻¹·(δ + ε × q) with q = A⁻¹·p the tool point in that joint's frame;
/// the linear axes' error enters rotated by W₀⁻¹.
pub fn tool_tip_error_linear5(
    st: &Structure,
    lin: &GeometricErrors,
    t: &Turntable,
    pos_mm: [f64; 3],
    r: RotaryPos,
    tool_mm: [f64; 3],
) -> Vector3<f64> {
    let chain = workpiece_chain(t, r);
    let p0 = Point3::from(Vector3::from(pos_mm) + Vector3::from(tool_mm));
    let w0 = compose(&chain, false);
    let mut d = w0.rotation.inverse() * tool_tip_error_linear(st, lin, pos_mm, tool_mm);
    for (k, f) in chain.iter().enumerate() {
        let Factor::Error(e) = f else { continue };
        let prefix = compose(&chain[..k], false);
        let suffix = compose(&chain[k + 1..], false);
        let q = (prefix.inverse() * p0).coords; // mm
        let delta = Vector3::new(e[0], e[1], e[2]); // µm
        let eps = Vector3::new(e[3], e[4], e[5]) * RAD_PER_URAD;
        let local = delta + eps.cross(&q) * UM_PER_MM;
        d -= suffix.rotation.inverse() * local;
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{random_errors, ErrorSizes};
    use tcomp_numerics::rng::Rng;

    fn random_turntable(rng: &mut Rng) -> Turntable {
        let mut r = |s: f64| rng.range(-s, s);
        let mut t = Turntable {
            pivot_a_mm: [250.0, 200.0, -150.0],
            offset_c_mm: [0.0, 0.0, 120.0],
            ..Default::default()
        };
        for (axis, e) in [(Rotary::A, &mut t.a), (Rotary::C, &mut t.c)] {
            e.location = [r(20.0), r(20.0), r(20.0), r(30.0), r(30.0), r(30.0)];
            for (k, name) in axis.term_names().iter().enumerate() {
                let size = if k < 3 { 5.0 } else { 15.0 };
                e.motion.insert(
                    name.clone(),
                    Fourier {
                        cos: vec![r(size), r(size / 3.0)],
                        sin: vec![r(size), r(size / 3.0)],
                    },
                );
            }
        }
        t
    }

    fn setup(seed: u64) -> (Structure, GeometricErrors, Turntable) {
        let mut rng = Rng::new(seed);
        let st = Structure::parse("/XYZ").unwrap();
        let lin = random_errors([500.0, 400.0, 300.0], &ErrorSizes::default(), &mut rng);
        (st, lin, random_turntable(&mut rng))
    }

    #[test]
    fn with_the_tables_at_zero_and_error_free_it_is_the_three_axis_error() {
        let (st, lin, mut t) = setup(1);
        t.a = RotaryErrors::default();
        t.c = RotaryErrors::default();
        let (pos, tool) = ([120.0, 300.0, 80.0], [10.0, -20.0, 150.0]);
        let e5 = tool_tip_error_exact5(&st, &lin, &t, pos, RotaryPos::default(), tool);
        let e3 = tool_tip_error_exact(&st, &lin, pos, tool);
        assert!((e5 - e3).norm() < 1e-6, "{e5} vs {e3}");
        assert!(e3.norm() > 1.0, "the linear errors must show");
        // At other angles the same error is seen turned into the workpiece frame.
        let r = RotaryPos {
            a_deg: 0.0,
            c_deg: 90.0,
        };
        let e5 = tool_tip_error_exact5(&st, &lin, &t, pos, r, tool);
        assert!((e5.norm() - e3.norm()).abs() < 1e-6);
        assert!(
            (e5 - e3).norm() > 0.5,
            "C at 90° must turn the error vector"
        );
    }

    #[test]
    fn first_order_form_differs_from_exact_by_second_order_terms() {
        let (st, lin, t) = setup(2);
        let (pos, tool) = ([400.0, 50.0, 250.0], [0.0, 0.0, 180.0]);
        let r = RotaryPos {
            a_deg: -35.0,
            c_deg: 130.0,
        };
        let gap = |f: f64| {
            let (l, tt) = (lin.scaled(f), t.scaled(f));
            let ex = tool_tip_error_exact5(&st, &l, &tt, pos, r, tool);
            let li = tool_tip_error_linear5(&st, &l, &tt, pos, r, tool);
            assert!(ex.norm() > 5.0 * f, "errors too small to test: {ex}");
            (ex - li).norm()
        };
        let (g1, g2) = (gap(1.0), gap(0.5));
        assert!(g1 > 1e-9, "exact and linear must not coincide: {g1}");
        let ratio = g1 / g2;
        assert!(
            (3.5..4.5).contains(&ratio),
            "halving the errors should quarter the gap: {ratio}"
        );
    }

    #[test]
    fn angular_positioning_error_of_c_moves_the_point_along_its_circle() {
        let st = Structure::parse("XY/Z").unwrap();
        let lin = GeometricErrors::zero();
        let mut t = Turntable {
            pivot_a_mm: [0.0, 0.0, 0.0],
            offset_c_mm: [0.0, 0.0, 0.0],
            ..Default::default()
        };
        // ECC = 50 µrad at 90° (sin term), nothing else.
        t.c.motion.insert(
            "ECC".into(),
            Fourier {
                cos: vec![],
                sin: vec![50.0],
            },
        );
        let r = RotaryPos {
            a_deg: 0.0,
            c_deg: 90.0,
        };
        // Tool at radius 200 mm from the C axis.
        let e = tool_tip_error_exact5(&st, &lin, &t, [200.0, 0.0, 50.0], r, [0.0; 3]);
        let expected = 200.0 * 50.0 * 1e-3; // mm · µrad → µm
        assert!((e.norm() - expected).abs() < 1e-3, "{e}");
        assert!(
            e.z.abs() < 1e-6,
            "a positioning error stays in the table plane: {e}"
        );
        let p = nominal_point(&t, [200.0, 0.0, 50.0], r, [0.0; 3]);
        // Radial part only to second order: r·ε²/2 = 2.5e-4 µm here.
        let radial = e.dot(&Vector3::new(p.x, p.y, 0.0).normalize());
        assert!(radial.abs() < 1e-3, "tangential, not radial: {e} at {p}");
    }

    #[test]
    fn location_offset_of_c_is_seen_turned_with_the_table() {
        let st = Structure::parse("XY/Z").unwrap();
        let lin = GeometricErrors::zero();
        let mut t = Turntable::default();
        t.c.location[0] = 10.0; // C axis line 10 µm off in x
        let at = |c_deg| {
            tool_tip_error_exact5(
                &st,
                &lin,
                &t,
                [100.0, 0.0, 0.0],
                RotaryPos { a_deg: 0.0, c_deg },
                [0.0; 3],
            )
        };
        let e0 = at(0.0);
        assert!((e0 - Vector3::new(-10.0, 0.0, 0.0)).norm() < 1e-6, "{e0}");
        let e90 = at(90.0);
        // Error = −Rz(−c)·offset: after the table turns +90° the base's x
        // is the workpiece's −y, so −10 µm along base x reads +10 µm along y.
        assert!((e90 - Vector3::new(0.0, 10.0, 0.0)).norm() < 1e-6, "{e90}");
    }

    #[test]
    fn unknown_motion_names_are_refused() {
        let mut t = Turntable::default();
        t.c.motion.insert("EXA".into(), Fourier::default());
        let err = t.check().unwrap_err().to_string();
        assert!(err.contains("EXA") && err.contains("ECC"), "{err}");
    }
}

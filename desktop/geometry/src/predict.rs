//! Predictions at a user's own poses (issue 49 item 4, `tcomp geometry
//! predict`): the desktop model's tool-tip error (f64, first order, the
//! form the board's sections hold; the exact rigid-body chain beside it
//! where the model allows), and what a model image serves at the same pose
//! — the core's own fixed-point functions (`Volumetric::evaluate`,
//! `five_axis::evaluate`), fed as the board feeds them: positions and tool
//! length in µm (holding 6–17, 34–35), A and C in 0.001° (36–39),
//! temperatures in 1/16 °C — with the difference to the desktop at those
//! very inputs and its stated bound.
//!
//! Positions are the PLC's (machine coordinates); the linear model's axis
//! coordinates are these minus the origin (`export --geometry-origin-mm`),
//! the rotary chain's pivot is in machine coordinates. The tool sits on the
//! spindle axis at (0, 0, L), as in the board's section. Sensor names
//! compare without a `T_` prefix.

use anyhow::{bail, Result};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use thermocomp_core::five_axis::{self, fstatus, FiveAxis};
use thermocomp_core::image::Model;
use thermocomp_core::limits::MAX_AXES;
use thermocomp_core::volumetric::{vstatus, Volumetric};

use crate::board::{bound_um, BoardOptions};
use crate::errors::GeometricErrors;
use crate::kinematics::{tool_tip_error_exact, tool_tip_error_linear, Structure};
use crate::rotary::board::stated_bound;
use crate::rotary::frames::rotary_error_machine;
use crate::rotary::model::{nominal_chain, tool_tip_error, Linear, Pose, RotaryModel};
use crate::volumetric::{build, VolumetricPoly};

/// A sensor name without its `T_` prefix.
pub fn bare(name: &str) -> String {
    name.strip_prefix("T_").unwrap_or(name).to_string()
}

/// The linear axes' model: identified errors, or a volumetric table.
pub enum LinearModel {
    Errors {
        structure: Structure,
        errors: Box<GeometricErrors>,
        stroke_mm: [f64; 3],
    },
    Table(Box<VolumetricPoly>),
}

impl LinearModel {
    pub fn stroke_mm(&self) -> [f64; 3] {
        match self {
            LinearModel::Errors { stroke_mm, .. } => *stroke_mm,
            LinearModel::Table(p) => p.stroke_mm,
        }
    }
    /// The f64 polynomial an image's section kind 3 was made from (for
    /// errors: rebuilt as `geometry table` builds it) and its largest
    /// difference to this model's first-order kinematics (µm).
    pub fn poly(&self) -> Result<(VolumetricPoly, f64)> {
        match self {
            LinearModel::Errors {
                structure,
                errors,
                stroke_mm,
            } => {
                let p = build(structure, *stroke_mm, errors, None)?;
                let fit = p.max_fit_error_um;
                Ok((p, fit))
            }
            LinearModel::Table(p) => Ok(((**p).clone(), 0.0)),
        }
    }
}

/// The desktop's models of one machine.
pub struct DesktopModel {
    pub linear: Option<LinearModel>,
    pub rotary: Option<RotaryModel>,
    /// Machine position of the linear model's zero (mm).
    pub origin_mm: [f64; 3],
}

/// One pose: PLC positions (mm), A and C (deg), tool length (mm), sensor
/// temperatures (°C) by bare name.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseIn {
    pub pos_mm: [f64; 3],
    pub a_deg: f64,
    pub c_deg: f64,
    pub tool_mm: f64,
    pub temps_c: BTreeMap<String, f64>,
}

/// The desktop's prediction at one pose (µm).
#[derive(Clone, Debug)]
pub struct Desktop {
    /// First order, machine frame: what the board's registers serve.
    pub machine_um: [f64; 3],
    /// The same in the workpiece frame (`geometry tooltip`'s frame).
    pub workpiece_um: [f64; 3],
    /// The exact rigid-body chain, workpiece frame (`None` for a table, or
    /// a rotary model with a non-zero origin).
    pub exact_workpiece_um: Option<[f64; 3]>,
    /// The linear axes' part and the rotary part, machine frame.
    pub linear_um: [f64; 3],
    pub rotary_um: Option<[f64; 3]>,
}

fn arr(v: Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl DesktopModel {
    /// The sensors the models read, in the order `export` gives the
    /// volumetric section (the table's, then the rotary drift's not among
    /// them), bare names.
    pub fn sensors(&self) -> Vec<String> {
        let mut s: Vec<String> = match &self.linear {
            Some(LinearModel::Table(p)) => p.sensors.iter().map(|n| bare(n)).collect(),
            _ => Vec::new(),
        };
        for d in self.rotary.iter().flat_map(|m| &m.drift) {
            if !s.contains(&bare(&d.sensor)) {
                s.push(bare(&d.sensor));
            }
        }
        s
    }

    fn temp(p: &PoseIn, name: &str) -> Result<f64> {
        match p.temps_c.get(&bare(name)) {
            Some(t) => Ok(*t),
            None => bail!(
                "the model reads sensor {0} but no T_{0} is given",
                bare(name)
            ),
        }
    }

    pub fn predict(&self, p: &PoseIn) -> Result<Desktop> {
        let tool = [0.0, 0.0, p.tool_mm];
        let q: [f64; 3] = std::array::from_fn(|k| p.pos_mm[k] - self.origin_mm[k]);
        let (linear, exact_lin) = match &self.linear {
            None => (Vector3::zeros(), Some(Vector3::zeros())),
            Some(LinearModel::Errors {
                structure, errors, ..
            }) => (
                tool_tip_error_linear(structure, errors, q, tool),
                Some(tool_tip_error_exact(structure, errors, q, tool)),
            ),
            Some(LinearModel::Table(poly)) => {
                let temps: Vec<f64> = (poly.sensors.iter())
                    .map(|s| Self::temp(p, s))
                    .collect::<Result<_>>()?;
                (Vector3::from(poly.eval(q, p.tool_mm, &temps)), None)
            }
        };
        let Some(m) = &self.rotary else {
            return Ok(Desktop {
                machine_um: arr(linear),
                workpiece_um: arr(linear),
                exact_workpiece_um: exact_lin.map(arr),
                linear_um: arr(linear),
                rotary_um: None,
            });
        };
        let temps: BTreeMap<String, f64> = (m.drift.iter())
            .map(|d| Ok((d.sensor.clone(), Self::temp(p, &d.sensor)?)))
            .collect::<Result<_>>()?;
        let loc = m.location_at(&temps)?;
        let tip = [p.pos_mm[0], p.pos_mm[1], p.pos_mm[2] + p.tool_mm];
        // with an identified spindle, its tilt's offset at this tool
        // relative to the model's reference tool (rotary::Spindle)
        let rot = rotary_error_machine(m, &loc, tip, p.a_deg, p.c_deg) + spindle_share(m, tool);
        let machine = linear + rot;
        let r0 = nominal_chain(m.pivot_a_mm, m.offset_c_mm, p.a_deg, p.c_deg).rotation;
        let pose = Pose {
            pos_mm: p.pos_mm,
            a_deg: p.a_deg,
            c_deg: p.c_deg,
            tool_mm: tool,
        };
        let exact = match &self.linear {
            _ if self.origin_mm != [0.0; 3] => None,
            None => Some(tool_tip_error(m, &loc, None, &pose)),
            Some(LinearModel::Errors {
                structure, errors, ..
            }) => Some(tool_tip_error(
                m,
                &loc,
                Some(Linear { structure, errors }),
                &pose,
            )),
            Some(LinearModel::Table(_)) => None,
        };
        Ok(Desktop {
            machine_um: arr(machine),
            workpiece_um: arr(r0.inverse() * machine),
            exact_workpiece_um: exact.map(arr),
            linear_um: arr(linear),
            rotary_um: Some(arr(rot)),
        })
    }
}

/// The registers the board would read for a pose.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardInputs {
    /// HR_POSITIONS (µm), X, Y, Z in the section's slots.
    pub positions_um: [i32; MAX_AXES],
    pub tool_um: i32,
    /// A, C (0.001°).
    pub angles_mdeg: [i32; 2],
    /// The section's sensors (1/16 °C).
    pub temps_16: Vec<Option<i32>>,
}

fn to_i32(v: f64, what: &str) -> Result<i32> {
    let r = v.round();
    if !(r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX)) {
        bail!("{what} {v} does not fit the board's 32-bit register");
    }
    Ok(r as i32)
}

/// The pose as the board's registers carry it (`names`: the section's
/// sensors, bare), and the same pose read back in physical units (what
/// the desktop is compared at).
pub fn board_inputs(v: &Volumetric, names: &[String], p: &PoseIn) -> Result<(BoardInputs, PoseIn)> {
    let mut positions_um = [0i32; MAX_AXES];
    let mut back = p.clone();
    for k in 0..3 {
        let um = to_i32(p.pos_mm[k] * 1e3, "position (µm)")?;
        positions_um[usize::from(v.slots[k])] = um;
        back.pos_mm[k] = f64::from(um) / 1e3;
    }
    let tool_um = to_i32(p.tool_mm * 1e3, "tool length (µm)")?;
    back.tool_mm = f64::from(tool_um) / 1e3;
    let a = to_i32(p.a_deg * 1e3, "A (0.001°)")?;
    let c = to_i32(p.c_deg * 1e3, "C (0.001°)")?;
    (back.a_deg, back.c_deg) = (f64::from(a) / 1e3, f64::from(c) / 1e3);
    let mut temps_16 = Vec::new();
    for n in names {
        let Some(t) = p.temps_c.get(n) else {
            bail!("the image reads sensor {n} but no T_{n} is given");
        };
        let t16 = to_i32(t * 16.0, "temperature (1/16 °C)")?;
        back.temps_c.insert(n.clone(), f64::from(t16) / 16.0);
        temps_16.push(Some(t16));
    }
    Ok((
        BoardInputs {
            positions_um,
            tool_um,
            angles_mdeg: [a, c],
            temps_16,
        },
        back,
    ))
}

/// What the board serves (µm): the core's evaluation.
#[derive(Clone, Debug)]
pub struct Served {
    pub corrections_um: [f64; 3],
    /// The rotary part alone (five-axis section only).
    pub rotary_um: Option<[f64; 3]>,
    /// Input register 186 ([`vstatus`]) and 334 ([`fstatus`]) bits.
    pub status: u16,
    pub five_status: u16,
}

impl Served {
    pub fn valid(&self) -> bool {
        self.status & vstatus::VALID != 0
    }
    /// Something was held at an edge (position, tool, temperature, angle,
    /// or the correction itself): the stated bound does not apply.
    pub fn clamped(&self) -> bool {
        let any = vstatus::POSITION_CLAMPED
            | vstatus::TOOL_CLAMPED
            | vstatus::TEMPERATURE_CLAMPED
            | vstatus::CLAMPED
            | vstatus::ANGLE_CLAMPED;
        self.status & any != 0
    }
    /// The status bits in words.
    pub fn flags(&self) -> Vec<&'static str> {
        let names = [
            (vstatus::POSITION_CLAMPED, "position_clamped"),
            (vstatus::TOOL_CLAMPED, "tool_clamped"),
            (vstatus::TEMPERATURE_CLAMPED, "temperature_clamped"),
            (vstatus::CLAMPED, "correction_clamped"),
            (vstatus::ANGLE_CLAMPED, "angle_clamped"),
            (vstatus::SENSOR_FAULT, "sensor_fault"),
        ];
        let mut f: Vec<&str> = (names.iter())
            .filter(|(b, _)| self.status & b != 0)
            .map(|(_, n)| *n)
            .collect();
        if !self.valid() {
            f.push("not_valid");
        }
        f
    }
}

/// The board's evaluation of `img` at `b`.
pub fn serve(img: &Model, b: &BoardInputs) -> Option<Served> {
    let v = img.volumetric.as_ref()?;
    let tenth = |c: [i32; 3]| c.map(|x| f64::from(x) / 10.0);
    Some(match &img.five_axis {
        None => {
            let out = v.evaluate(&b.positions_um, b.tool_um, &b.temps_16);
            Served {
                corrections_um: tenth(out.corrections),
                rotary_um: None,
                status: out.status,
                five_status: fstatus::NO_SECTION,
            }
        }
        Some(f) => {
            let out =
                five_axis::evaluate(v, f, &b.positions_um, b.tool_um, b.angles_mdeg, &b.temps_16);
            Served {
                corrections_um: tenth(out.corrections),
                rotary_um: Some(tenth(out.rotary)),
                status: out.status,
                five_status: out.five_status,
            }
        }
    })
}

/// The stated bound (µm) on |served − the desktop's linear part| at the
/// board's inputs `b`: the core's quantisation at these temperature rises,
/// the rounding of coefficients, strokes and references
/// ([`crate::board`]'s export bound), plus the table's own difference to
/// the errors' first-order kinematics (`fit_um`).
pub fn linear_bound_um(poly: &VolumetricPoly, v: &Volumetric, b: &BoardInputs, fit_um: f64) -> f64 {
    let rises: Vec<i32> = (v.sensors.iter().zip(&b.temps_16))
        .map(|(s, t)| t.unwrap_or(0).clamp(i32::from(s.min), i32::from(s.max)) - s.sensor.ref_temp)
        .collect();
    let o = BoardOptions {
        channels: Vec::new(),
        slots: v.slots,
        origin_mm: v.origin_um.map(|x| f64::from(x) / 1e3),
        tool_max_mm: f64::from(v.tool_max_um) / 1e3,
        max_correction_um: 0.0,
    };
    bound_um(poly, v, &rises, &o) + fit_um
}

/// The spindle tilt's tool offset [µm, machine frame] at tool `tool_mm`
/// relative to the model's reference tool: the desktop adds it, the board
/// (no tool length in its rotary section) does not serve it.
fn spindle_share(m: &RotaryModel, tool_mm: [f64; 3]) -> Vector3<f64> {
    m.spindle.map_or(Vector3::zeros(), |s| s.offset_um(tool_mm))
}

/// The stated bound (µm) on |served rotary part − the model's f64| at pose
/// `p` (board inputs): [`stated_bound`] at this pose's arm and temperatures,
/// plus the spindle tilt's share the board does not serve ([`spindle_share`]).
pub fn rotary_bound_um(m: &RotaryModel, f: &FiveAxis, p: &PoseIn) -> f64 {
    let tip = [p.pos_mm[0], p.pos_mm[1], p.pos_mm[2] + p.tool_mm];
    let arm = (0..3)
        .map(|k| ((tip[k] - m.pivot_a_mm[k]) / 1e3).powi(2))
        .sum::<f64>()
        .sqrt()
        + m.offset_c_mm.iter().map(|v| v.abs()).sum::<f64>() / 1e3;
    let dt_max = (m.drift.iter())
        .map(|d| {
            let t = p.temps_c.get(&bare(&d.sensor)).copied();
            (t.unwrap_or(d.reference_c) - d.reference_c).abs()
        })
        .fold(0.0f64, f64::max);
    stated_bound(f, arm, dt_max) + spindle_share(m, [0.0, 0.0, p.tool_mm]).norm()
}

/// Whether the image's section kind 3 is `poly` quantised (same strokes
/// to the µm, same terms in order, each coefficient within its rounding):
/// `Err` says where it is not, and then no bound is stated.
pub fn same_table(poly: &VolumetricPoly, v: &Volumetric) -> std::result::Result<(), String> {
    for k in 0..3 {
        let s = f64::from(v.stroke_um[k]) / 1e3;
        if (s - poly.stroke_mm[k]).abs() > 1e-3 {
            return Err(format!(
                "stroke of axis {} is {s} mm in the image, {} mm in the model",
                ["X", "Y", "Z"][k],
                poly.stroke_mm[k]
            ));
        }
    }
    if poly.terms.len() != v.terms.len() {
        return Err(format!(
            "{} terms in the image, {} in the model's table",
            v.terms.len(),
            poly.terms.len()
        ));
    }
    let l_m = f64::from(v.tool_max_um) / 1e6;
    for (i, (t, q)) in poly.terms.iter().zip(&v.terms).enumerate() {
        let sensor = t.sensor.map_or(thermocomp_core::image::NONE, |s| s as u8);
        let full = l_m.powi(i32::from(t.monomial[3]));
        let near =
            (0..3).all(|d| (f64::from(q.coef[d]) - t.coef_um[d] * 1e6 * full).abs() <= 0.5 + 1e-6);
        if t.monomial != q.exps || sensor != q.sensor || !near {
            return Err(format!(
                "term {} ({:?}) differs from the model's table",
                i + 1,
                q.exps
            ));
        }
    }
    Ok(())
}

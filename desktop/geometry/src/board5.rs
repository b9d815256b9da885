//! The five-axis section on the board (issue 31 item 4, desktop half):
//! the rotary axes' errors in physical units (µm, µrad, per kelvin; the
//! R-test names of `shared/formats/rtest.md`) → image section kind 4
//! (`thermocomp_core::five_axis`), and the board's prediction by the very
//! function the firmware runs.
//!
//! [`RotaryModel`] is the JSON an identification writes (`XOC` … `COA`,
//! `EXA` … `ECC`); [`RotaryModel::from_turntable`] takes the simulator's
//! [`Turntable`]. Quantisation: µm → pm and µrad → prad (rounded once), a
//! location error's per-kelvin slopes re-referenced to the volumetric
//! section's (quantised) reference temperatures, angles → 0.001°.

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use thermocomp_core::five_axis::{
    self, FiveAxis, FiveAxisSpec, FiveOutput, FIVE_AXIS_RTEST_LOCATION, LOCATION_NAMES,
    MAX_FOURIER_ORDER, MOTION_LETTERS,
};
use thermocomp_core::image::Model;
use thermocomp_core::volumetric::Volumetric;

use super::five_axis::{Fourier, Rotary, Turntable};

/// A location error: constant, and per kelvin of the model's sensors.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Location {
    /// µm (XOC, YOC, YOA, ZOA) or µrad (AOC, BOC, BOA, COA) at the reference temperatures.
    pub value: f64,
    /// Per kelvin of each of [`RotaryModel::sensors`] (same unit per K).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub per_k: Vec<f64>,
}

/// A location error in JSON: a number (static) or `{value, per_k}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum LocationValue {
    Static(f64),
    Thermal(Location),
}

impl LocationValue {
    fn get(&self) -> Location {
        match self {
            LocationValue::Static(v) => Location {
                value: *v,
                per_k: Vec::new(),
            },
            LocationValue::Thermal(l) => l.clone(),
        }
    }
}

/// The rotary axes' errors of a table-tilting XYZ-A(x)-C(z) machine in
/// physical units (what `tcomp export --rotary` reads).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RotaryModel {
    /// Nominal point on the A axis, machine frame, linear axes at zero (mm).
    pub pivot_a_mm: [f64; 3],
    /// Nominal C-axis origin relative to pivot_a, in the A frame (mm).
    pub offset_c_mm: [f64; 3],
    /// Sensors the per-kelvin slopes refer to (names of the run's `T_` columns).
    #[serde(default)]
    pub sensors: Vec<String>,
    /// Their reference temperatures (°C).
    #[serde(default)]
    pub t_ref_c: Vec<f64>,
    /// XOC, YOC, AOC, BOC, YOA, ZOA, BOA, COA (missing: 0).
    #[serde(default)]
    pub location: BTreeMap<String, LocationValue>,
    /// Component errors EXA … ECA, EXC … ECC as Fourier series (missing: 0).
    #[serde(default)]
    pub motion: BTreeMap<String, Fourier>,
    /// The location errors are in the R-test convention (a rotation about
    /// the actual axis line, zero at A = C = 0): the board serves them as
    /// `(I − R(θ))·ξ_L(T)` (section flag `FIVE_AXIS_RTEST_LOCATION`).
    /// false: as written, constant in the angle (the board's `L·R` form).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub rtest_location: bool,
}

/// A sensor name without its run column's `T_`.
fn bare(name: &str) -> &str {
    name.strip_prefix("T_").unwrap_or(name)
}

/// How the section is laid out on the board.
#[derive(Clone, Debug)]
pub struct FiveAxisOptions {
    /// A and C ranges (degrees); outside is held at the edge and flagged.
    pub a_range_deg: [f64; 2],
    pub c_range_deg: [f64; 2],
    /// Largest total correction per direction (µm).
    pub max_correction_um: f64,
}

impl Default for FiveAxisOptions {
    fn default() -> Self {
        FiveAxisOptions {
            a_range_deg: [-120.0, 120.0],
            c_range_deg: [-720.0, 720.0],
            max_correction_um: 500.0,
        }
    }
}

/// The Turntable's location index of each of [`LOCATION_NAMES`]: (axis, index).
const LOCATION_SLOTS: [(Rotary, usize); 8] = [
    (Rotary::C, 0),
    (Rotary::C, 1),
    (Rotary::C, 3),
    (Rotary::C, 4),
    (Rotary::A, 1),
    (Rotary::A, 2),
    (Rotary::A, 4),
    (Rotary::A, 5),
];

impl RotaryModel {
    /// The static errors of a simulated turntable. Its other location
    /// entries (XOA, AOA, ZOC, COC: not location errors of ISO 230-7, a
    /// setting of the linear axes or of the angle's zero) must be zero.
    pub fn from_turntable(t: &Turntable) -> Result<RotaryModel> {
        let mut location = BTreeMap::new();
        for (name, (axis, i)) in LOCATION_NAMES.iter().zip(LOCATION_SLOTS) {
            let e = match axis {
                Rotary::A => &t.a,
                Rotary::C => &t.c,
            };
            location.insert(name.to_string(), LocationValue::Static(e.location[i]));
        }
        for (axis, e, names) in [
            (Rotary::A, &t.a, ["XOA", "", "", "AOA", "", ""]),
            (Rotary::C, &t.c, ["", "", "ZOC", "", "", "COC"]),
        ] {
            for (i, n) in names.iter().enumerate() {
                if !n.is_empty() && e.location[i] != 0.0 {
                    bail!(
                        "turntable: {n} = {} on axis {} is not a location error the board serves (set it through the linear axes or the angle's zero)",
                        e.location[i],
                        axis.letter()
                    );
                }
            }
        }
        let motion = (t.a.motion.iter().chain(&t.c.motion))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        Ok(RotaryModel {
            pivot_a_mm: t.pivot_a_mm,
            offset_c_mm: t.offset_c_mm,
            location,
            motion,
            ..RotaryModel::default()
        })
    }

    /// Read the JSON (one-line errors naming the file).
    pub fn read(path: &std::path::Path) -> Result<RotaryModel> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
        serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: not a rotary-error file: {e}", path.display()))
    }
}

fn to_i32(v: f64, what: &str) -> Result<i32> {
    let r = v.round();
    if !(r.is_finite() && r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX)) {
        bail!("five-axis {what}: {v} does not fit the board's 32-bit field");
    }
    Ok(r as i32)
}

/// The section for `r`, to go with the volumetric section `vol` whose
/// sensors are named `vol_sensors` (the polynomial's order); refuses with
/// one line what the board cannot hold.
pub fn quantize_five_axis(
    r: &RotaryModel,
    vol: &Volumetric,
    vol_sensors: &[String],
    o: &FiveAxisOptions,
) -> Result<FiveAxis> {
    let mut s = FiveAxisSpec::default();
    for k in 0..3 {
        s.pivot_a_um[k] = to_i32(r.pivot_a_mm[k] * 1e3, "pivot_a (µm)")?;
        s.offset_c_um[k] = to_i32(r.offset_c_mm[k] * 1e3, "offset_c (µm)")?;
    }
    for k in 0..2 {
        s.a_range_mdeg[k] = to_i32(o.a_range_deg[k] * 1e3, "A range (0.001°)")?;
        s.c_range_mdeg[k] = to_i32(o.c_range_deg[k] * 1e3, "C range (0.001°)")?;
    }
    s.max_correction = [to_i32(o.max_correction_um * 10.0, "max correction (0.1 µm)")?; 3];
    if r.t_ref_c.len() != r.sensors.len() {
        bail!(
            "rotary errors: {} sensors but {} reference temperatures",
            r.sensors.len(),
            r.t_ref_c.len()
        );
    }
    // Each of the model's sensors → its column in the volumetric section.
    let mut column = Vec::new();
    for name in &r.sensors {
        match vol_sensors.iter().position(|v| bare(v) == bare(name)) {
            Some(j) => column.push(j),
            None => bail!(
                "rotary errors read sensor {name}, which the volumetric section does not ({})",
                vol_sensors.join(", ")
            ),
        }
    }
    for name in r.location.keys() {
        if !LOCATION_NAMES.contains(&name.as_str()) {
            bail!(
                "rotary errors: unknown location error {name:?} (expected one of {})",
                LOCATION_NAMES.join(", ")
            );
        }
    }
    let mut n_sensors = 0usize;
    for (e, name) in LOCATION_NAMES.iter().enumerate() {
        let Some(l) = r.location.get(*name).map(LocationValue::get) else {
            continue;
        };
        if l.per_k.len() > r.sensors.len() {
            bail!("rotary errors: {name} has more per-kelvin slopes than sensors");
        }
        let mut c0 = l.value;
        let mut per_col = [0.0f64; 4];
        for (i, &slope) in l.per_k.iter().enumerate() {
            let j = column[i];
            let vol_ref = vol
                .sensors
                .get(j)
                .map_or(0.0, |s| f64::from(s.sensor.ref_temp) / 16.0);
            c0 += slope * (vol_ref - r.t_ref_c[i]);
            if slope != 0.0 {
                per_col[j] += slope;
                n_sensors = n_sensors.max(j + 1);
            }
        }
        s.location[e][0] = to_i32(c0 * 1e6, name)?;
        for j in 0..4 {
            s.location[e][1 + j] = to_i32(per_col[j] * 1e6, name)?;
        }
    }
    s.n_sensors = n_sensors as u8;
    let mut order = 0;
    for (axis, letter) in [(0usize, 'A'), (1, 'C')] {
        for (e, m) in MOTION_LETTERS.iter().enumerate() {
            let name = format!("E{m}{letter}");
            let Some(f) = r.motion.get(&name) else {
                continue;
            };
            let n = f.cos.len().max(f.sin.len());
            if n > MAX_FOURIER_ORDER {
                bail!("rotary errors: {name} has order {n}; the board takes at most {MAX_FOURIER_ORDER}");
            }
            for k in 0..n {
                let a = f.cos.get(k).copied().unwrap_or(0.0);
                let b = f.sin.get(k).copied().unwrap_or(0.0);
                s.motion[axis][e][k] = [to_i32(a * 1e6, &name)?, to_i32(b * 1e6, &name)?];
                if a != 0.0 || b != 0.0 {
                    order = order.max(k + 1);
                }
            }
        }
    }
    for key in r.motion.keys() {
        let known = ['A', 'C']
            .iter()
            .any(|l| MOTION_LETTERS.iter().any(|m| *key == format!("E{m}{l}")));
        if !known {
            bail!("rotary errors: unknown component error {key:?} (expected EXA … ECA, EXC … ECC)");
        }
    }
    s.order = order as u8;
    if r.rtest_location {
        s.flags = FIVE_AXIS_RTEST_LOCATION;
    }
    let f = FiveAxis::new(&s).map_err(|e| anyhow::anyhow!("{e}"))?;
    f.check_with(Some(vol))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(f)
}

/// What the board serves for `model` at `positions` (µm), `tool_um`, A and C
/// (0.001°) and the kind-3 sensors' temperatures (1/16 °C): the core's
/// evaluation (`None` without both sections).
pub fn predict5(
    model: &Model,
    positions: &[i32],
    tool_um: i32,
    angles_mdeg: [i32; 2],
    temps: &[Option<i32>],
) -> Option<FiveOutput> {
    let (v, f) = (model.volumetric.as_ref()?, model.five_axis.as_ref()?);
    Some(five_axis::evaluate(
        v,
        f,
        positions,
        tool_um,
        angles_mdeg,
        temps,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::{quantize, BoardOptions};
    use crate::five_axis::{tool_tip_error_linear5, RotaryErrors, RotaryPos};
    use crate::kinematics::Structure;
    use crate::sim::{random_errors, ErrorSizes};
    use crate::volumetric::build;
    use nalgebra::{Rotation3, Vector3};
    use tcomp_numerics::rng::Rng;

    fn random_turntable(rng: &mut Rng) -> Turntable {
        let mut r = |s: f64| rng.range(-s, s);
        let mut t = Turntable {
            pivot_a_mm: [400.0, 250.0, -150.0],
            offset_c_mm: [0.0, 0.0, 120.0],
            ..Default::default()
        };
        for (axis, e) in [(Rotary::A, &mut t.a), (Rotary::C, &mut t.c)] {
            e.location = match axis {
                Rotary::A => [0.0, r(15.0), r(15.0), 0.0, r(30.0), r(30.0)],
                Rotary::C => [r(15.0), r(15.0), 0.0, r(30.0), r(30.0), 0.0],
            };
            for (k, name) in axis.term_names().iter().enumerate() {
                let size = if k < 3 { 4.0 } else { 12.0 };
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

    /// The served correction (machine frame) against the simulator's own
    /// first-order five-axis kinematics turned into the machine frame, at
    /// poses over the whole A and C range.
    #[test]
    fn the_board_serves_the_five_axis_kinematics_in_the_machine_frame() {
        let mut rng = Rng::new(31);
        let stroke = [800.0, 500.0, 400.0];
        let st = Structure::parse("/XYZ").unwrap();
        let lin = random_errors(stroke, &ErrorSizes::default(), &mut rng);
        let t = random_turntable(&mut rng);
        let poly = build(&st, stroke, &lin, None).unwrap();
        let opts = BoardOptions {
            channels: vec![],
            slots: [0, 1, 2],
            origin_mm: [0.0; 3],
            tool_max_mm: 500.0,
            max_correction_um: 1000.0,
        };
        let vol = quantize(&poly, &opts).unwrap();
        let r = RotaryModel::from_turntable(&t).unwrap();
        let f = quantize_five_axis(&r, &vol, &[], &FiveAxisOptions::default()).unwrap();
        assert_eq!(f.order, 2);
        let mut worst = 0.0f64;
        let mut rotary_seen = 0.0f64;
        for i in 0..60 {
            let a = -90.0 + 3.0 * f64::from(i) + 0.123;
            let c = 11.7 * f64::from(i) - 300.0;
            let pos = [
                (0.1 + 0.8 * rng.uniform()) * stroke[0],
                (0.1 + 0.8 * rng.uniform()) * stroke[1],
                (0.1 + 0.8 * rng.uniform()) * stroke[2],
            ];
            let tool = 50.0 + 200.0 * rng.uniform();
            let pos_um = pos.map(|p| (p * 1e3).round() as i32);
            let (a_m, c_m) = ((a * 1e3).round() as i32, (c * 1e3).round() as i32);
            let tool_um = (tool * 1e3).round() as i32;
            // The simulator at exactly the integers the board sees.
            let rp = RotaryPos {
                a_deg: f64::from(a_m) / 1e3,
                c_deg: f64::from(c_m) / 1e3,
            };
            let pos_mm = pos_um.map(|p| f64::from(p) / 1e3);
            let tool_mm = [0.0, 0.0, f64::from(tool_um) / 1e3];
            let d_w = tool_tip_error_linear5(&st, &lin, &t, pos_mm, rp, tool_mm);
            let rw = Rotation3::from_axis_angle(&Vector3::x_axis(), rp.a_deg.to_radians())
                * Rotation3::from_axis_angle(&Vector3::z_axis(), rp.c_deg.to_radians());
            let want = rw * d_w;
            let got = five_axis::evaluate(&vol, &f, &pos_um, tool_um, [a_m, c_m], &[]);
            assert_eq!(got.five_status, five_axis::fstatus::INCLUDED);
            for d in 0..3 {
                let e = (f64::from(got.corrections[d]) / 10.0 - want[d]).abs();
                worst = worst.max(e);
            }
            rotary_seen = rotary_seen
                .max(f64::from(got.rotary.iter().map(|v| v.abs()).max().unwrap()) / 10.0);
        }
        println!(
            "worst |served − kinematics| {worst:.4} µm, rotary part up to {rotary_seen:.1} µm"
        );
        // ½ of 0.1 µm (the register), the kind-3 polynomial's fit, nm-level rest.
        assert!(
            worst <= 0.05 + poly.max_fit_error_um + 0.005,
            "worst {worst} µm (fit {})",
            poly.max_fit_error_um
        );
        assert!(
            rotary_seen > 5.0,
            "the rotary part is large: {rotary_seen} µm"
        );
    }

    #[test]
    fn thermal_location_errors_are_re_referenced_and_refusals_are_one_line() {
        let stroke = [800.0, 500.0, 400.0];
        let st = Structure::parse("/XYZ").unwrap();
        let lin = random_errors(stroke, &ErrorSizes::default(), &mut Rng::new(3));
        let mut poly = build(&st, stroke, &lin, None).unwrap();
        poly.sensors = vec!["T1".into(), "T2".into()];
        poly.t_ref_c = vec![20.0, 21.0];
        let opts = BoardOptions {
            channels: vec![0, 1],
            slots: [0, 1, 2],
            origin_mm: [0.0; 3],
            tool_max_mm: 500.0,
            max_correction_um: 1000.0,
        };
        let vol = quantize(&poly, &opts).unwrap();
        let mut r = RotaryModel {
            pivot_a_mm: [400.0, 250.0, -150.0],
            offset_c_mm: [0.0, 0.0, 120.0],
            sensors: vec!["T2".into()],
            t_ref_c: vec![25.0],
            ..Default::default()
        };
        r.location.insert(
            "XOC".into(),
            LocationValue::Thermal(Location {
                value: 10.0,
                per_k: vec![0.5],
            }),
        );
        let f = quantize_five_axis(&r, &vol, &poly.sensors, &FiveAxisOptions::default()).unwrap();
        // T2 is the section's second sensor: two columns; at 21 °C (the
        // section's reference) XOC = 10 + 0.5 · (21 − 25) = 8 µm.
        assert_eq!(f.n_sensors, 2);
        assert_eq!(f.location[0], [8_000_000, 0, 500_000, 0, 0]);
        let json = r#"{"pivot_a_mm":[0,0,0],"offset_c_mm":[0,0,0],"location":{"XOC":3.5,"ZOC":1}}"#;
        let bad: RotaryModel = serde_json::from_str(json).unwrap();
        let e = quantize_five_axis(&bad, &vol, &poly.sensors, &FiveAxisOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("ZOC") && !e.contains('\n'), "{e}");
        let mut big = r.clone();
        big.location
            .insert("BOA".into(), LocationValue::Static(2000.0));
        let e = quantize_five_axis(&big, &vol, &poly.sensors, &FiveAxisOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("BOA"), "{e}");
        let mut t = Turntable::default();
        t.c.location[2] = 1.0;
        let e = RotaryModel::from_turntable(&t).unwrap_err().to_string();
        assert!(e.contains("ZOC"), "{e}");
        let _ = RotaryErrors::default();
    }
}

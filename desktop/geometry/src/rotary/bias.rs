//! Seed 001 s21–s22 for the rotary drift (issue 31 item 3): keep the
//! fitted temperature slopes of the location errors, re-optimise their
//! constants (the bias terms, the location at the reference temperatures)
//! on tool-tip readings taken at other temperature states, as
//! `thermal::optimise_bias` does for the three linear axes.
//!
//! A tool-tip reading is the error vector of the tool point relative to the
//! workpiece (workpiece frame, µm) at a pose, e.g. a touch probe on an
//! artefact on the table or a tracker; every reading carries the linear
//! axes' error too, which the compensation's linear model predicts. One
//! linear least-squares problem (first-order sensitivities, SVD):
//! directions the readings cannot see stay as the R-test fit left them.

use anyhow::{bail, Result};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;

use super::columns::{effect, Col};
use super::model::{
    nominal_chain, reading_sensitivity, tool_tip_error, Linear, Location, Pose, RotaryModel,
};
use tcomp_numerics::rng::Rng;

/// One tool-tip reading at a pose.
#[derive(Clone, Debug)]
pub struct ToolTip5 {
    pub pose: Pose,
    pub error_um: [f64; 3],
}

/// Tool-tip readings at one temperature state (sensor name → °C).
#[derive(Clone, Debug)]
pub struct RotaryCalibrationState {
    pub temps: BTreeMap<String, f64>,
    pub points: Vec<ToolTip5>,
}

/// The poses of one calibration state: the tool tip at 2×2×2 linear
/// positions (10 %, 90 % of each stroke) × A ∈ {−90, −45, 0, 45, 90}° ×
/// C ∈ {30, 120, 210, 300}°, one 120 mm tool: 160 poses, none on the
/// check's grid.
pub fn calibration_poses(stroke: [f64; 3]) -> Vec<Pose> {
    let mut out = Vec::new();
    for fx in [0.1, 0.9] {
        for fy in [0.1, 0.9] {
            for fz in [0.1, 0.9] {
                for a in [-90.0, -45.0, 0.0, 45.0, 90.0] {
                    for c in [30.0, 120.0, 210.0, 300.0] {
                        out.push(Pose {
                            pos_mm: [fx * stroke[0], fy * stroke[1], fz * stroke[2]],
                            a_deg: a,
                            c_deg: c,
                            tool_mm: [0.0, 0.0, 120.0],
                        });
                    }
                }
            }
        }
    }
    out
}

/// Simulated readings: the machine's exact tool-tip error plus N(0, σ²)
/// per direction.
pub fn simulate_state(
    truth: &RotaryModel,
    lin: Option<Linear>,
    temps: &BTreeMap<String, f64>,
    poses: &[Pose],
    noise_um: f64,
    rng: &mut Rng,
) -> Result<RotaryCalibrationState> {
    let loc = truth.location_at(temps)?;
    let points = poses
        .iter()
        .map(|p| {
            let e = tool_tip_error(truth, &loc, lin, p);
            ToolTip5 {
                pose: *p,
                error_um: std::array::from_fn(|d| e[d] + noise_um * rng.normal()),
            }
        })
        .collect();
    Ok(RotaryCalibrationState {
        temps: temps.clone(),
        points,
    })
}

/// The model with its location constants re-optimised on `calibration`
/// (slopes, reference temperatures and component errors kept); `lin` is
/// the compensation's linear model, whose prediction is taken off.
pub fn optimise_rotary_bias(
    model: &RotaryModel,
    lin: Option<Linear>,
    calibration: &[RotaryCalibrationState],
) -> Result<RotaryModel> {
    let (mut rows, mut y) = (Vec::new(), Vec::new());
    for c in calibration {
        let loc = model.location_at(&c.temps)?;
        for o in &c.points {
            let p = &o.pose;
            let pred = tool_tip_error(model, &loc, lin, p);
            // the tool point in the C (workpiece) frame: the R-test's nest
            let w0 = nominal_chain(model.pivot_a_mm, model.offset_c_mm, p.a_deg, p.c_deg);
            let q = w0.inverse() * Point3::from(Vector3::from(p.pos_mm) + Vector3::from(p.tool_mm));
            let s = reading_sensitivity(
                model.pivot_a_mm,
                model.offset_c_mm,
                [q.x, q.y, q.z],
                p.a_deg,
                p.c_deg,
            );
            let cols: Vec<Vector3<f64>> = (0..8)
                .map(|j| effect(Col::Loc(j), &s, p.a_deg, p.c_deg, 0, &[]))
                .collect();
            for d in 0..3 {
                rows.push(cols.iter().map(|v| v[d]).collect::<Vec<f64>>());
                y.push(o.error_um[d] - pred[d]);
            }
        }
    }
    if rows.is_empty() {
        bail!("rotary bias optimisation: no tool-tip readings");
    }
    let delta = tcomp_numerics::linalg::least_squares(&rows, &y, false, 0.0)?;
    let mut l = model.location.to_array();
    for (v, d) in l.iter_mut().zip(&delta) {
        *v += d;
    }
    let mut out = model.clone();
    out.location = Location::from_array(l);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotary::sim::{random_rotary, RPlan, RotarySizes};

    /// The location columns at a general pose (tool point through the
    /// inverse chain) match the exact chain's change to first order.
    #[test]
    fn location_columns_match_the_exact_chain_at_general_poses() {
        let plan = RPlan::default_plan();
        let mut rng = Rng::new(5);
        let m = random_rotary(&plan, &RotarySizes::default(), false, &mut rng);
        let poses = calibration_poses([800.0, 700.0, 600.0]);
        for j in 0..8 {
            let mut bumped = m.clone();
            let mut l = m.location.to_array();
            l[j] += 5.0;
            bumped.location = Location::from_array(l);
            let cal =
                simulate_state(&bumped, None, &BTreeMap::new(), &poses, 0.0, &mut rng).unwrap();
            let fitted = optimise_rotary_bias(&m, None, &[cal]).unwrap();
            let got = fitted.location.to_array();
            for k in 0..8 {
                let want = if k == j {
                    l[k]
                } else {
                    m.location.to_array()[k]
                };
                assert!(
                    (got[k] - want).abs() < 0.02,
                    "term {k} after bumping {j}: {} vs {want}",
                    got[k]
                );
            }
        }
    }

    /// A model whose location constants are off (slopes nearly right) is
    /// pulled back by readings at three other states: the held-out states'
    /// tool-tip error left over shrinks.
    #[test]
    fn the_bias_step_reduces_the_error_at_held_out_states() {
        use crate::rotary::check::{grid, BIAS_H, HELD_OUT_H};
        use crate::rotary::sim::{warmup_temps, SENSORS};
        let plan = RPlan::default_plan();
        let mut rng = Rng::new(9);
        let truth = random_rotary(&plan, &RotarySizes::default(), true, &mut rng);
        let mut model = truth.clone();
        let mut l = model.location.to_array();
        for (k, v) in l.iter_mut().enumerate() {
            *v += if matches!(k, 2 | 3 | 6 | 7) { 6.0 } else { 2.0 } * rng.range(-1.0, 1.0);
        }
        model.location = Location::from_array(l);
        for d in &mut model.drift {
            let mut p = d.per_kelvin.to_array();
            p.iter_mut().for_each(|v| *v += 0.05 * rng.range(-1.0, 1.0));
            d.per_kelvin = Location::from_array(p);
        }
        let end = 4.5 * 3600.0;
        let at = |h: f64| -> BTreeMap<String, f64> {
            SENSORS
                .iter()
                .map(|s| s.0.to_string())
                .zip(warmup_temps(end + h * 3600.0, Some(end)))
                .collect()
        };
        let stroke = [800.0, 700.0, 600.0];
        let cal: Vec<RotaryCalibrationState> = BIAS_H[..3]
            .iter()
            .map(|h| {
                simulate_state(
                    &truth,
                    None,
                    &at(*h),
                    &calibration_poses(stroke),
                    0.5,
                    &mut rng,
                )
                .unwrap()
            })
            .collect();
        let biased = optimise_rotary_bias(&model, None, &cal).unwrap();
        let left = |m: &RotaryModel| {
            let mut s = 0.0;
            let poses = grid(stroke);
            for h in HELD_OUT_H {
                let temps = at(h);
                let (lt, lm) = (
                    truth.location_at(&temps).unwrap(),
                    m.location_at(&temps).unwrap(),
                );
                for p in &poses {
                    let d = tool_tip_error(&truth, &lt, None, p) - tool_tip_error(m, &lm, None, p);
                    s += d.norm_squared();
                }
            }
            (s / (4 * poses.len()) as f64).sqrt()
        };
        let (before, after) = (left(&model), left(&biased));
        println!("held-out RMS left: {before:.3} µm without, {after:.3} µm with the bias step");
        assert!(after < 0.25 * before, "{after} vs {before}");
    }
}

//! Five-axis check (issue 31): the tool-tip error over a held-out grid of
//! linear positions × A ∈ {−90…90}° × C ∈ {0…315}° before and after
//! compensation with an identified model, and the whole simulated chain
//! the benchmark runs per machine (14 lines → linear errors; R-test files
//! written and read back → rotary errors; grid scored).

use anyhow::Result;
use nalgebra::Vector3;
use serde::Serialize;
use std::collections::BTreeMap;

use super::check::{figures, Compared, Figures};
use super::errors::GeometricErrors;
use super::identify::{identify, to_reference_convention, Degrees, LineObs};
use super::kinematics::Structure;
use super::lines::{average_runs, plan14};
use super::rotary::{tool_tip_error, Linear, RotaryModel, COMPONENT_NAMES, LOCATION_NAMES};
use super::rotary_identify::{identify_rotary, RotaryOptions};
use super::rotary_sim::{
    axis_of, random_rotary, simulate, warmup_temps, CycleSetup, RPlan, RotarySizes, SENSORS,
};
use super::rtest::RTestFile;
use super::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp_data::rng::Rng;

/// A machine as the check sees it.
#[derive(Clone, Copy)]
pub struct Machine5<'a> {
    pub rotary: &'a RotaryModel,
    pub linear: Option<Linear<'a>>,
}

/// The held-out grid: 3×3×3 linear positions (20, 50, 80 % of each
/// stroke), A every 30° over ±90°, C every 45°, two tools: 3,024 poses.
pub fn grid(stroke: [f64; 3]) -> Vec<super::rotary::Pose> {
    let mut out = Vec::new();
    let f = [0.2, 0.5, 0.8];
    for i in f {
        for j in f {
            for k in f {
                for a in (-3..=3).map(|n| 30.0 * n as f64) {
                    for c in (0..8).map(|n| 45.0 * n as f64) {
                        for tool in [[0.0, 0.0, 100.0], [30.0, -40.0, 180.0]] {
                            out.push(super::rotary::Pose {
                                pos_mm: [i * stroke[0], j * stroke[1], k * stroke[2]],
                                a_deg: a,
                                c_deg: c,
                                tool_mm: tool,
                            });
                        }
                    }
                }
            }
        }
    }
    out
}

/// "Measured" (truth plus N(0, noise²) per direction) against predicted
/// tool-tip errors over `grid` at the sensor temperatures `temps`.
#[allow(clippy::too_many_arguments)]
pub fn compare(
    truth: &Machine5,
    model: &Machine5,
    poses: &[super::rotary::Pose],
    temps: &BTreeMap<String, f64>,
    noise_um: f64,
    state: &str,
    rng: &mut Rng,
) -> Result<Vec<Compared>> {
    let (lt, lm) = (
        truth.rotary.location_at(temps)?,
        model.rotary.location_at(temps)?,
    );
    Ok(poses
        .iter()
        .map(|p| {
            let t = tool_tip_error(truth.rotary, &lt, truth.linear, p);
            let noise = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise_um;
            Compared {
                state: state.to_string(),
                measured: t + noise,
                predicted: tool_tip_error(model.rotary, &lm, model.linear, p),
            }
        })
        .collect())
}

/// Per component error, identified minus true over the axis's range
/// (C all round, A ±110°): (RMS of the difference, RMS of the truth) [µm or µrad].
pub fn component_recovery(id: &RotaryModel, truth: &RotaryModel) -> BTreeMap<String, (f64, f64)> {
    let mut out = BTreeMap::new();
    for name in COMPONENT_NAMES {
        let angles: Vec<f64> = match axis_of(name) {
            super::rotary::Axis5::C => (0..72).map(|k| 5.0 * k as f64).collect(),
            super::rotary::Axis5::A => (-22..=22).map(|k| 5.0 * k as f64).collect(),
        };
        let ev = |m: &RotaryModel, d: f64| m.components.get(name).map_or(0.0, |f| f.eval(d));
        let n = angles.len() as f64;
        let diff = (angles
            .iter()
            .map(|d| (ev(id, *d) - ev(truth, *d)).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let size = (angles.iter().map(|d| ev(truth, *d).powi(2)).sum::<f64>() / n).sqrt();
        out.insert(name.to_string(), (diff, size));
    }
    out
}

/// Figures of one simulated machine.
#[derive(Clone, Debug, Serialize)]
pub struct CaseFigures {
    pub seed: u64,
    /// |identified − true| per location error (at held-out states with drift).
    pub location_error: BTreeMap<String, f64>,
    pub worst_um: f64,
    pub worst_urad: f64,
    /// RMS over the component errors of identified − true, µm and µrad
    /// groups, and the RMS of the true ones.
    pub component_rms_um: (f64, f64),
    pub component_rms_urad: (f64, f64),
    pub condition_number: Option<f64>,
    pub unobservable: Vec<String>,
    /// Grid: compensated with linear and rotary models.
    pub grid: Figures,
    /// Grid: compensated with the linear (14-line) model only.
    pub grid_linear_only: Figures,
}

/// The linear machine of a case: truth in the 14-line reference convention
/// and its identification from simulated lines (σ = `noise_um`).
pub fn linear_case(
    stroke: [f64; 3],
    noise_um: f64,
    rng: &mut Rng,
) -> Result<(Structure, GeometricErrors, GeometricErrors)> {
    let st = Structure::parse("/XYZ")?;
    let raw = random_errors(stroke, &ErrorSizes::default(), rng);
    let truth = to_reference_convention(&raw, stroke);
    let setup = MeasurementSetup {
        noise_um,
        ..Default::default()
    };
    let mut files = Vec::new();
    for spec in plan14(stroke, 100.0, 100.0) {
        files.extend(measure_line(&st, &truth, &spec, &setup, None, rng));
    }
    let obs: Vec<LineObs> = average_runs(&files)?.into_iter().map(|a| a.obs).collect();
    let id = identify(&st, &obs, Degrees::default(), stroke)?;
    Ok((st, truth, id.errors))
}

/// Stroke of the simulated machine: the plan's R-test poses stay inside it.
pub const CASE_STROKE: [f64; 3] = [800.0, 700.0, 600.0];

/// One machine through the whole chain. `thermal_cycles` > 0: drift over a
/// warm-up, fitted with every sensor; the grid then at four held-out
/// states of the cool-down after it. `linear_known`: the rotary fit and the
/// compensation take the true linear errors instead of the 14-line ones
/// (separates the rotary identification from the linear one's residue).
pub fn run_case(
    seed: u64,
    noise_um: f64,
    thermal_cycles: usize,
    linear_known: bool,
) -> Result<CaseFigures> {
    let mut rng = Rng::new(seed);
    let plan = RPlan::default_plan();
    let (st, lin_truth, lin_id) = linear_case(CASE_STROKE, noise_um, &mut rng)?;
    let truth = random_rotary(&plan, &RotarySizes::default(), thermal_cycles > 0, &mut rng);
    let lt = Linear {
        structure: &st,
        errors: &lin_truth,
    };
    let li = Linear {
        structure: &st,
        errors: if linear_known { &lin_truth } else { &lin_id },
    };
    let setup = CycleSetup {
        noise_um,
        thermal_cycles,
        ..Default::default()
    };
    // through the file format and back, as a user's files would come
    let files: Vec<RTestFile> = simulate(&truth, Some(lt), &plan, &setup, &mut rng)?
        .iter()
        .map(|f| RTestFile::parse(&f.to_text(), &f.name))
        .collect::<Result<_>>()?;
    let sensors = if thermal_cycles > 0 {
        SENSORS.iter().map(|s| s.0.to_string()).collect()
    } else {
        vec![]
    };
    let id = identify_rotary(
        &files,
        Some(li),
        &RotaryOptions {
            sensors,
            ..Default::default()
        },
    )?;
    let end = setup.cycle_period_s * thermal_cycles as f64;
    let states: Vec<BTreeMap<String, f64>> = if thermal_cycles > 0 {
        [0.5, 1.0, 2.0, 3.0]
            .iter()
            .map(|h| {
                let t = warmup_temps(end + h * 3600.0, Some(end));
                SENSORS.iter().map(|s| s.0.to_string()).zip(t).collect()
            })
            .collect()
    } else {
        vec![BTreeMap::new()]
    };
    let mut location_error: BTreeMap<String, f64> = BTreeMap::new();
    for temps in &states {
        let (t, m) = (
            truth.location_at(temps)?.to_array(),
            id.model.location_at(temps)?.to_array(),
        );
        for k in 0..8 {
            let e = location_error
                .entry(LOCATION_NAMES[k].to_string())
                .or_insert(0.0);
            *e = e.max((t[k] - m[k]).abs());
        }
    }
    let worst = |names: &[&str]| names.iter().map(|n| location_error[*n]).fold(0.0, f64::max);
    let rec = component_recovery(&id.model, &truth);
    let group = |ang: bool| {
        let v: Vec<&(f64, f64)> = rec
            .iter()
            .filter(|(n, _)| {
                (COMPONENT_NAMES.iter().position(|c| c == n).unwrap_or(0) % 6 >= 3) == ang
            })
            .map(|(_, v)| v)
            .collect();
        let k = v.len().max(1) as f64;
        (
            (v.iter().map(|x| x.0 * x.0).sum::<f64>() / k).sqrt(),
            (v.iter().map(|x| x.1 * x.1).sum::<f64>() / k).sqrt(),
        )
    };
    let poses = grid(CASE_STROKE);
    let tm = Machine5 {
        rotary: &truth,
        linear: Some(lt),
    };
    let none = RotaryModel {
        pivot_a_mm: truth.pivot_a_mm,
        offset_c_mm: truth.offset_c_mm,
        ..Default::default()
    };
    let (mut all, mut lin_only) = (Vec::new(), Vec::new());
    for (k, temps) in states.iter().enumerate() {
        let state = format!("S{k}");
        all.extend(compare(
            &tm,
            &Machine5 {
                rotary: &id.model,
                linear: Some(li),
            },
            &poses,
            temps,
            noise_um,
            &state,
            &mut rng,
        )?);
        lin_only.extend(compare(
            &tm,
            &Machine5 {
                rotary: &none,
                linear: Some(li),
            },
            &poses,
            temps,
            noise_um,
            &state,
            &mut rng,
        )?);
    }
    Ok(CaseFigures {
        seed,
        worst_um: worst(&["XOC", "YOC", "YOA", "ZOA"]),
        worst_urad: worst(&["AOC", "BOC", "BOA", "COA"]),
        location_error,
        component_rms_um: group(false),
        component_rms_urad: group(true),
        condition_number: id.condition_number,
        unobservable: id.unobservable_terms.clone(),
        grid: figures(&all.iter().collect::<Vec<_>>()),
        grid_linear_only: figures(&lin_only.iter().collect::<Vec<_>>()),
    })
}

//! Five-axis check (issue 31): the tool-tip error over a held-out grid of
//! linear positions × A ∈ {−90…90}° × C ∈ {0…315}° before and after
//! compensation with an identified model, and the whole simulated chain
//! the benchmark runs per machine (14 lines → linear errors; R-test files
//! written and read back → rotary errors; grid scored).

use anyhow::Result;
use nalgebra::Vector3;
use serde::Serialize;
use std::collections::BTreeMap;

use super::bias::{calibration_poses, optimise_rotary_bias, simulate_state};
use super::identify::{identify_rotary, RotaryOptions};
use super::joint::{identify_rotary_joint, LinearPrior};
use super::model::{tool_tip_error, Linear, RotaryModel, COMPONENT_NAMES, LOCATION_NAMES};
use super::orders::{choose_orders, Order};
use super::sim::{
    axis_of, random_rotary, simulate, warmup_temps, CycleSetup, RPlan, RotarySizes, SENSORS,
};
use crate::check::{figures, Compared, Figures};
use crate::errors::GeometricErrors;
use crate::identify::{identify, to_reference_convention, Degrees, Identification, LineObs};
use crate::kinematics::Structure;
use crate::lines::{average_runs, plan14};
use crate::rtest::RTestFile;
use crate::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp_numerics::rng::Rng;

/// A machine as the check sees it.
#[derive(Clone, Copy)]
pub struct Machine5<'a> {
    pub rotary: &'a RotaryModel,
    pub linear: Option<Linear<'a>>,
}

/// The held-out grid: 3×3×3 linear positions (20, 50, 80 % of each
/// stroke), A every 30° over ±90°, C every 45°, two tools: 3,024 poses.
pub fn grid(stroke: [f64; 3]) -> Vec<super::model::Pose> {
    let mut out = Vec::new();
    let f = [0.2, 0.5, 0.8];
    for i in f {
        for j in f {
            for k in f {
                for a in (-3..=3).map(|n| 30.0 * n as f64) {
                    for c in (0..8).map(|n| 45.0 * n as f64) {
                        for tool in [[0.0, 0.0, 100.0], [30.0, -40.0, 180.0]] {
                            out.push(super::model::Pose {
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
    poses: &[super::model::Pose],
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
            super::model::Axis5::C => (0..72).map(|k| 5.0 * k as f64).collect(),
            super::model::Axis5::A => (-22..=22).map(|k| 5.0 * k as f64).collect(),
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
    /// How the linear model entered the rotary fit.
    pub linear_input: LinearInput,
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
    /// Grid, compensated with linear and rotary models, scored against the
    /// true tool-tip error (no reading noise on the scored poses): the
    /// figure the targets are compared with.
    pub grid_true: Figures,
    /// The same against the "measured" error (truth + σ per direction, as
    /// a check with a real instrument would see it; before this field the
    /// only one).
    pub grid: Figures,
    /// Grid: compensated with the linear (14-line) model only (measured).
    pub grid_linear_only: Figures,
    /// With drift and bias states: the location constants re-optimised on
    /// tool-tip readings at other states (`bias`), true and measured.
    pub grid_bias_true: Option<Figures>,
    pub grid_bias: Option<Figures>,
    /// With the bias step: worst location error at the held-out states
    /// (µm, µrad).
    pub worst_bias: Option<(f64, f64)>,
    /// Joint fit: what it did to the linear model.
    pub joint: Option<super::joint::JointLinear>,
    /// The harmonic orders fitted, C then A (the simulator's own 3 and 2,
    /// or those the evidence chose with `CaseOptions::auto_orders`).
    pub orders: [usize; 2],
}

/// How the rotary fit takes the linear axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearInput {
    /// The true linear errors (isolates the rotary fit).
    Known,
    /// The 14-line model as known input (its error aliases into the rotary terms).
    Fixed,
    /// The 14 lines and the R-test files in one fit (`joint`); the
    /// compensation then uses the corrected linear model.
    Joint,
}

/// The linear machine of a case.
pub struct LinearCase {
    pub structure: Structure,
    /// Truth in the 14-line reference convention.
    pub truth: GeometricErrors,
    pub identification: Identification,
    /// The averaged lines it was identified from.
    pub lines: Vec<LineObs>,
}

/// The linear machine of a case: truth in the 14-line reference convention
/// and its identification from simulated lines (σ = `noise_um`).
pub fn linear_case(
    stroke: [f64; 3],
    noise_um: f64,
    rng: &mut Rng,
) -> Result<(Structure, GeometricErrors, GeometricErrors)> {
    let c = linear_case_full(stroke, noise_um, rng)?;
    Ok((c.structure, c.truth, c.identification.errors))
}

/// `linear_case` with the identification and its lines.
pub fn linear_case_full(stroke: [f64; 3], noise_um: f64, rng: &mut Rng) -> Result<LinearCase> {
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
    let lines: Vec<LineObs> = average_runs(&files)?.into_iter().map(|a| a.obs).collect();
    let identification = identify(&st, &lines, Degrees::default(), stroke)?;
    Ok(LinearCase {
        structure: st,
        truth,
        identification,
        lines,
    })
}

/// Stroke of the simulated machine: the plan's R-test poses stay inside it.
pub const CASE_STROKE: [f64; 3] = [800.0, 700.0, 600.0];

/// What one simulated machine goes through.
#[derive(Clone, Copy, Debug)]
pub struct CaseOptions {
    pub noise_um: f64,
    /// Drift over a warm-up of this many cycles (0: none), fitted with
    /// every sensor; the grid then at four held-out states of the cool-down.
    pub thermal_cycles: usize,
    pub linear: LinearInput,
    /// With drift: tool-tip readings at this many other states of the
    /// cool-down (0.25 h, 1.5 h, 4 h, 6 h … after the stop) for the bias step.
    pub bias_states: usize,
    /// Choose the harmonic orders by the evidence (`orders`, the CLI's
    /// default) instead of fitting the simulator's own (C 3, A 2).
    pub auto_orders: bool,
}

impl Default for CaseOptions {
    fn default() -> Self {
        CaseOptions {
            noise_um: 0.5,
            thermal_cycles: 0,
            linear: LinearInput::Joint,
            bias_states: 0,
            auto_orders: false,
        }
    }
}

/// Hours after the warm-up's stop of the held-out states and of the bias
/// step's calibration states (never the same).
pub const HELD_OUT_H: [f64; 4] = [0.5, 1.0, 2.0, 3.0];
pub const BIAS_H: [f64; 4] = [0.25, 1.5, 4.0, 6.0];

fn named(t: Vec<f64>) -> BTreeMap<String, f64> {
    SENSORS.iter().map(|s| s.0.to_string()).zip(t).collect()
}

/// One machine through the whole chain (seed `seed`, `CaseOptions`).
pub fn run_case(seed: u64, o: &CaseOptions) -> Result<CaseFigures> {
    let (noise_um, thermal_cycles) = (o.noise_um, o.thermal_cycles);
    let mut rng = Rng::new(seed);
    let plan = RPlan::default_plan();
    let lc = linear_case_full(CASE_STROKE, noise_um, &mut rng)?;
    let st = &lc.structure;
    let truth = random_rotary(&plan, &RotarySizes::default(), thermal_cycles > 0, &mut rng);
    let lt = Linear {
        structure: st,
        errors: &lc.truth,
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
    let mut ro = RotaryOptions {
        sensors,
        ..Default::default()
    };
    if o.auto_orders {
        let noise = crate::adequacy::StatedNoise::new(Some(noise_um))?;
        let trial = |r: &RotaryOptions| fit(&files, &lc, lt, o.linear, r).map(|f| f.0);
        ro = choose_orders(trial, &ro, Order::Auto, Order::Auto, noise)?.0;
    }
    let (id, lin_model) = fit(&files, &lc, lt, o.linear, &ro)?;
    let li = Linear {
        structure: st,
        errors: &lin_model,
    };
    let end = setup.cycle_period_s * thermal_cycles as f64;
    let states: Vec<BTreeMap<String, f64>> = if thermal_cycles > 0 {
        HELD_OUT_H
            .iter()
            .map(|h| named(warmup_temps(end + h * 3600.0, Some(end))))
            .collect()
    } else {
        vec![BTreeMap::new()]
    };
    let biased = if thermal_cycles > 0 && o.bias_states > 0 {
        let cal = bias_readings(&truth, lt, end, o, &mut rng)?;
        Some(optimise_rotary_bias(&id.model, Some(li), &cal)?)
    } else {
        None
    };
    let (location_error, worst_um, worst_urad) = location_errors(&truth, &id.model, &states)?;
    let worst_bias = match &biased {
        Some(b) => location_errors(&truth, b, &states).map(|(_, u, r)| Some((u, r)))?,
        None => None,
    };
    let (component_rms_um, component_rms_urad) = component_groups(&id.model, &truth);
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
    let mut sets: [Vec<Compared>; 5] = Default::default();
    for (k, temps) in states.iter().enumerate() {
        let state = format!("S{k}");
        let m5 = |r| Machine5 {
            rotary: r,
            linear: Some(li),
        };
        // one noise stream per state: the same draws with and without the bias step
        let state_rng = || Rng::new(seed.wrapping_mul(7919).wrapping_add(k as u64));
        let mut quiet = Rng::new(0);
        sets[0].extend(compare(
            &tm,
            &m5(&id.model),
            &poses,
            temps,
            0.0,
            &state,
            &mut quiet,
        )?);
        sets[1].extend(compare(
            &tm,
            &m5(&id.model),
            &poses,
            temps,
            noise_um,
            &state,
            &mut state_rng(),
        )?);
        sets[2].extend(compare(
            &tm,
            &m5(&none),
            &poses,
            temps,
            noise_um,
            &state,
            &mut rng,
        )?);
        if let Some(b) = &biased {
            sets[3].extend(compare(
                &tm,
                &m5(b),
                &poses,
                temps,
                0.0,
                &state,
                &mut quiet,
            )?);
            sets[4].extend(compare(
                &tm,
                &m5(b),
                &poses,
                temps,
                noise_um,
                &state,
                &mut state_rng(),
            )?);
        }
    }
    let fig = |v: &Vec<Compared>| figures(&v.iter().collect::<Vec<_>>());
    Ok(CaseFigures {
        seed,
        linear_input: o.linear,
        worst_um,
        worst_urad,
        location_error,
        component_rms_um,
        component_rms_urad,
        condition_number: id.condition_number,
        unobservable: id.unobservable_terms.clone(),
        grid_true: fig(&sets[0]),
        grid: fig(&sets[1]),
        grid_linear_only: fig(&sets[2]),
        grid_bias_true: biased.as_ref().map(|_| fig(&sets[3])),
        grid_bias: biased.as_ref().map(|_| fig(&sets[4])),
        worst_bias,
        joint: id.linear.clone(),
        orders: [ro.order_c, ro.order_a],
    })
}

/// The rotary fit with the linear axes taken as `how` says; the linear
/// model the compensation then uses.
fn fit(
    files: &[RTestFile],
    lc: &LinearCase,
    lt: Linear,
    how: LinearInput,
    ro: &RotaryOptions,
) -> Result<(super::identify::RotaryIdentification, GeometricErrors)> {
    let st = &lc.structure;
    Ok(match how {
        LinearInput::Known => (identify_rotary(files, Some(lt), ro)?, lc.truth.clone()),
        LinearInput::Fixed => {
            let li = Linear {
                structure: st,
                errors: &lc.identification.errors,
            };
            (
                identify_rotary(files, Some(li), ro)?,
                lc.identification.errors.clone(),
            )
        }
        LinearInput::Joint => {
            let prior = LinearPrior {
                structure: st,
                identification: &lc.identification,
                lines: &lc.lines,
            };
            identify_rotary_joint(files, &prior, ro)?
        }
    })
}

/// Tool-tip readings of the truth at `o.bias_states` states of the
/// cool-down after the warm-up that ended at `end` s (`BIAS_H`).
fn bias_readings(
    truth: &RotaryModel,
    lt: Linear,
    end: f64,
    o: &CaseOptions,
    rng: &mut Rng,
) -> Result<Vec<super::bias::RotaryCalibrationState>> {
    let poses = calibration_poses(CASE_STROKE);
    (0..o.bias_states)
        .map(|k| {
            let h = BIAS_H.get(k).copied().unwrap_or(6.0 + 2.0 * k as f64);
            let temps = named(warmup_temps(end + h * 3600.0, Some(end)));
            simulate_state(truth, Some(lt), &temps, &poses, o.noise_um, rng)
        })
        .collect()
}

/// RMS over the component errors of identified − true and of the truth,
/// for the µm group and the µrad group.
fn component_groups(model: &RotaryModel, truth: &RotaryModel) -> ((f64, f64), (f64, f64)) {
    let rec = component_recovery(model, truth);
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
    (group(false), group(true))
}

/// Worst |identified − true| per location error over `states`, and the
/// worst offset [µm] and tilt [µrad].
pub fn location_errors(
    truth: &RotaryModel,
    model: &RotaryModel,
    states: &[BTreeMap<String, f64>],
) -> Result<(BTreeMap<String, f64>, f64, f64)> {
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    for temps in states {
        let (t, m) = (
            truth.location_at(temps)?.to_array(),
            model.location_at(temps)?.to_array(),
        );
        for k in 0..8 {
            let e = out.entry(LOCATION_NAMES[k].to_string()).or_insert(0.0);
            *e = e.max((t[k] - m[k]).abs());
        }
    }
    let worst = |names: &[&str]| names.iter().map(|n| out[*n]).fold(0.0, f64::max);
    let (um, urad) = (
        worst(&["XOC", "YOC", "YOA", "ZOA"]),
        worst(&["AOC", "BOC", "BOA", "COA"]),
    );
    Ok((out, um, urad))
}

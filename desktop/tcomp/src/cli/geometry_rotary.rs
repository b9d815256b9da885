//! `tcomp geometry sim-rotary | plan-rotary | identify-rotary | check-rotary`:
//! the rotary axes of a table-tilting XYZ-A-C machine from R-test files
//! (docs/formats/rtest.md, docs/geometry.md "Rotary axes").

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::PathBuf;

use super::geometry_adequacy::{inadequate_warning, print_adequacy, refuse_inadequate};
use super::geometry_rotary_linear::{fit_rotary, linear_input, LinearIn};
use tcomp_geometry::check::figures;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::rotary::bias::{calibration_poses, optimise_rotary_bias, simulate_state};
use tcomp_geometry::rotary::check::{compare, grid, linear_case, Machine5, CASE_STROKE};
use tcomp_geometry::rotary::identify::{identify_rotary, RotaryIdentification, RotaryOptions};
use tcomp_geometry::rotary::orders::{choose_orders, Order, OrderChoice};
use tcomp_geometry::rotary::sim::{random_rotary, simulate, CycleSetup, RPlan, RotarySizes};
use tcomp_geometry::rotary::{Linear, RotaryModel};
use tcomp_geometry::rtest::RTestFile;
use tcomp_geometry::study::ErrorsJson;
use tcomp_numerics::rng::Rng;

#[derive(clap::Args, Debug)]
pub struct SimRotaryArgs {
    /// Output directory (R-test files, rotary-truth.json; with --lines also
    /// lines/ with the 14 line files and errors.json of the linear axes).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Reading noise (standard deviation, every reading incl. the zeroing row) [µm].
    #[arg(long, default_value_t = 0.5)]
    pub noise_um: f64,
    /// Drift the location errors with three sensors over a warm-up: this
    /// many cycles (one file each, the nest moved in turn); 0: one cold
    /// cycle per nest.
    #[arg(long, default_value_t = 0)]
    pub thermal_cycles: usize,
    /// Give the machine random linear errors too and write their 14 lines.
    #[arg(long)]
    pub lines: bool,
    /// Tilt the spindle relative to the linear axes' frame: about x and y
    /// [µrad], e.g. 20,-15 (the R-test files see it only through their
    /// tool lengths).
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
    pub spindle_tilt_urad: Option<String>,
    /// Measure every nest with each of these tool lengths [mm] instead of
    /// the plan's one tool per nest, e.g. 100,200.
    #[arg(long, value_name = "L,…")]
    pub tools_mm: Option<String>,
}

/// `a,b,…` as finite numbers (`what` names the flag in the error).
fn numbers(s: &str, what: &str) -> Result<Vec<f64>> {
    s.split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| anyhow::anyhow!("{what}: `{}` is not a number", v.trim()))
        })
        .collect()
}

#[derive(clap::Args, Debug)]
pub struct PlanRotaryArgs {
    /// Harmonics of C's and A's component errors the plan must separate.
    #[arg(long, default_value_t = 3)]
    pub order_c: usize,
    #[arg(long, default_value_t = 2)]
    pub order_a: usize,
    /// Use only the first N nest positions (to see what fewer cannot do).
    #[arg(long)]
    pub nests: Option<usize>,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct IdentifyRotaryArgs {
    /// R-test files of one turntable.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// The linear axes: the 14 line files (fitted together with the R-test
    /// files: the linear model's own error then does not alias into the
    /// rotary terms) or an errors JSON (`geometry identify --json`,
    /// `simulate`'s errors.json), taken as known input.
    #[arg(long, num_args = 1..)]
    pub lines: Vec<PathBuf>,
    /// With line files: take their 14-line model as known input instead of
    /// fitting the lines and the R-test files together.
    #[arg(long)]
    pub linear_fixed: bool,
    /// With line files (joint fit): write the corrected linear model here
    /// (errors JSON, for `geometry table` and the export).
    #[arg(long)]
    pub linear_out: Option<PathBuf>,
    /// Harmonics of C's error motions: `auto` (chosen by the evidence of
    /// the fit at the stated noise, orders 0–6 tried) or a number 0–6.
    #[arg(long, default_value = "auto")]
    pub order_c: Order,
    /// Harmonics of A's error motions: `auto` or a number 0–6.
    #[arg(long, default_value = "auto")]
    pub order_a: Order,
    /// Fit each location error's drift with these sensors (comma-separated
    /// names without T_, or `all` for every T_ column of the files).
    #[arg(long)]
    pub drift: Option<String>,
    /// Exit 0 even when a location error is unobservable (it is then
    /// listed, and has no value).
    #[arg(long)]
    pub partial: bool,
    /// Write the identified model (JSON) here.
    #[arg(long)]
    pub model_out: Option<PathBuf>,
    /// Noise of one R-test reading [µm] for the adequacy test (default:
    /// the documented 0.5 µm, said so in the report).
    #[arg(long)]
    pub noise_um: Option<f64>,
    /// Write the model even when it fails the adequacy test (marked
    /// `"adequate": false`, σ's inflated by the misfit).
    #[arg(long)]
    pub accept_inadequate: bool,
    /// A true model (sim-rotary's rotary-truth.json): print the recovery.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct CheckRotaryArgs {
    /// The machine (sim-rotary's rotary-truth.json).
    #[arg(long)]
    pub truth: PathBuf,
    /// The compensation's model (identify-rotary --model-out).
    #[arg(long)]
    pub model: PathBuf,
    /// Linear errors of the machine and of the model (errors JSON); both or neither.
    #[arg(long, requires = "lines_model")]
    pub lines_truth: Option<PathBuf>,
    #[arg(long, requires = "lines_truth")]
    pub lines_model: Option<PathBuf>,
    /// Sensor temperatures of the scored state, e.g. ctable=24.5,trunnion=22,bed=21.
    #[arg(long)]
    pub temps: Option<String>,
    /// Bias step (seed 001 s21–s22): simulated tool-tip readings of the
    /// truth at these other states (`;`-separated, each as --temps; 160
    /// poses each, σ --noise-um), the model's location constants
    /// re-optimised on them and scored beside the model without it.
    #[arg(long)]
    pub bias_temps: Option<String>,
    #[arg(long, default_value_t = 0.5)]
    pub noise_um: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long)]
    pub json: bool,
}

pub fn sim_rotary_cmd(a: SimRotaryArgs) -> Result<()> {
    if !(a.noise_um >= 0.0 && a.noise_um.is_finite()) {
        bail!("--noise-um must be ≥ 0");
    }
    let mut rng = Rng::new(a.seed);
    let mut plan = RPlan::default_plan();
    if let Some(t) = a.tools_mm.as_deref() {
        let tools = numbers(t, "--tools-mm")?;
        if tools.iter().any(|l| *l < 0.0) {
            bail!("--tools-mm: tool lengths must be ≥ 0 mm");
        }
        let nests: Vec<[f64; 3]> = plan.nests.iter().map(|(n, _)| *n).collect();
        plan.nests = (nests.iter())
            .flat_map(|n| tools.iter().map(move |l| (*n, [0.0, 0.0, *l])))
            .collect();
    }
    let tilt = match a
        .spindle_tilt_urad
        .as_deref()
        .map(|t| numbers(t, "--spindle-tilt-urad"))
    {
        None => None,
        Some(Ok(v)) if v.len() == 2 => Some(v),
        Some(Ok(_)) => bail!("--spindle-tilt-urad: two angles, about x and y (µrad), e.g. 20,-15"),
        Some(Err(e)) => return Err(e),
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let lin = if a.lines {
        let (st, truth, _) = linear_case(CASE_STROKE, a.noise_um, &mut rng)?;
        let dir = a.out.join("lines");
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let setup = tcomp_geometry::sim::MeasurementSetup {
            noise_um: a.noise_um,
            ..Default::default()
        };
        for spec in tcomp_geometry::lines::plan14(CASE_STROKE, 100.0, 100.0) {
            let [f, b] =
                tcomp_geometry::sim::measure_line(&st, &truth, &spec, &setup, None, &mut rng);
            f.write(&dir.join(format!("{}_forward.csv", spec.id)))?;
            b.write(&dir.join(format!("{}_backward.csv", spec.id)))?;
        }
        let ej = ErrorsJson::from_errors(&truth, &st, CASE_STROKE, 11);
        write_json(&a.out.join("errors.json"), &serde_json::to_value(&ej)?)?;
        Some((st, truth))
    } else {
        None
    };
    let mut truth = random_rotary(
        &plan,
        &RotarySizes::default(),
        a.thermal_cycles > 0,
        &mut rng,
    );
    truth.spindle = tilt.map(|v| tcomp_geometry::rotary::Spindle {
        about_x_urad: v[0],
        about_y_urad: v[1],
        reference_tool_mm: [0.0; 3],
    });
    let setup = CycleSetup {
        noise_um: a.noise_um,
        thermal_cycles: a.thermal_cycles,
        ..Default::default()
    };
    let l = lin.as_ref().map(|(st, e)| Linear {
        structure: st,
        errors: e,
    });
    let files = simulate(&truth, l, &plan, &setup, &mut rng)?;
    for f in &files {
        f.write(&a.out.join(&f.name))?;
    }
    write_json(
        &a.out.join("rotary-truth.json"),
        &serde_json::to_value(&truth)?,
    )?;
    println!(
        "wrote {} R-test files{} and rotary-truth.json to {} (noise {} µm, seed {})",
        files.len(),
        if a.lines {
            ", lines/ (14 lines × 2 runs), errors.json"
        } else {
            ""
        },
        a.out.display(),
        a.noise_um,
        a.seed
    );
    Ok(())
}

fn write_json(path: &std::path::Path, v: &serde_json::Value) -> Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(v)?)
        .with_context(|| format!("writing {}", path.display()))
}

pub fn plan_rotary_cmd(a: PlanRotaryArgs) -> Result<()> {
    let mut plan = RPlan::default_plan();
    if let Some(n) = a.nests {
        if n == 0 || n > plan.nests.len() {
            bail!("--nests: 1 to {}", plan.nests.len());
        }
        plan.nests.truncate(n);
    }
    // conditioning: noise-free cycles of an error-free machine give the design
    let m = RotaryModel {
        pivot_a_mm: plan.pivot_a_mm,
        offset_c_mm: plan.offset_c_mm,
        ..Default::default()
    };
    let setup = CycleSetup {
        noise_um: 0.0,
        ..Default::default()
    };
    let files = simulate(&m, None, &plan, &setup, &mut Rng::new(1))?;
    let o = RotaryOptions {
        order_c: a.order_c,
        order_a: a.order_a,
        ..Default::default()
    };
    let id = identify_rotary(&files, None, &o)?;
    if a.json {
        let nests: Vec<_> = plan
            .nests
            .iter()
            .map(|(n, t)| serde_json::json!({"nest_mm": n, "tool_mm": t}))
            .collect();
        println!(
            "{}",
            serde_json::json!({"pivot_a_mm": plan.pivot_a_mm, "offset_c_mm": plan.offset_c_mm, "nests": nests,
                "poses": plan.poses, "unknowns": id.unknowns, "rank": id.rank, "readings": id.readings,
                "condition_number": id.condition_number, "unobservable": id.unobservable})
        );
        return Ok(());
    }
    println!(
        "R-test plan: pivot_a_mm {:?}, offset_c_mm {:?}",
        plan.pivot_a_mm, plan.offset_c_mm
    );
    for (k, (n, t)) in plan.nests.iter().enumerate() {
        println!("  nest N{}: nest_mm {n:?}, tool_mm {t:?}", k + 1);
    }
    println!(
        "  per cycle {} poses: zero at A = C = 0; C every 15° at A = 0; A every 10° over ±110° at C = 0, 90, 180, 270°; C every 45° at A = ±60°; back to zero",
        plan.poses.len()
    );
    print_conditioning(&id);
    Ok(())
}

fn print_conditioning(id: &RotaryIdentification) {
    match id.condition_number {
        Some(c) => println!(
            "  {} unknowns, {} readings, condition number {c:.1}",
            id.unknowns, id.readings
        ),
        None => println!(
            "  {} unknowns, {} readings, rank {} (not all observable)",
            id.unknowns, id.readings, id.rank
        ),
    }
    for u in &id.unobservable {
        println!("  unobservable: {} — {}", u.terms.join(", "), u.why);
    }
}

/// Allowance [µm] for the error of a linear model taken as known input at
/// the R-test positions (combined with the stated noise in quadrature).
const KNOWN_LINEAR_UM: f64 = 0.3;

pub fn identify_rotary_cmd(a: IdentifyRotaryArgs) -> Result<()> {
    let files: Vec<RTestFile> = a
        .files
        .iter()
        .map(|p| RTestFile::read(p))
        .collect::<Result<_>>()?;
    let sensors = match a.drift.as_deref() {
        None => vec![],
        Some("all") => files.first().map(|f| f.sensors.clone()).unwrap_or_default(),
        Some(s) => s
            .split(',')
            .map(|x| x.trim().trim_start_matches("T_").to_string())
            .collect(),
    };
    if a.drift.is_some() && sensors.is_empty() {
        bail!("--drift: the files have no T_ columns");
    }
    let noise = tcomp_geometry::adequacy::StatedNoise::new(a.noise_um)?;
    let lin = linear_input(&a.lines, a.accept_inadequate, noise)?;
    if a.linear_out.is_some() && (a.linear_fixed || !lin.has_lines()) {
        bail!("--linear-out needs the line files as --lines and no --linear-fixed (only the joint fit changes the linear model)");
    }
    // A linear model taken as known input (an errors JSON, --linear-fixed)
    // is not exact: its own error at the R-test positions (a few tenths of
    // a µm from 14 lines at σ 0.5 µm, docs/geometry.md) adds to the
    // readings' noise; the test allows KNOWN_LINEAR_UM for it. The joint
    // fit carries the lines' uncertainty itself.
    let known = matches!(lin, LinearIn::Known(..)) || (a.linear_fixed && !a.lines.is_empty());
    let noise = if known {
        tcomp_geometry::adequacy::StatedNoise {
            um: noise.um.hypot(KNOWN_LINEAR_UM),
            given: noise.given,
        }
    } else {
        noise
    };
    let base = RotaryOptions {
        sensors,
        ..Default::default()
    };
    // the orders (`auto`: by the evidence at the noise the adequacy test states)
    let trial = |o: &RotaryOptions| fit_rotary(&files, &lin, o, a.linear_fixed, None);
    let (o, orders) = choose_orders(trial, &base, a.order_c, a.order_a, noise)?;
    let mut id = fit_rotary(&files, &lin, &o, a.linear_fixed, a.linear_out.as_ref())?;
    id.assess(noise)?;
    let adq = id
        .adequacy
        .clone()
        .ok_or_else(|| anyhow::anyhow!("internal: no adequacy verdict"))?;
    // An unobservable location error is refused below with its reason.
    let location_unobservable = id
        .unobservable_terms
        .iter()
        .any(|t| tcomp_geometry::rotary::LOCATION_NAMES.contains(&t.as_str()));
    if a.partial || !location_unobservable {
        refuse_inadequate(
            &adq,
            a.accept_inadequate,
            &format!("the rotary model of these {} R-test files", files.len()),
            "measure more: more nests, tool lengths and sweeps (`tcomp geometry plan-rotary`), the linear axes with more lines (`tcomp geometry plan`)",
        )?;
    }
    let truth = a.truth.as_ref().map(|p| RotaryModel::read(p)).transpose()?;
    if let Some(p) = &a.model_out {
        write_json(p, &serde_json::to_value(&id.model)?)?;
    }
    if a.json {
        let mut v = serde_json::to_value(&id)?;
        if let Some(o) = v.as_object_mut() {
            o.insert("orders".into(), serde_json::to_value(&orders)?);
            if let Some(t) = &truth {
                o.insert("recovery".into(), recovery_json(&id, t));
            }
        }
        println!("{v}");
    } else {
        print_identification(&id, truth.as_ref(), &orders);
        print_adequacy(&adq);
    }
    if let Some(w) = inadequate_warning(&adq, "rotary model").filter(|_| a.accept_inadequate) {
        eprintln!("warning: {w}");
    }
    let bad: Vec<&String> = id
        .unobservable_terms
        .iter()
        .filter(|t| tcomp_geometry::rotary::LOCATION_NAMES.contains(&t.as_str()))
        .collect();
    if !bad.is_empty() && !a.partial {
        bail!(
            "location errors {} are not observable from these files (see `unobservable`); measure what the reason asks for, or pass --partial to keep the rest",
            bad.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    Ok(())
}

fn recovery_json(id: &RotaryIdentification, t: &RotaryModel) -> serde_json::Value {
    // both relative to the lines' frame, or both apparent at the one tool
    let tl = truth_location(id, t);
    let ml = (id.model)
        .location_for_tool(&id.model.location, [0.0; 3])
        .to_array();
    let loc: BTreeMap<&str, f64> = tcomp_geometry::rotary::LOCATION_NAMES
        .iter()
        .copied()
        .zip((0..8).map(|k| ml[k] - tl[k]))
        .collect();
    let comp: BTreeMap<String, serde_json::Value> =
        tcomp_geometry::rotary::check::component_recovery(&id.model, t)
            .into_iter()
            .map(|(k, (d, s))| (k, serde_json::json!({"rms_error": d, "true_rms": s})))
            .collect();
    let mut v = serde_json::json!({"location_error": loc, "components": comp});
    if let (Some(o), Some(e)) = (v.as_object_mut(), spindle_recovery(id, t)) {
        o.insert("spindle_error_urad".into(), serde_json::json!(e));
    }
    v
}

/// The true location errors as the identification reports them: relative
/// to the lines' frame, or, with the spindle undetermined, as they appear
/// at the files' one tool.
fn truth_location(id: &RotaryIdentification, t: &RotaryModel) -> [f64; 8] {
    let tool = match (&id.model.spindle, id.spindle.tools_mm.as_slice()) {
        (None, [one]) => *one,
        _ => [0.0; 3],
    };
    t.location_for_tool(&t.location, tool).to_array()
}

/// Identified minus true spindle angles [µrad] (a truth without a spindle: zero tilt).
fn spindle_recovery(id: &RotaryIdentification, t: &RotaryModel) -> Option<[f64; 2]> {
    let s = id.model.spindle?;
    let ts = t.spindle.unwrap_or_default();
    Some([
        s.about_x_urad - ts.about_x_urad,
        s.about_y_urad - ts.about_y_urad,
    ])
}

fn print_identification(
    id: &RotaryIdentification,
    truth: Option<&RotaryModel>,
    orders: &[OrderChoice],
) {
    println!(
        "{} files, {} nest positions, residual RMS {:.3} µm",
        id.files, id.nest_positions, id.residual_rms_um
    );
    print_conditioning(id);
    print_orders(orders);
    if let Some(j) = id.linear.as_ref().filter(|j| j.linear_model == "generic") {
        println!(
            "  linear axes: the lines' generic model (no shape assumed) fitted with the R-test files, its posterior as prior ({} modes; condition number of the whole {:.0}): noise {:.3} µm (lines), {:.3} µm (R-test); its prediction at the R-test readings moved {:.3} µm RMS; lines' residual {:.3} → {:.3} µm",
            j.linear_unknowns, j.joint_condition_number.unwrap_or(f64::INFINITY), j.sigma_lines_um, j.sigma_rtest_um, j.change_at_rtest_rms_um, j.line_residual_rms_um_before, j.line_residual_rms_um
        );
    } else if let Some(j) = &id.linear {
        println!(
            "  linear axes fitted with the lines ({} of the unknowns, {} of the readings; condition number of the whole {:.0}): noise {:.3} µm (lines), {:.3} µm (R-test); their prediction at the R-test readings moved {:.3} µm RMS; lines' residual {:.3} → {:.3} µm",
            j.linear_unknowns, j.line_readings, j.joint_condition_number.unwrap_or(f64::INFINITY), j.sigma_lines_um, j.sigma_rtest_um, j.change_at_rtest_rms_um, j.line_residual_rms_um_before, j.line_residual_rms_um
        );
    }
    let tl = truth.map(|t| truth_location(id, t));
    print_spindle(id, truth);
    println!(
        "  location errors (± 1σ){}:",
        if id.model.spindle.is_some() {
            ", relative to the lines' frame"
        } else {
            ""
        }
    );
    for (k, t) in id.location.iter().enumerate() {
        let rec = tl
            .map(|v| format!("   truth {:8.3}", v[k]))
            .unwrap_or_default();
        match (t.value, t.sigma) {
            (Some(v), Some(s)) => println!("    {} {v:9.3} ± {s:.3} {}{rec}", t.name, t.unit),
            _ => println!("    {} unobservable{rec}", t.name),
        }
    }
    if !id.drift.is_empty() {
        println!("  drift (± 1σ):");
        for t in &id.drift {
            match (t.value, t.sigma) {
                (Some(v), Some(s)) => println!("    {} {v:8.3} ± {s:.3} {}", t.name, t.unit),
                _ => println!("    {} unobservable", t.name),
            }
        }
    }
    println!("  component errors (Fourier a_k(cos kθ − 1) + b_k sin kθ, ± 1σ):");
    for t in &id.components {
        match (t.value, t.sigma) {
            (Some(v), Some(s)) => println!("    {:32} {v:8.3} ± {s:.3} {}", t.name, t.unit),
            _ => println!("    {:32} unobservable", t.name),
        }
    }
}

/// Each axis's harmonic order and, when the evidence chose it, the ln
/// evidence of every candidate relative to order 0.
fn print_orders(orders: &[OrderChoice]) {
    for c in orders {
        if c.candidates.is_empty() {
            println!("  harmonic order of {}: {} (given)", c.axis, c.order);
            continue;
        }
        let ev: Vec<String> = (c.candidates.iter())
            .map(|k| {
                let mark = if k.order == c.order { "*" } else { "" };
                format!("{} {:.1}{mark}", k.order, k.ln_evidence)
            })
            .collect();
        println!(
            "  harmonic order of {}: {} by the evidence (ln evidence vs order 0 at the stated noise: {})",
            c.axis,
            c.order,
            ev.join(", ")
        );
    }
}

/// The spindle's direction, or why it is undetermined.
fn print_spindle(id: &RotaryIdentification, truth: Option<&RotaryModel>) {
    let s = &id.spindle;
    match s.status.as_str() {
        "identified" => {
            let ts = truth.map(|t| t.spindle.unwrap_or_default());
            println!(
                "  spindle direction relative to the lines' frame (± 1σ; {} tools):",
                s.tools_mm.len()
            );
            for (k, t) in s.angles.iter().enumerate() {
                let rec = ts
                    .map(|ts| format!("   truth {:8.3}", [ts.about_x_urad, ts.about_y_urad][k]))
                    .unwrap_or_default();
                if let (Some(v), Some(sg)) = (t.value, t.sigma) {
                    println!("    {} {v:9.3} ± {sg:.3} {}{rec}", t.name, t.unit);
                }
            }
            println!("    {}", s.why);
        }
        _ => println!("  spindle direction {}: {}", s.status, s.why),
    }
}

fn parse_temps(s: &str) -> Result<BTreeMap<String, f64>> {
    s.split(',')
        .map(|kv| {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| anyhow::anyhow!("--temps: `{kv}` is not name=°C"))?;
            let t: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| anyhow::anyhow!("--temps: `{v}` is not a number"))?;
            Ok((k.trim().trim_start_matches("T_").to_string(), t))
        })
        .collect()
}

pub fn check_rotary_cmd(a: CheckRotaryArgs) -> Result<()> {
    if !(a.noise_um >= 0.0 && a.noise_um.is_finite()) {
        bail!("--noise-um must be ≥ 0");
    }
    let truth = RotaryModel::read(&a.truth)?;
    let model = RotaryModel::read(&a.model)?;
    if !model.unobservable.is_empty() {
        bail!(
            "{}: the model has unobservable terms ({}); it cannot compensate",
            a.model.display(),
            model.unobservable.join(", ")
        );
    }
    let temps = a
        .temps
        .as_deref()
        .map(parse_temps)
        .transpose()?
        .unwrap_or_default();
    let read = |p: &Option<PathBuf>| -> Result<Option<(Structure, tcomp_geometry::GeometricErrors, [f64; 3])>> {
        p.as_ref()
            .map(|p| {
                let ej = ErrorsJson::read(p)?;
                Ok((Structure::parse(&ej.structure)?, ej.to_errors()?, ej.stroke_mm))
            })
            .transpose()
    };
    let (lt, lm) = (read(&a.lines_truth)?, read(&a.lines_model)?);
    let stroke = lt.as_ref().map_or(CASE_STROKE, |l| l.2);
    let poses = grid(stroke);
    let t5 = Machine5 {
        rotary: &truth,
        linear: lt.as_ref().map(|(s, e, _)| Linear {
            structure: s,
            errors: e,
        }),
    };
    let m5 = Machine5 {
        rotary: &model,
        linear: lm.as_ref().map(|(s, e, _)| Linear {
            structure: s,
            errors: e,
        }),
    };
    let fig = |m: &Machine5, noise: f64| -> Result<tcomp_geometry::check::Figures> {
        // the same noise draws for every model scored
        let pts = compare(
            &t5,
            m,
            &poses,
            &temps,
            noise,
            "check",
            &mut Rng::new(a.seed),
        )?;
        Ok(figures(&pts.iter().collect::<Vec<_>>()))
    };
    let (f, ft) = (fig(&m5, a.noise_um)?, fig(&m5, 0.0)?);
    let bias = match a.bias_temps.as_deref() {
        None => None,
        Some(list) => {
            let mut rng = Rng::new(a.seed.wrapping_add(1));
            let poses = calibration_poses(stroke);
            let mut cal = Vec::new();
            for st in list.split(';').filter(|x| !x.trim().is_empty()) {
                let temps = parse_temps(st)?;
                cal.push(simulate_state(
                    &truth, t5.linear, &temps, &poses, a.noise_um, &mut rng,
                )?);
            }
            if cal.is_empty() {
                bail!("--bias-temps: no state given");
            }
            let b = optimise_rotary_bias(&model, m5.linear, &cal)?;
            let mb = Machine5 {
                rotary: &b,
                linear: m5.linear,
            };
            Some((fig(&mb, a.noise_um)?, fig(&mb, 0.0)?, cal.len()))
        }
    };
    if a.json {
        let mut v = serde_json::json!({"grid": f, "grid_true": ft, "temps_c": temps});
        if let (Some((b, bt, n)), Some(o)) = (&bias, v.as_object_mut()) {
            o.insert("bias_states".into(), (*n).into());
            o.insert("grid_bias".into(), serde_json::to_value(b)?);
            o.insert("grid_bias_true".into(), serde_json::to_value(bt)?);
        }
        println!("{v}");
    } else {
        println!(
            "five-axis grid ({} poses: 27 positions × A −90…90° every 30° × C 0…315° every 45° × 2 tools): tool-tip RMS {:.2} µm before, {:.2} µm after ({:.1} % less) against the true error; against the measured one (σ {} µm per direction) {:.2} → {:.2} µm ({:.1} % less), max {:.2} → {:.2} µm",
            ft.points, ft.before_rms_um, ft.after_rms_um, ft.reduction_pct, a.noise_um,
            f.before_rms_um, f.after_rms_um, f.reduction_pct, f.before_max_um, f.after_max_um
        );
        if let Some((b, bt, n)) = &bias {
            println!(
                "  with the location constants re-optimised on tool-tip readings at {n} other state(s): {:.2} µm after ({:.1} % less) true, {:.2} µm ({:.1} %) measured",
                bt.after_rms_um, bt.reduction_pct, b.after_rms_um, b.reduction_pct
            );
        }
    }
    Ok(())
}

//! `tcomp geometry`: the subcommands and their dispatch, the arguments the
//! three-axis commands share (volume, degrees), and simulate, plan and
//! fit-thermal. Each other command lives in a `geometry_*` file of its own
//! (identify's poly model in `geometry_identify`, smooth and dense in
//! `geometry_smooth`, the rotary axes in `geometry_rotary`); none imports
//! this file.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::PathBuf;

use super::geometry_check::{check_cmd, CheckArgs};
use super::geometry_generic::{default_method, identify_generic_cmd, nulls_clause, GenericRequest};
use super::geometry_identify::{
    combination_text, condition_json, condition_text, identify_poly_cmd, PolyRequest,
};
use super::geometry_plan::{criterion, line_json, line_words, plan_lines, print_criterion};
use super::geometry_predict::{predict_cmd, PredictArgs};
use super::geometry_rotary::{
    check_rotary_cmd, identify_rotary_cmd, plan_rotary_cmd, sim_rotary_cmd, CheckRotaryArgs,
    IdentifyRotaryArgs, PlanRotaryArgs, SimRotaryArgs,
};
use super::geometry_score::{score_cmd, ScoreArgs};
use super::geometry_smooth::{identify_smooth_cmd, SmoothRequest};
use super::geometry_table::{
    parse_triple, table_cmd, table_json, tooltip_cmd, TableArgs, TooltipArgs,
};
use tcomp_geometry::identify::{identify, Degrees, LineKind, LineObs};
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::{average_runs, LineFile};
use tcomp_geometry::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp_geometry::study::ErrorsJson;
use tcomp_numerics::rng::Rng;

#[derive(clap::Args, Debug)]
pub struct GeometryArgs {
    #[command(subcommand)]
    pub command: GeometryCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum GeometryCommand {
    /// Write the line files of a plan (forward and backward runs; --plan 14,
    /// rich or rich-optics) of a machine with random smooth errors (or the errors of
    /// --errors), and its errors as JSON.
    #[command(alias = "sim")]
    Simulate(SimulateArgs),
    /// Identify the 21 errors from line files; prints the error functions,
    /// the conditioning and what the lines cannot see.
    Identify(IdentifyArgs),
    /// Print a line plan (--plan 14, rich or rich-optics) for a working volume, its
    /// conditioning and the stated criterion (worst-term posterior σ, null
    /// directions).
    Plan(PlanArgs),
    /// Temperature dependence: per error coefficient a linear function of
    /// sensor temperatures, fitted from lines at several temperature states;
    /// each state held out in turn.
    FitThermal(FitThermalArgs),
    /// Volumetric check: predicted against measured (simulated, with noise)
    /// tool-tip error over a held-out grid, before and after compensation;
    /// from error files, or a whole simulated thermal check (--thermal-sim).
    Check(CheckArgs),
    /// Tool-tip error at one position of a three- or five-axis machine
    /// (exact and first-order), in the workpiece frame.
    Tooltip(TooltipArgs),
    /// The model's tool-tip error at your own poses (a CSV: x, y, z, a, c,
    /// tool, T_…), and with --image what the board serves there (bit-exact).
    #[command(after_help = super::geometry_predict::EXAMPLE)]
    Predict(PredictArgs),
    /// The volumetric correction polynomial the board will evaluate
    /// (positions, tool length): its terms, size and fit to the kinematics.
    Table(TableArgs),
    /// Score a model against a tabulated machine and held-out lines (issue 29).
    Score(ScoreArgs),
    /// Write R-test files (docs/formats/rtest.md) of a five-axis machine
    /// with random location and component errors (and their drift).
    SimRotary(SimRotaryArgs),
    /// The R-test poses (nests, tools, A and C sweeps) and their conditioning.
    PlanRotary(PlanRotaryArgs),
    /// Identify the eight location errors together with the component
    /// errors from R-test files; prints uncertainties and what is unobservable.
    IdentifyRotary(IdentifyRotaryArgs),
    /// Five-axis check: tool-tip error over positions × A × C before and
    /// after compensation with a rotary model.
    CheckRotary(CheckRotaryArgs),
}

#[derive(clap::Args, Debug)]
pub struct FitThermalArgs {
    /// Line files with `temperature_state` metadata and `T_` columns.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    #[command(flatten)]
    pub degrees: DegreeArgs,
    /// Sensors to use, e.g. xscrew,column (default: every T_ column).
    #[arg(long)]
    pub sensors: Option<String>,
    #[arg(long)]
    pub stroke: Option<String>,
    /// Also write the board's volumetric polynomial with its per-kelvin
    /// terms (the JSON `geometry table --json` writes; `export --geometry` reads it).
    #[arg(long)]
    pub table: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct VolumeArgs {
    /// Working volume X,Y,Z [mm] (the lines run in [0,X]×[0,Y]×[0,Z]).
    #[arg(long, default_value = "800,500,400")]
    pub stroke: String,
    /// Reflector length below the spindle gauge point [mm].
    #[arg(long, default_value_t = 100.0)]
    pub tool: f64,
    /// Lateral reflector offset on the lines that need one [mm].
    #[arg(long, default_value_t = 100.0)]
    pub side: f64,
}

#[derive(clap::Args, Debug)]
pub struct DegreeArgs {
    /// Polynomial degree of positioning, pitch and yaw.
    #[arg(long, default_value_t = Degrees::default().main)]
    pub degree: usize,
    /// Degree of the straightness errors (2 = one bow beyond the squareness line).
    #[arg(long, default_value_t = Degrees::default().straightness)]
    pub straightness_degree: usize,
    /// Degree of the roll errors EAX, EBY, ECZ.
    #[arg(long, default_value_t = Degrees::default().roll)]
    pub roll_degree: usize,
}

impl DegreeArgs {
    fn degrees(&self) -> Result<Degrees> {
        if self.degree < 1 || self.roll_degree < 1 || self.straightness_degree < 2 {
            bail!("degrees: --degree and --roll-degree must be ≥ 1, --straightness-degree ≥ 2");
        }
        if self
            .degree
            .max(self.roll_degree)
            .max(self.straightness_degree)
            > 8
        {
            bail!("degrees above 8 are not supported (the lines cannot carry them)");
        }
        Ok(Degrees {
            main: self.degree,
            straightness: self.straightness_degree,
            roll: self.roll_degree,
        })
    }
}

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Degrees of the random error polynomials.
    #[command(flatten)]
    pub degrees: DegreeArgs,
    #[arg(long, default_value = "XY/Z")]
    pub structure: String,
    /// Which lines: `14` (today's plan), `rich` (the recommended 28 lines
    /// that pin the machine down; `geometry plan --plan rich`) or
    /// `rich-optics` (rich with one straightness-optics line).
    #[arg(long, default_value = "14")]
    pub plan: String,
    /// Errors to simulate (JSON as written by simulate or identify) instead of random ones.
    #[arg(long)]
    pub errors: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Reading noise (standard deviation) [µm].
    #[arg(long, default_value_t = 0.5)]
    pub noise_um: f64,
    /// Beam misalignment (standard deviation per tilt angle) [µrad].
    #[arg(long, default_value_t = 200.0)]
    pub misalign_urad: f64,
    /// Reflector position error (standard deviation per coordinate) [mm].
    #[arg(long, default_value_t = 1.0)]
    pub reflector_mm: f64,
    /// Lost motion of X,Y,Z [µm] (backward minus forward run).
    #[arg(long, default_value = "3,2,4")]
    pub reversal_um: String,
    /// Targets per line, ends included.
    #[arg(long, default_value_t = 41)]
    pub targets: usize,
    /// Temperature states to simulate (0: one state, no temperatures). With
    /// N > 0 the machine's errors change with three sensors (T_xscrew,
    /// T_column, T_bed) and files are named S1_L01_forward.csv ….
    #[arg(long, default_value_t = 0)]
    pub states: usize,
    /// Output directory (created): L01_forward.csv … L14_backward.csv (…
    /// L28 with --plan rich), errors.json.
    #[arg(short, long)]
    pub out: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct IdentifyArgs {
    /// Line files (forward/backward runs of a line are averaged).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    #[command(flatten)]
    pub degrees: DegreeArgs,
    /// Axis strokes X,Y,Z [mm] (default: the range the lines cover).
    #[arg(long)]
    pub stroke: Option<String>,
    /// Tabulate the functions at this many positions per axis.
    #[arg(long, default_value_t = 11)]
    pub points: usize,
    /// Errors of the simulated machine: adds the recovery error per term.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// When the lines do not determine every error: write the model anyway,
    /// the undetermined errors listed under `unobservable_terms`.
    #[arg(long)]
    pub partial: bool,
    /// `generic`: no shape assumed (Legendre degree 16 per error, prior
    /// sizes and the lines' laser scale chosen by the evidence; issue 49),
    /// the default when the lines determine the machine (≥ 18 lines, no
    /// null direction); `poly`: the polynomial model of the degree options,
    /// the default otherwise; `smooth`: degree-10 Legendre (issue 29);
    /// `dense`: values per node with a roughness prior chosen from the data.
    #[arg(long)]
    pub method: Option<String>,
    /// `--method dense`: values per error function (both ends included).
    #[arg(long, default_value_t = tcomp_geometry::dense::DEFAULT_NODES)]
    pub nodes: usize,
    /// Noise of one reading of one run [µm] for the adequacy test
    /// (default: the documented 0.5 µm, said so in the report).
    #[arg(long)]
    pub noise_um: Option<f64>,
    /// Write the model even when it fails the adequacy test (marked
    /// `"adequate": false`, σ's inflated by the misfit).
    #[arg(long)]
    pub accept_inadequate: bool,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct PlanArgs {
    #[command(flatten)]
    pub volume: VolumeArgs,
    #[command(flatten)]
    pub degrees: DegreeArgs,
    #[arg(long, default_value = "XY/Z")]
    pub structure: String,
    /// Which lines: `14` (today's plan), `rich` (the recommended 28
    /// displacement-only lines, no null direction) or `rich-optics` (rich
    /// with one line exchanged for a straightness-optics line).
    #[arg(long, default_value = "14")]
    pub plan: String,
    /// Noise of one reading of one run [µm] the criterion is computed for.
    #[arg(long, default_value_t = 0.5)]
    pub noise_um: f64,
    #[arg(long)]
    pub json: bool,
}

fn stroke_of(v: &VolumeArgs) -> Result<[f64; 3]> {
    let s = parse_triple(&v.stroke, "--stroke")?;
    if s.iter().any(|x| !(*x > 0.0)) {
        bail!("--stroke: every axis stroke must be positive");
    }
    Ok(s)
}

pub fn main(a: GeometryArgs) -> Result<()> {
    match a.command {
        GeometryCommand::Simulate(s) => simulate(s),
        GeometryCommand::Identify(i) => identify_cmd(i),
        GeometryCommand::Plan(p) => plan_cmd(p),
        GeometryCommand::FitThermal(f) => fit_thermal_cmd(f),
        GeometryCommand::Check(c) => check_cmd(c),
        GeometryCommand::Tooltip(t) => tooltip_cmd(t),
        GeometryCommand::Predict(p) => predict_cmd(p),
        GeometryCommand::Table(t) => table_cmd(t),
        GeometryCommand::Score(s) => score_cmd(s),
        GeometryCommand::SimRotary(s) => sim_rotary_cmd(s),
        GeometryCommand::PlanRotary(p) => plan_rotary_cmd(p),
        GeometryCommand::IdentifyRotary(i) => identify_rotary_cmd(i),
        GeometryCommand::CheckRotary(c) => check_rotary_cmd(c),
    }
}

fn simulate(a: SimulateArgs) -> Result<()> {
    let stroke = stroke_of(&a.volume)?;
    let st = Structure::parse(&a.structure).context("--structure")?;
    let reversal_um = parse_triple(&a.reversal_um, "--reversal-um")?;
    for (v, what) in [
        (a.noise_um, "--noise-um"),
        (a.misalign_urad, "--misalign-urad"),
        (a.reflector_mm, "--reflector-mm"),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            bail!("{what} must be ≥ 0");
        }
    }
    if a.targets < 3 {
        bail!("--targets must be at least 3");
    }
    let mut rng = Rng::new(a.seed);
    let truth = match &a.errors {
        Some(p) => ErrorsJson::read(p)?.to_errors()?,
        None => random_errors(
            stroke,
            &ErrorSizes {
                degrees: a.degrees.degrees()?,
                ..Default::default()
            },
            &mut rng,
        ),
    };
    let setup = MeasurementSetup {
        noise_um: a.noise_um,
        beam_misalignment_urad: a.misalign_urad,
        reflector_offset_mm: a.reflector_mm,
        reversal_um,
        targets: a.targets,
    };
    let plan = plan_lines(&a.plan, stroke, a.volume.tool, a.volume.side)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    if a.states > 0 {
        let machine = tcomp_geometry::sim::ThermalMachine::random(
            stroke,
            &["xscrew", "column", "bed"],
            &mut rng,
        );
        let mut n = 0;
        for k in 1..=a.states {
            let temps: Vec<f64> = (0..3).map(|_| rng.range(20.0, 32.0)).collect();
            let name = format!("S{k}");
            for f in tcomp_geometry::sim::measure_state(
                &st, &machine, &temps, &name, &plan, &setup, &mut rng,
            ) {
                let run = if f.run == tcomp_geometry::lines::Run::Backward {
                    "backward"
                } else {
                    "forward"
                };
                f.write(&a.out.join(format!("{name}_{}_{run}.csv", f.spec.id)))?;
                n += 1;
            }
        }
        let ej = ErrorsJson::from_errors(&machine.base, &st, stroke, 11);
        let path = a.out.join("errors.json");
        std::fs::write(&path, serde_json::to_string_pretty(&ej)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!(
            "wrote {n} line files of {} temperature states and errors.json (errors at 20 °C) to {}",
            a.states,
            a.out.display()
        );
        return Ok(());
    }
    let mut n = 0;
    for spec in &plan {
        let [f, b] = measure_line(&st, &truth, spec, &setup, None, &mut rng);
        f.write(&a.out.join(format!("{}_forward.csv", spec.id)))?;
        b.write(&a.out.join(format!("{}_backward.csv", spec.id)))?;
        n += 2;
    }
    let ej = ErrorsJson::from_errors(&truth, &st, stroke, 11);
    let path = a.out.join("errors.json");
    std::fs::write(&path, serde_json::to_string_pretty(&ej)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "wrote {n} line files (plan {}, {} lines) and errors.json to {} (noise {} µm, seed {})",
        a.plan,
        plan.len(),
        a.out.display(),
        a.noise_um,
        a.seed
    );
    Ok(())
}

/// `--method` picks the model: poly here, generic in `geometry_generic`,
/// smooth and dense in `geometry_smooth`; without it, generic when the
/// lines determine the machine, else poly (whose refusal then names what
/// no line sees).
fn identify_cmd(a: IdentifyArgs) -> Result<()> {
    let (method, nulls, lines) = match a.method.as_deref() {
        Some(m) => (m, Vec::new(), 0),
        None => default_method(&a.files, a.stroke.as_deref()),
    };
    match method {
        "generic" => identify_generic_cmd(&GenericRequest {
            files: &a.files,
            stroke: a.stroke.as_deref(),
            points: a.points,
            truth: a.truth.as_deref(),
            partial: a.partial,
            noise_um: a.noise_um,
            accept_inadequate: a.accept_inadequate,
            json: a.json,
        }),
        "poly" => identify_poly_cmd(&PolyRequest {
            files: &a.files,
            degrees: a.degrees.degrees()?,
            stroke: a.stroke.as_deref(),
            points: a.points,
            truth: a.truth.as_deref(),
            partial: a.partial,
            noise_um: a.noise_um,
            accept_inadequate: a.accept_inadequate,
            json: a.json,
        })
        .map_err(|e| {
            if nulls.is_empty() {
                e
            } else {
                anyhow::anyhow!("{e}; {}", nulls_clause(lines, &nulls))
            }
        }),
        "smooth" | "dense" => identify_smooth_cmd(&SmoothRequest {
            dense: (method == "dense").then_some(a.nodes),
            files: &a.files,
            stroke: a.stroke.as_deref(),
            points: a.points,
            truth: a.truth.as_deref(),
            partial: a.partial,
            json: a.json,
        }),
        m => bail!("--method {m:?}: generic, poly, smooth or dense"),
    }
}

fn plan_cmd(a: PlanArgs) -> Result<()> {
    let stroke = stroke_of(&a.volume)?;
    let st = Structure::parse(&a.structure).context("--structure")?;
    let degrees = a.degrees.degrees()?;
    let plan = plan_lines(&a.plan, stroke, a.volume.tool, a.volume.side)?;
    let crit = criterion(&st, stroke, &plan, a.noise_um)?;
    // The polynomial model's rank and conditioning: of the displacement
    // lines (it reads no straightness line; the criterion uses them all).
    let obs: Vec<LineObs> = plan
        .iter()
        .filter(|l| l.kind == LineKind::Displacement)
        .map(|l| LineObs {
            id: l.id.clone(),
            direction: l.direction,
            sense: l.sense,
            kind: l.kind,
            tool_offset_mm: l.tool_offset_mm,
            points: l
                .targets(41)
                .into_iter()
                .map(|(_, p)| tcomp_geometry::identify::Observation {
                    pos_mm: p,
                    disp_um: 0.0,
                })
                .collect(),
        })
        .collect();
    let id = identify(&st, &obs, degrees, stroke)?;
    if a.json {
        let lines: Vec<_> = plan.iter().map(line_json).collect();
        println!(
            "{}",
            serde_json::json!({"lines": lines, "unknowns": id.basis.columns.len(), "rank": id.rank,
                "condition_number": condition_json(id.condition_number),
                "unobservable": id.unobservable, "plan": a.plan, "criterion": crit})
        );
        return Ok(());
    }
    for l in &plan {
        println!("{}", line_words(l));
    }
    println!(
        "{} unknowns, rank {}, condition number {}{}",
        id.basis.columns.len(),
        id.rank,
        condition_text(id.condition_number),
        if obs.len() < plan.len() {
            format!(" (polynomial model, its {} displacement lines)", obs.len())
        } else {
            String::new()
        }
    );
    for u in &id.unobservable {
        println!("  not observable: {}", combination_text(&u.combination));
    }
    print_criterion(&a.plan, &crit);
    Ok(())
}

fn fit_thermal_cmd(a: FitThermalArgs) -> Result<()> {
    use tcomp_geometry::thermal::{fit, leave_one_out, sensitivities, State};
    let degrees = a.degrees.degrees()?;
    let files: Vec<LineFile> = a
        .files
        .iter()
        .map(|p| LineFile::read(p))
        .collect::<Result<_>>()?;
    let st = tcomp_geometry::guard::common_structure(&files, &a.files)?;
    let avg = average_runs(&files)?;
    let sensors: Vec<String> = match &a.sensors {
        Some(s) => s
            .split(',')
            .map(|x| x.trim().trim_start_matches("T_").to_string())
            .collect(),
        None => avg[0].temps.iter().map(|(n, _)| n.clone()).collect(),
    };
    if sensors.is_empty() {
        bail!("the line files have no T_ columns; fit-thermal needs sensor temperatures");
    }
    let mut by_state: BTreeMap<String, Vec<&tcomp_geometry::lines::Averaged>> = BTreeMap::new();
    for l in &avg {
        let Some(s) = &l.temperature_state else {
            bail!("line {}: no temperature_state metadata", l.obs.id);
        };
        by_state.entry(s.clone()).or_default().push(l);
    }
    let mut states = Vec::new();
    for (name, lines) in &by_state {
        let mut temps = Vec::new();
        for s in &sensors {
            let v: Vec<f64> = lines
                .iter()
                .map(|l| l.temps.iter().find(|(n, _)| n == s).map(|(_, t)| *t))
                .collect::<Option<_>>()
                .ok_or_else(|| anyhow::anyhow!("state {name}: a line has no T_{s} column"))?;
            temps.push(v.iter().sum::<f64>() / v.len() as f64);
        }
        states.push(State {
            name: name.clone(),
            lines: lines.iter().map(|l| l.obs.clone()).collect(),
            temps,
        });
    }
    let stroke = match &a.stroke {
        Some(s) => parse_triple(s, "--stroke")?,
        None => {
            let mut m = [0.0f64; 3];
            for l in &avg {
                for p in &l.obs.points {
                    for k in 0..3 {
                        m[k] = m[k].max(p.pos_mm[k].abs());
                    }
                }
            }
            m
        }
    };
    let model = fit(&st, &states, &sensors, degrees, stroke)?;
    let held = leave_one_out(&st, &states, &sensors, degrees, stroke)?;
    let sens = sensitivities(&model);
    let table = match &a.table {
        Some(path) => {
            let errors = model.errors_at(&model.t_ref);
            let p = tcomp_geometry::volumetric::build(&st, stroke, &errors, Some(&model))?;
            std::fs::write(path, table_json(&p)?.to_string())
                .with_context(|| format!("writing {}", path.display()))?;
            Some((
                path.display().to_string(),
                p.terms.len(),
                p.max_fit_error_um,
            ))
        }
        None => None,
    };
    if a.json {
        let s: BTreeMap<_, _> = sens.iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        println!(
            "{}",
            serde_json::json!({"sensors": sensors, "states": states.len(), "t_ref_c": model.t_ref,
                "sensitivity_per_kelvin_at_stroke_end": s, "held_out": held,
                "table": table.as_ref().map(|(path, terms, err)| serde_json::json!(
                    {"path": path, "terms": terms, "max_fit_error_um": err}))})
        );
        return Ok(());
    }
    if let Some((path, terms, err)) = &table {
        println!(
            "wrote {path}: the volumetric polynomial with per-kelvin terms, {terms} terms (largest difference to the first-order kinematics {err:.4} µm)"
        );
    }
    println!(
        "{} states, sensors {}; reference temperatures {:?} °C",
        states.len(),
        sensors.join(", "),
        model
            .t_ref
            .iter()
            .map(|t| (t * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    println!("sensitivity at the end of the stroke per kelvin of each sensor (µm/K or µrad/K):");
    for (n, v) in &sens {
        let s: Vec<String> = v.iter().map(|x| format!("{x:+7.3}")).collect();
        println!("  {n:5} {}", s.join(" "));
    }
    println!("held-out states (fitted without them): line residual RMS, static geometry → with temperature terms (own fit):");
    for h in &held {
        println!(
            "  {}: {:.2} → {:.2} µm ({:.2})",
            h.state, h.static_rms_um, h.thermal_rms_um, h.own_fit_rms_um
        );
    }
    Ok(())
}

//! Issue 50, item 6: how the thermal models hold outside their training
//! envelope. Per case (one channel of one run, fitted on its training part
//! and scored on the served part the fit never saw), MAE and RMS (µm) of:
//!
//! - `default`: exactly what `tcomp fit` + `tcomp export` ship (the fit's
//!   own choice, no `--use`), replayed through the board's fixed-point core
//!   (`tcomp replay`'s arithmetic); `default_float` is the same choice in
//!   floating point, as the fit reports it;
//! - `ridge`: the fit's ridge on the lagged MLR's inputs, its penalty chosen
//!   by forward-chaining time-blocked CV on the training rows only
//!   (`fit/ridge.rs`); `ridge_all`: a plain ridge on every temperature rise
//!   and the spindle speed (no lags, no input choice), penalty chosen the
//!   same way;
//! - `mlr` (the lagged MLR) and `ga_bpn` (the GA-trained network ensemble),
//!   as the fit validates them;
//! - `raw_rezero`: the raw error minus its value at the first served row (an
//!   operator's touch-off there and no model); `default_rezero`: the default's
//!   residual re-zeroed the same way.
//!
//! Cases: (a) every real run (FL_THERMAL, published chronological split:
//! train the first 60 %, serve the next 20 %), one fit per channel, as
//! `tcomp fit run.csv --split-chrono 0.6,0.8 --channels dchK_um`; (b)
//! simulated runs of the turning centre (`tcomp sim`'s library) whose last
//! 40 % leaves the training envelope: the ambient 2 K warmer, or spindle
//! speeds never run in training, `--seeds` runs each (`tcomp fit run.csv
//! --split-chrono 0.6,1`). Each case states the share of served rows with
//! an input outside its training range.
//!
//! Per case also "a re-zero is a promise" (issue 50 item 4, [`rezero`]):
//! a re-zero (command 2) at the start of every steady block of the served
//! part, the board's served change since against the raw error about it.
//!
//! Measures only: nothing here changes how a model is fitted or chosen.

mod report;
mod rezero;

use report::{headline, one_line, print_table};

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use tcomp_data::runcsv::Run;
use tcomp_model::export::{float_model_from_fit, ExportOptions};
use tcomp_model::fit::greedy::blocked_folds;
use tcomp_model::fit::net::NetOpts;
use tcomp_model::fit::pipeline::{fit_runs, FitConfig, FitReport, Plan, Silent};
use tcomp_model::fit::ridge::{all_blocks, choose_penalty, fit_ridge};
use tcomp_model::fit::{
    metrics, ranged_specs, FeatureKind, FeatureSpec, Metrics, Model, Segment, SeriesCache,
};
use tcomp_model::replay::ReplayRow;
use tcomp_thermal::sim::{sim_run, Duty, Machine, SimOptions};

/// "Worse than ridge" means more than this fraction above it.
const RIDGE_MARGIN: f64 = 0.05;

fn default_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/caiviac-fl-thermal/run.csv")
}

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(run)
}

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    name = "bench-extrapolation",
    about = "Issue 50: MAE / RMS on the served part of the default pipeline (fit + export, replayed on the board's arithmetic) beside ridge (penalty by time-blocked CV), MLR, the network and the raw error after a re-zero; every real run per channel and simulated runs whose served part leaves the training envelope (ambient +2 K, unseen spindle speeds)"
)]
struct Args {
    /// Print the figures as one JSON object.
    #[arg(long)]
    json: bool,
    /// The FL_THERMAL run CSV (default: shared/data/caiviac-fl-thermal/run.csv).
    #[arg(long, value_name = "CSV", default_value_os_t = default_data(), hide_default_value = true)]
    data: PathBuf,
    /// FL_THERMAL channels to score, comma list (default: every d…_um column).
    #[arg(long, value_name = "LIST")]
    channels: Option<String>,
    /// Skip the real run (simulated cases only).
    #[arg(long)]
    no_real: bool,
    /// Simulated scenarios, comma list: `ambient` (served part 2 K warmer),
    /// `speed` (served part at spindle speeds never run in training); empty:
    /// none.
    #[arg(long, value_name = "LIST", default_value = "ambient,speed")]
    scenarios: String,
    /// Simulated runs per scenario (noise seeds 1..=N; the seed also orders
    /// the training speeds).
    #[arg(long, value_name = "N", default_value_t = 3)]
    seeds: u64,
    /// Sample period of the simulated runs, seconds (20 h each).
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    sample_period: f64,
    /// Networks per ensemble (default: `tcomp fit`'s).
    #[arg(long, value_name = "N", default_value_t = NetOpts::default().ensemble)]
    ensemble: usize,
    /// Genetic algorithm individuals per generation (default: `tcomp fit`'s).
    #[arg(long, value_name = "N", default_value_t = NetOpts::default().population)]
    population: usize,
    /// Genetic algorithm generations (default: `tcomp fit`'s).
    #[arg(long, value_name = "N", default_value_t = NetOpts::default().generations)]
    generations: usize,
    /// Maximum Levenberg–Marquardt steps (default: `tcomp fit`'s).
    #[arg(long, value_name = "N", default_value_t = NetOpts::default().lm_iters)]
    lm_iters: usize,
}

impl Args {
    /// `tcomp fit`'s default configuration with the given split (and the
    /// network budget, which only a reduced run changes).
    fn fit_config(&self, split: (f64, f64), channel: Option<&str>) -> FitConfig {
        FitConfig {
            split_chrono: Some(split),
            channels: channel.map(|c| vec![c.to_string()]),
            net: NetOpts {
                ensemble: self.ensemble.max(1),
                population: self.population.max(4),
                generations: self.generations,
                lm_iters: self.lm_iters,
                ..NetOpts::default()
            },
            ..FitConfig::default()
        }
    }

    fn budget_is_default(&self) -> bool {
        let d = NetOpts::default();
        (
            self.ensemble,
            self.population,
            self.generations,
            self.lm_iters,
        ) == (d.ensemble, d.population, d.generations, d.lm_iters)
    }
}

fn run() -> Result<()> {
    let args: Args = tcomp_bench::cli::parse()?;
    let t0 = Instant::now();
    let mut cases = Vec::new();
    if !args.no_real {
        cases.extend(real_cases(&args)?);
    }
    cases.extend(sim_cases(&args)?);
    if cases.is_empty() {
        bail!("no case to score: give the real run or a scenario");
    }
    let headline = headline(&cases);
    let out = json!({
        "bench": "extrapolation",
        "ridge_margin": RIDGE_MARGIN,
        "network_budget": {"ensemble": args.ensemble, "population": args.population,
            "generations": args.generations, "lm_iters": args.lm_iters,
            "tcomp_fit_default": args.budget_is_default()},
        "steady_rezero_rule": rezero::rule(),
        "headline": headline,
        "cases": cases,
        "seconds": t0.elapsed().as_secs_f64(),
    });
    if args.json {
        println!("{out}");
    } else {
        print_table(&out);
    }
    Ok(())
}

/// (a) The real run, one fit per channel.
fn real_cases(args: &Args) -> Result<Vec<Value>> {
    let run = Run::read(&args.data).with_context(|| "FL_THERMAL data (give --data <run.csv>)")?;
    let channels: Vec<String> = match &args.channels {
        Some(c) => c.split(',').map(|s| s.trim().to_string()).collect(),
        None => run.error_columns().iter().map(|s| s.to_string()).collect(),
    };
    let mut out = Vec::new();
    for ch in &channels {
        let cfg = args.fit_config((0.6, 0.8), Some(ch));
        let case = score_case(
            &format!("fl-thermal/{ch}"),
            "real",
            "published chronological split: train 0-60 %, serve 60-80 %",
            &run,
            ch,
            &cfg,
        )?;
        if !args.json {
            eprintln!("{}", one_line(&case));
        }
        out.push(case);
    }
    Ok(out)
}

/// (b) Simulated runs whose served part leaves the training envelope.
fn sim_cases(args: &Args) -> Result<Vec<Value>> {
    let base = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let machine = Machine::load(&base.join("../../examples/machines/turning-center-16.toml"))?;
    let mut out = Vec::new();
    for scenario in args.scenarios.split(',').map(str::trim) {
        if scenario.is_empty() {
            continue;
        }
        for seed in 1..=args.seeds {
            let (duty, what) = scenario_duty(scenario, seed, machine.spec.ambient_c)?;
            let run = sim_run(
                &machine,
                &duty,
                &SimOptions {
                    effects: vec![],
                    seed,
                    hours: None,
                    sample_period_s: Some(args.sample_period),
                    noise: true,
                },
            )?;
            let cfg = args.fit_config((0.6, 1.0), None);
            // One fit for all the run's channels, as `tcomp fit run.csv`.
            let report = fit_report(&run, &cfg)?;
            for ch in run.error_columns() {
                let label = format!("sim-{scenario}/seed{seed}/{ch}");
                let case = score_fitted(&label, "simulated", &what, &run, ch, &cfg, &report)?;
                if !args.json {
                    eprintln!("{}", one_line(&case));
                }
                out.push(case);
            }
        }
    }
    Ok(out)
}

/// The duty of one simulated case: 12 h of training (rest, three speed
/// steps of 2 h with 1.5 h rests, in an order set by `seed`), then 8 h
/// served beyond the envelope. `ambient`: the served part at speeds seen
/// in training while the ambient rises 2 K in 0.5 K steps over its first
/// 2 h and stays there; `speed`: the served part at 8,500 rpm (above every
/// training speed) and 5,000 rpm (between them), ambient unchanged.
fn scenario_duty(scenario: &str, seed: u64, ambient: f64) -> Result<(Duty, String)> {
    let speeds = {
        let mut s = [2000.0, 4000.0, 6000.0];
        s.rotate_left((seed % 3) as usize);
        if seed.is_multiple_of(2) {
            s.swap(1, 2);
        }
        s
    };
    let mut segs: Vec<(f64, f64, f64)> = vec![(30.0, 0.0, ambient)];
    for &s in &speeds {
        segs.push((120.0, s, ambient));
        segs.push((90.0, 0.0, ambient));
    }
    segs.push((60.0, 0.0, ambient));
    let what = match scenario {
        "ambient" => {
            for k in 1..=4 {
                segs.push((30.0, speeds[0], ambient + 0.5 * k as f64));
            }
            segs.push((90.0, 0.0, ambient + 2.0));
            segs.push((120.0, speeds[2], ambient + 2.0));
            segs.push((150.0, 0.0, ambient + 2.0));
            format!(
                "turning-center-16, 20 h; train 0-60 %: {} rpm, ambient {ambient} °C; served 60-100 %: {} / {} rpm while the ambient rises to {} °C in 2 h",
                speeds.map(|s| s.to_string()).join(" / "),
                speeds[0],
                speeds[2],
                ambient + 2.0
            )
        }
        "speed" => {
            segs.push((120.0, 8500.0, ambient));
            segs.push((90.0, 0.0, ambient));
            segs.push((120.0, 5000.0, ambient));
            segs.push((150.0, 0.0, ambient));
            format!(
                "turning-center-16, 20 h; train 0-60 %: {} rpm; served 60-100 %: 8500 rpm (above every training speed) then 5000 rpm (never run), ambient {ambient} °C throughout",
                speeds.map(|s| s.to_string()).join(" / ")
            )
        }
        o => bail!("--scenarios: unknown scenario `{o}` (ambient or speed)"),
    };
    let mut toml = format!("name = \"extrapolation-{scenario}-{seed}\"\n");
    for (min, rpm, amb) in segs {
        let (feed, coolant) = if rpm > 0.0 { (0.3, 1.0) } else { (0.0, 0.0) };
        toml.push_str(&format!(
            "[[segment]]\nduration_min = {min}\nrpm = {rpm}\nfeed = {feed}\ncoolant = {coolant}\nambient_c = {amb}\n"
        ));
    }
    let duty = Duty::from_toml(&toml, &format!("extrapolation-{scenario}"))?;
    Ok((duty, what))
}

/// `tcomp fit`'s library call on one run, silently.
fn fit_report(run: &Run, cfg: &FitConfig) -> Result<FitReport> {
    fit_runs(vec![("run".to_string(), run.clone())], 1, cfg, &Silent)
}

/// Fit channel `ch` alone and score it.
fn score_case(
    label: &str,
    kind: &str,
    what: &str,
    run: &Run,
    ch: &str,
    cfg: &FitConfig,
) -> Result<Value> {
    let report = fit_report(run, cfg)?;
    score_fitted(label, kind, what, run, ch, cfg, &report)
}

/// One case's figures from a fit of its run.
fn score_fitted(
    label: &str,
    kind: &str,
    what: &str,
    run: &Run,
    ch: &str,
    cfg: &FitConfig,
    report: &FitReport,
) -> Result<Value> {
    // The rows the fit trained on and served, as it planned them.
    let mut runs = vec![run.clone()];
    runs[0].errors_as_rises("run");
    let plan = Plan::new(runs, vec!["run".into()], 1, cfg.split_chrono)?;
    let (train, served) = (&report.train_segments, &report.val_segments);
    let served_rows = served_range(served)?;
    let y = plan.runs[0]
        .col(ch)
        .with_context(|| format!("no column {ch}"))?;

    let model_fig = |name: &str| -> Option<Value> {
        let m = report.models.iter().find(|m| m.name == name)?;
        m.channels.get(ch).map(fig)
    };
    let chosen = report
        .chosen
        .get(ch)
        .cloned()
        .unwrap_or_else(|| "mlr".into());
    let default_float = if chosen == "none" {
        let (yy, _) = served_y(y, served_rows.clone());
        Some(fig(&metrics(&yy, &vec![0.0; yy.len()])))
    } else {
        model_fig(&chosen)
    };
    let board = board_replay(report, &plan.runs[0], ch, served_rows.clone())?;
    let raw_rezero = rezeroed(y, served_rows.clone(), |_| 0.0);
    let ridge_all = ridge_all(&plan, train, served, ch, cfg)?;
    let penalty = report
        .inputs
        .iter()
        .find(|i| i.channel == ch)
        .and_then(|i| i.cv.get("ridge"))
        .and_then(|s| s.penalty);
    let mut ridge = model_fig("ridge");
    if let (Some(Value::Object(o)), Some(p)) = (ridge.as_mut(), penalty) {
        o.insert("penalty".into(), json!(p));
    }
    let shipped = shipped_specs(report, ch, &chosen);
    let env_default = envelope_share(&plan, served, ch, &shipped)?;
    let env_all = envelope_share(&plan, served, ch, &all_input_specs(&plan, train, ch)?)?;
    let outside = |block: std::ops::Range<usize>| inputs_outside(&plan, block, ch, &shipped);
    let replay = board
        .replay
        .as_ref()
        .map(|(r, d, m)| (r.as_slice(), *d, *m));
    let promise = rezero::score_case(&plan.runs[0], y, served_rows.clone(), replay, &outside);

    let models = json!({
        "default": fig(&board.served),
        "default_float": default_float,
        "default_rezero": fig(&board.rezero),
        "ridge": ridge,
        "ridge_all": ridge_all,
        "mlr": model_fig("mlr"),
        "ga_bpn": model_fig("ga-bpn"),
        "raw_rezero": fig(&raw_rezero),
    });
    let get = |m: &str, k: &str| models[m][k].as_f64();
    let worse = |a: &str, b: &str, k: &str, margin: f64| -> Option<bool> {
        Some(get(a, k)? > get(b, k)? * (1.0 + margin))
    };
    let info = report.inputs.iter().find(|i| i.channel == ch);
    Ok(json!({
        "case": label,
        "kind": kind,
        "what": what,
        "channel": ch,
        "train_rows": info.map(|i| i.train_rows),
        "served_rows": served_rows.len(),
        "chosen": chosen,
        "envelope_policy": report.model_file.envelope.get(ch).map(|e| e.policy.clone()),
        "inputs": shipped.iter().map(FeatureSpec::name).collect::<Vec<_>>(),
        "cv_rms_um": info.map(|i| i.cv.iter().map(|(k, v)| (k.clone(), v.rms_um)).collect::<BTreeMap<_, _>>()),
        "outside_envelope_pct": {
            "default_inputs": env_default,
            "all_inputs": env_all,
        },
        "models": models,
        "default_worse_than_ridge": {
            "mae": worse("default", "ridge", "mae_um", RIDGE_MARGIN),
            "rms": worse("default", "ridge", "rms_um", RIDGE_MARGIN),
        },
        "default_worse_than_ridge_all": {
            "mae": worse("default", "ridge_all", "mae_um", RIDGE_MARGIN),
            "rms": worse("default", "ridge_all", "rms_um", RIDGE_MARGIN),
        },
        "default_worse_than_raw_rezero": {
            "mae": worse("default", "raw_rezero", "mae_um", 0.0),
            "rms": worse("default", "raw_rezero", "rms_um", 0.0),
        },
        "rezero_promise": promise,
    }))
}

fn fig(m: &Metrics) -> Value {
    json!({"mae_um": m.mae_um, "rms_um": m.rms_um, "rows": m.n})
}

/// The served rows (one run, one contiguous block).
fn served_range(served: &[Segment]) -> Result<std::ops::Range<usize>> {
    match served {
        [s] if s.end > s.start => Ok(s.start..s.end),
        _ => bail!("expected one served block, got {served:?}"),
    }
}

/// The measured values of the served rows (and their row numbers).
fn served_y(y: &[Option<f64>], rows: std::ops::Range<usize>) -> (Vec<f64>, Vec<usize>) {
    rows.filter_map(|r| y[r].map(|v| (v, r))).unzip()
}

/// Figures of `y − served(r)` re-zeroed at the first served row: each
/// residual minus the first one (what an operator's touch-off there gives).
fn rezeroed(
    y: &[Option<f64>],
    rows: std::ops::Range<usize>,
    served: impl Fn(usize) -> f64,
) -> Metrics {
    let (yy, rr) = served_y(y, rows);
    let res: Vec<f64> = yy.iter().zip(&rr).map(|(v, &r)| v - served(r)).collect();
    let first = res.first().copied().unwrap_or(0.0);
    let shifted: Vec<f64> = res.iter().map(|e| e - first).collect();
    metrics(&shifted, &vec![0.0; shifted.len()])
}

/// The board's figures on the served rows: as served, re-zeroed at the
/// first served row, and the replay itself (every row of the run, the
/// channel's direction, its largest correction; `None`: the board serves 0).
struct Board {
    served: Metrics,
    rezero: Metrics,
    replay: Option<(Vec<ReplayRow>, usize, i32)>,
}

/// What `tcomp export` (defaults, no `--use`) ships, replayed through the
/// board's fixed-point core over the whole run: the channel's residual on
/// the served rows, as served and re-zeroed at the first served row. When
/// the fit chose no model for the channel (or for any: nothing to export)
/// the board serves 0.
fn board_replay(
    report: &FitReport,
    run: &Run,
    ch: &str,
    rows: std::ops::Range<usize>,
) -> Result<Board> {
    let y = run.col(ch).with_context(|| format!("no column {ch}"))?;
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    let zero = |_: usize| 0.0;
    let serves_zero = |rows: std::ops::Range<usize>| {
        let (yy, _) = served_y(y, rows.clone());
        Board {
            served: metrics(&yy, &vec![0.0; yy.len()]),
            rezero: rezeroed(y, rows, zero),
            replay: None,
        }
    };
    let float = match float_model_from_fit(&report.model_file, &columns, &ExportOptions::default())
    {
        Ok(f) => f,
        Err(_) if report.model_file.chosen.values().all(|c| c == "none") => {
            return Ok(serves_zero(rows));
        }
        Err(e) => return Err(e),
    };
    // As `export`: the envelope policy per direction from the fit's
    // evidence and the output low-pass the fit chose, built into the image
    // by the very function `export` writes (fallbacks left out to fit, its
    // refusals, extrapolate judged on what the image holds).
    let sections = tcomp_model::export::Sections {
        envelope: tcomp_model::export::policies(&report.model_file, &float).0,
        output: tcomp_model::export::decays(&report.model_file, &float).0,
        ..Default::default()
    };
    let built = tcomp_model::export::build_image(&float, &sections)
        .with_context(|| format!("{ch}: the image `tcomp export` would ship"))?;
    built.notes.iter().for_each(|n| eprintln!("{ch}: {n}"));
    // The board's model is the one its parser reads from these bytes.
    let model = thermocomp_core::Model::parse(&built.bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
    let Some(d) =
        (0..model.directions.len()).find(|&d| format!("d{}_um", model.direction_name(d)) == ch)
    else {
        // The fit chose `none` for this channel: the board serves 0.
        return Ok(serves_zero(rows));
    };
    let max_correction = model.directions[d].max_correction;
    let mut csv = Vec::new();
    run.write_to(&mut csv)?;
    let replayed = tcomp_model::replay::replay(&String::from_utf8(csv)?, model)?;
    let served = |r: usize| f64::from(replayed[r].out.corrections[d]) / 10.0;
    let (yy, rr) = served_y(y, rows.clone());
    let pred: Vec<f64> = rr.iter().map(|&r| served(r)).collect();
    Ok(Board {
        served: metrics(&yy, &pred),
        rezero: rezeroed(y, rows, served),
        replay: Some((replayed, d, max_correction)),
    })
}

/// The inputs (with training ranges) of the model the fit ships for `ch`;
/// for `none`, the lagged MLR's (the envelope of what it would have read).
fn shipped_specs(report: &FitReport, ch: &str, chosen: &str) -> Vec<FeatureSpec> {
    let f = &report.model_file;
    let find = |v: &[tcomp_model::fit::MlrParams]| {
        v.iter()
            .find(|m| m.channel == ch)
            .map(|m| m.features.clone())
    };
    let specs = match chosen {
        "mlr-static" => find(&f.mlr_static),
        "ridge" => find(&f.ridge),
        "ga-bpn" => f
            .nets
            .iter()
            .find(|n| n.channel == ch)
            .map(|n| n.features.clone()),
        _ => None,
    };
    specs.or_else(|| find(&f.mlr)).unwrap_or_default()
}

/// Every temperature rise and the spindle speed, unlagged, with their
/// ranges over the training rows.
fn all_input_specs(plan: &Plan, train: &[Segment], ch: &str) -> Result<Vec<FeatureSpec>> {
    let kinds = all_kinds(&plan.runs[0]);
    let cache = SeriesCache::new(&plan.runs, kinds.clone())?;
    let idx: Vec<usize> = (0..kinds.len()).collect();
    let full = cache.samples(&plan.runs, train, &idx, ch)?;
    Ok(ranged_specs(&kinds, &full))
}

fn all_kinds(run: &Run) -> Vec<(FeatureKind, Option<f64>)> {
    let mut kinds: Vec<(FeatureKind, Option<f64>)> = run
        .temperature_columns()
        .iter()
        .map(|c| (FeatureKind::SensorRise(c.to_string()), None))
        .collect();
    if run.col("spindle_rpm").is_some() {
        kinds.push((FeatureKind::Spindle, None));
    }
    kinds
}

/// Per input of `specs` (name), the percentage of `block`'s rows (with a
/// target) on which it lies outside its training range, those above 0 only.
fn inputs_outside(
    plan: &Plan,
    block: std::ops::Range<usize>,
    ch: &str,
    specs: &[FeatureSpec],
) -> Value {
    let seg = [Segment {
        run: 0,
        start: block.start,
        end: block.end,
    }];
    let kinds: Vec<_> = specs.iter().map(|s| (s.kind.clone(), s.tau_s)).collect();
    let idx: Vec<usize> = (0..specs.len()).collect();
    let Ok(s) =
        SeriesCache::new(&plan.runs, kinds).and_then(|c| c.samples(&plan.runs, &seg, &idx, ch))
    else {
        return Value::Null;
    };
    let n = s.y.len().max(1) as f64;
    let mut out = serde_json::Map::new();
    for (i, f) in specs.iter().enumerate() {
        let k = s.x.iter().filter(|r| r[i] < f.min || r[i] > f.max).count();
        if k > 0 {
            out.insert(f.name(), json!(100.0 * k as f64 / n));
        }
    }
    Value::Object(out)
}

/// Percentage of the served rows (with a target) on which any of `specs`'
/// inputs lies outside its training range.
fn envelope_share(
    plan: &Plan,
    served: &[Segment],
    ch: &str,
    specs: &[FeatureSpec],
) -> Result<Option<f64>> {
    if specs.is_empty() {
        return Ok(None);
    }
    let kinds: Vec<_> = specs.iter().map(|s| (s.kind.clone(), s.tau_s)).collect();
    let cache = SeriesCache::new(&plan.runs, kinds)?;
    let idx: Vec<usize> = (0..specs.len()).collect();
    let s = cache.samples(&plan.runs, served, &idx, ch)?;
    if s.y.is_empty() {
        return Ok(None);
    }
    let out =
        s.x.iter()
            .filter(|r| {
                specs
                    .iter()
                    .zip(r.iter())
                    .any(|(f, &v)| v < f.min || v > f.max)
            })
            .count();
    Ok(Some(100.0 * out as f64 / s.y.len() as f64))
}

/// A plain ridge on every temperature rise and the spindle speed, its
/// penalty chosen by forward-chaining CV over the fit's time blocks of
/// the training rows (`ridge::choose_penalty`), fitted on all training rows.
fn ridge_all(
    plan: &Plan,
    train: &[Segment],
    served: &[Segment],
    ch: &str,
    cfg: &FitConfig,
) -> Result<Option<Value>> {
    let kinds = all_kinds(&plan.runs[0]);
    let cache = SeriesCache::new(&plan.runs, kinds.clone())?;
    let idx: Vec<usize> = (0..kinds.len()).collect();
    let folds = blocked_folds(&plan.runs, train, cfg.select_folds);
    let Some(lambda) = choose_penalty(&cache, &plan.runs, &all_blocks(&folds), &idx, ch)? else {
        return Ok(None);
    };
    let full = cache.samples(&plan.runs, train, &idx, ch)?;
    let val = cache.samples(&plan.runs, served, &idx, ch)?;
    let m = fit_ridge(ranged_specs(&kinds, &full), &full, lambda, ch)?;
    let pred: Vec<f64> = val.x.iter().map(|r| m.predict_raw(r)).collect();
    let mut v = fig(&metrics(&val.y, &pred));
    v["penalty"] = json!(lambda);
    v["inputs"] = json!(kinds.len());
    Ok(Some(v))
}

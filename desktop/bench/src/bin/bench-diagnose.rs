//! Blind check of `tcomp diagnose`: ≥ 50 generated cases (each effect, pairs,
//! clean runs) at random strengths and duty cycles; top-1 identification,
//! held-out gap shrink, false alarms, and the time of a full diagnosis of an
//! 8 h run sampled at 1 s.
//!
//! `bench-diagnose [--cases N] [--seed S] [--json] [--verbose] [--machines DIR] [--machine FILE]`
//! (`--open-only`, `--open-machine-only`, `--closed-only`, `--cross-only`:
//! one column alone; `--periodic-only`: the periodic-driver column, both
//! modes, `harness/periodic.rs`)
//!
//! The cross-model column runs `diagnose fit` on cases of the first
//! simulator (`tcomp_thermal::sim`), which the fit mode was never tuned on.
//!
//! `--machine FILE`: the machine file of the open-world machine-file column
//! (default `examples/machines/vertical-mc-truth.toml`, the truth's own numbers;
//! `examples/machines/vertical-mc-design-error.toml` is the same design off by
//! ±10–20 %). The column takes the file as exact (as `tcomp diagnose`
//! does by default); `--calibrate` calibrates its design values on each
//! case's fit rows first (`tcomp diagnose --calibrate`).
//!
//! Issue 27's columns: `--columns exact,design,fit` (or `all`) diagnoses the
//! same cases with the exact design file, with a design file whose every
//! design number is off by a lognormal factor (σ of its log `--sigma`,
//! default 0.15, drawn per case), both with default flags, and with no file
//! (`diagnose fit`), on `--worlds open,cross` (default both), scored named /
//! honest / wrong / silent with false alarms on clean cases. `--heldout`
//! runs the held-out seeds (`HELDOUT_SEEDS`: 101, 103, 107) instead of
//! `--seed`; never tune on them. One line per case and column on stderr
//! (wall and CPU seconds). `--threads N`: diagnose on N threads (default:
//! every core; `--threads 1` for the one-core time).
//!
//! Issue 52 item 4: `--worlds open,cross,third` (or `all`; alone it runs
//! every column) adds the blind third world (`worlds/third/`, frozen: run
//! by its own gen.py and scorer as `python3` subprocesses, with the
//! `tcomp` binary beside this one or `--tcomp FILE`), reports per world
//! and column named / honest / ambiguous / wrong / silent / false alarms,
//! a `worst` row per column and the CPU seconds per world. `--cases N` is
//! the cases per world; without it each world draws enough for ≥ 150
//! effect and 30 clean cases per column (slow: hours on two cores).
use anyhow::Result;
use std::path::PathBuf;
use tcomp_bench::harness::{
    run_bench, run_cross_bench, run_open_bench, run_open_machine_bench, run_periodic_bench,
    run_worlds, worlds_text, ApproxConfig, BenchConfig, Column, World, WorldsConfig, HELDOUT_SEEDS,
};
use tcomp_thermal::diagnose::{diagnose, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(run)
}

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    name = "bench-diagnose",
    about = "Blind check of `tcomp diagnose`: generated cases of known effects, scored named / honest / wrong / silent with false alarms on clean cases",
    after_help = "Examples:\n  bench-diagnose --json                       the closed-world bench (60 cases)\n  bench-diagnose --columns all --cases 10     issue 27's columns, both worlds\n  bench-diagnose --columns fit --worlds open  `diagnose fit` on the open world"
)]
struct Args {
    /// Generated cases (clean cases are added past this count) [default: 60; with --worlds/--columns, per world, enough for 150 effect + 30 clean cases]
    #[arg(long)]
    cases: Option<usize>,
    /// First case index (to run a slice of a seed's cases).
    #[arg(long = "first-case", default_value_t = 0)]
    first_case: usize,
    /// Seed of the cases (development seeds; see --heldout).
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Print the figures as one JSON object.
    #[arg(long)]
    json: bool,
    /// One line per case with what was named.
    #[arg(long)]
    verbose: bool,
    /// The open-world `diagnose fit` column alone.
    #[arg(long = "open-only")]
    open_only: bool,
    /// The open-world machine-file column alone.
    #[arg(long = "open-machine-only")]
    machine_only: bool,
    /// The closed-world column alone.
    #[arg(long = "closed-only")]
    closed_only: bool,
    /// The cross-model `diagnose fit` column alone.
    #[arg(long = "cross-only")]
    cross_only: bool,
    /// The periodic-driver column alone (both modes).
    #[arg(long = "periodic-only")]
    periodic_only: bool,
    /// Folder of the closed world's machine files.
    #[arg(long = "machines", value_name = "DIR", default_value_os_t = examples_dir().join("machines"))]
    dir: PathBuf,
    /// Machine file of the open-world machine-file column (default: the truth's own numbers).
    #[arg(long = "machine", value_name = "FILE")]
    open_machine_file: Option<PathBuf>,
    /// Calibrate the machine file's design values on each case's fit rows first.
    #[arg(long)]
    calibrate: bool,
    /// Issue 27's columns: `all` or a comma list of exact, design, fit.
    #[arg(long, value_name = "LIST", value_parser = parse_columns)]
    columns: Option<Columns>,
    /// Worlds of the columns: `all` or a comma list of open, cross, third [default with --columns: open,cross]; alone it runs every column.
    #[arg(long, value_name = "LIST", value_parser = parse_worlds)]
    worlds: Option<Worlds>,
    /// The tcomp binary the third world's scorer runs [default: tcomp beside this binary].
    #[arg(long, value_name = "FILE")]
    tcomp: Option<PathBuf>,
    /// Third-world cases its gen.py already wrote (scored as they are; --cases and --first-case do not apply).
    #[arg(long = "third-cases", value_name = "DIR")]
    third_cases: Option<PathBuf>,
    /// Run the held-out seeds (101, 103, 107) instead of --seed; never tune on them.
    #[arg(long)]
    heldout: bool,
    /// σ of the log of the design file's error factor (the `design` column).
    #[arg(long, default_value_t = tcomp_bench::harness::perturb::DESIGN_SIGMA)]
    sigma: f64,
    /// Diagnose on this many threads (default: every core; 1 for the one-core time).
    #[arg(long)]
    threads: Option<usize>,
}

/// A list given as one comma-separated value (clap would read a `Vec`
/// field as a repeated flag).
#[derive(Clone)]
struct Columns(Vec<Column>);
#[derive(Clone)]
struct Worlds(Vec<World>);

/// `--worlds LIST`: `all` or a comma list of open, cross, third.
fn parse_worlds(l: &str) -> Result<Worlds> {
    if l == "all" {
        return Ok(Worlds(vec![World::Open, World::Cross, World::Third]));
    }
    Ok(Worlds(
        l.split(',').map(World::parse).collect::<Result<_>>()?,
    ))
}

fn parse_args() -> Result<Args> {
    <Args as clap::Parser>::try_parse().map_err(|e| {
        // --help / --version print and exit 0; a bad flag is one line.
        if matches!(
            e.kind(),
            clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
        ) {
            e.exit()
        }
        anyhow::anyhow!(
            "{}",
            e.to_string()
                .lines()
                .next()
                .unwrap_or("bad arguments")
                .trim_start_matches("error: ")
        )
    })
}

fn run() -> Result<()> {
    let Args {
        cases,
        seed,
        json,
        verbose,
        open_only,
        machine_only,
        closed_only,
        cross_only,
        periodic_only,
        dir,
        open_machine_file,
        calibrate,
        columns,
        worlds,
        heldout,
        sigma,
        threads,
        first_case,
        tcomp,
        third_cases,
    } = parse_args()?;
    let machines = vec![
        Machine::load(&dir.join("turning-center-16.toml"))?,
        Machine::load(&dir.join("five-axis-20.toml"))?,
    ];
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let open_cfg = BenchConfig {
        cases: cases.unwrap_or(60),
        seed,
        hours: 8.0,
        sample_period_s: 10.0,
        threads,
        verbose,
        calibrate,
    };
    // the closed world searches the simulator it was drawn from: never calibrated
    let closed_cfg = BenchConfig {
        calibrate: false,
        ..open_cfg
    };
    if columns.is_some() || worlds.is_some() {
        // --worlds alone: every column; --columns alone: the two in-process worlds
        let columns = columns.unwrap_or(Columns(vec![Column::Exact, Column::Design, Column::Fit]));
        let worlds = worlds.unwrap_or(Worlds(vec![World::Open, World::Cross]));
        let path = open_machine_file.unwrap_or_else(|| dir.join("vertical-mc-truth.toml"));
        let seeds = if heldout {
            HELDOUT_SEEDS.to_vec()
        } else {
            vec![seed]
        };
        let acfg = ApproxConfig {
            columns: columns.0,
            worlds: worlds.0,
            sigma,
            seeds,
            first_case,
        };
        let tcomp = match tcomp {
            Some(t) => t,
            None => std::env::current_exe()?.with_file_name("tcomp"),
        };
        let wcfg = WorldsConfig {
            cases,
            tcomp: &tcomp,
            third_dir: third_cases.as_deref(),
        };
        return run_columns(&path, &machines, &open_cfg, &acfg, &wcfg, json);
    }
    if closed_only {
        let v = run_bench(&machines, &closed_cfg)?;
        println!("{v}");
        return Ok(());
    }
    if cross_only {
        // diagnose fit on the first simulator's machines (never tuned on)
        println!("{}", run_cross_bench(&machines, &open_cfg)?);
        return Ok(());
    }
    if open_only {
        // the open world alone: `diagnose fit`, no machine-file pass
        println!("{}", run_open_bench(&open_cfg)?);
        return Ok(());
    }
    let open_machine_path = open_machine_file.unwrap_or_else(|| dir.join("vertical-mc-truth.toml"));
    let truth_machine = Machine::load(&open_machine_path)?;
    if periodic_only {
        println!("{}", run_periodic_bench(&truth_machine, &open_cfg)?);
        return Ok(());
    }
    let mut open_machine = run_open_machine_bench(&truth_machine, &open_cfg)?;
    open_machine["machine_file"] = serde_json::json!(open_machine_path.display().to_string());
    if machine_only {
        println!("{open_machine}");
        return Ok(());
    }
    let open = run_open_bench(&open_cfg)?;
    let cross = run_cross_bench(&machines, &open_cfg)?;
    let mut v = run_bench(&machines, &closed_cfg)?;
    let (secs, top) = full_diagnosis_8h_1s(&machines[1], threads)?;
    v["full_diagnosis_8h_1s_seconds"] = serde_json::json!(secs);
    v["full_diagnosis_8h_1s_top"] = serde_json::json!(top);
    v["threads"] = serde_json::json!(threads);
    // closed world (machine file, the simulator the diagnoser searches) and
    // open world (no machine file, the separate truth model) side by side
    let pick = |j: &serde_json::Value| {
        serde_json::json!({
            "top1_rate": j["top1_rate"],
            "heldout_gap_shrink_um": j["mean_heldout_gap_shrink_um"],
            "heldout_gap_shrink_c": j.get("mean_heldout_gap_shrink_c").cloned().unwrap_or(j["mean_heldout_gap_shrink"].clone()),
            "false_alarms": j["false_alarms"],
            "clean_cases": j["clean_cases"],
            "seconds_per_case": j["mean_diagnosis_seconds"],
        })
    };
    let mut open_fit = pick(&open);
    open_fit["top1_rate_fit_testable"] = open["top1_rate_fit_testable"].clone();
    let mut with_machine = pick(&open_machine);
    with_machine["per_effect"] = open_machine["per_effect"].clone();
    with_machine["max_seconds_per_case"] = open_machine["max_diagnosis_seconds"].clone();
    with_machine["machine_file"] = open_machine["machine_file"].clone();
    v["side_by_side"] = serde_json::json!({
        "closed_world": pick(&v),
        "open_world_fit": open_fit,
        "open_world_with_machine_file": with_machine,
        "cross_model_fit": {
            "top1_rate": cross["top1_rate"],
            "per_effect": cross["per_effect"],
            "false_alarms": cross["false_alarms"],
            "clean_cases": cross["clean_cases"],
            "seconds_per_case": cross["mean_diagnosis_seconds"],
        },
    });
    v["cross_model_fit"] = cross.clone();
    v["open_world_machine_file"] = open_machine.clone();
    v["open_world"] = open.clone();
    if json {
        println!("{v}");
    } else {
        print_text(&v, &open, &cross, secs, threads);
    }
    Ok(())
}

/// `--columns LIST`: `all` or a comma list of exact, design, fit.
fn parse_columns(l: &str) -> Result<Columns> {
    if l == "all" {
        return Ok(Columns(vec![Column::Exact, Column::Design, Column::Fit]));
    }
    Ok(Columns(
        l.split(',').map(Column::parse).collect::<Result<_>>()?,
    ))
}

/// Issue 27's columns on issue 52's worlds (`--columns`, `--worlds`), with
/// the worst world per column, printed as text or JSON.
fn run_columns(
    path: &std::path::Path,
    machines: &[Machine],
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
    wcfg: &WorldsConfig,
    json: bool,
) -> Result<()> {
    let mut v = run_worlds(&Machine::load(path)?, machines, cfg, acfg, wcfg)?;
    v["open_world_machine_file"] = serde_json::json!(path.display().to_string());
    if json {
        println!("{v}");
    } else {
        print!("{}", worlds_text(&v));
    }
    Ok(())
}

/// Time of a full diagnosis (all candidates) of one 8 h run sampled at 1 s,
/// and the effect it names first.
fn full_diagnosis_8h_1s(m: &Machine, threads: usize) -> Result<(f64, Option<String>)> {
    let duty = Duty::load(&examples_dir().join("duty/production-mixed.toml"))?;
    let run = sim_run(
        m,
        &duty,
        &SimOptions {
            effects: vec![Effect::Ballscrew { k_w: 80.0 }],
            seed: 5,
            hours: Some(8.0),
            sample_period_s: Some(1.0),
            noise: true,
        },
    )?;
    let t = std::time::Instant::now();
    let d = diagnose(
        m,
        &[("8h-1s".into(), run)],
        &Options {
            threads,
            ..Options::default()
        },
    )?;
    let secs = t.elapsed().as_secs_f64();
    Ok((secs, d.findings.first().map(|f| f.name.clone())))
}

/// The text summary (without --json).
fn print_text(
    v: &serde_json::Value,
    open: &serde_json::Value,
    cross: &serde_json::Value,
    secs: f64,
    threads: usize,
) {
    println!(
        "bench-diagnose: {} cases ({} single, {} pair, {} clean): top-1 {:.1} % (single {:.1} %, pair {:.1} %), {:.1} % of effect cases counting a parameter finding that names the effect's physics, held-out gap shrink {:.1} % (µm channels {:.1} %), false alarms {}/{}; 8 h @ 1 s full diagnosis {:.2} s ({} threads)",
        v["cases"], v["single_cases"], v["pair_cases"], v["clean_cases"],
        v["top1_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["top1_single_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["top1_pair_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["top1_or_physics_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["mean_heldout_gap_shrink"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["mean_heldout_gap_shrink_um"].as_f64().unwrap_or(f64::NAN) * 100.0,
        v["false_alarms"], v["clean_cases"], secs, threads
    );
    println!(
        "open world (diagnose fit, no machine file, truth model diagnose/truth.rs): {} cases: top-1 {:.1} % (step/lag/chiller/speed kinds {:.1} %), held-out shrink {:.1} % °C / {:.1} % µm, false alarms {}/{}, {:.2} s per 8 h case; per effect {}",
        open["cases"],
        open["top1_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        open["top1_rate_fit_testable"].as_f64().unwrap_or(f64::NAN) * 100.0,
        open["mean_heldout_gap_shrink_c"].as_f64().unwrap_or(f64::NAN) * 100.0,
        open["mean_heldout_gap_shrink_um"].as_f64().unwrap_or(f64::NAN) * 100.0,
        open["false_alarms"], open["clean_cases"],
        open["mean_diagnosis_seconds"].as_f64().unwrap_or(f64::NAN),
        open["per_effect"]
    );
    println!(
        "cross model (diagnose fit on the first simulator's machines): {} cases: top-1 {:.1} %, false alarms {}/{}, {:.2} s per 8 h case; per effect {}",
        cross["cases"],
        cross["top1_rate"].as_f64().unwrap_or(f64::NAN) * 100.0,
        cross["false_alarms"], cross["clean_cases"],
        cross["mean_diagnosis_seconds"].as_f64().unwrap_or(f64::NAN),
        cross["per_effect"]
    );
    if let Some(ms) = v["misses"].as_array() {
        for m in ms {
            println!("  miss: {m}");
        }
    }
}

/// `examples/` at the repository root, where the machine and duty files are.
fn examples_dir() -> PathBuf {
    let bench = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let root = bench.ancestors().nth(2).unwrap_or(&bench);
    root.join("examples")
}

//! `tcomp`: from calibration runs to a model image on the board. This crate
//! only parses the command line and hands each subcommand to the library
//! crates (`tcomp-data`, `-model`, `-geometry`, `-thermal`, `-link`); the
//! per-command argument structs and their glue are in `cli/`.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

mod cli;
use anyhow::Context;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "tcomp",
    version,
    about = "thermocomp desktop tools: record, select, fit, export, upload, simulate, diagnose"
)]
struct Cli {
    /// On an error, print the full chain and the stack trace (also TCOMP_BACKTRACE=1).
    #[arg(long, global = true)]
    debug: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Quantize a model through the core's quantizer and write the board's model image.
    Export {
        /// Export the built-in demonstration model (random weights from --seed).
        #[arg(long)]
        demo: bool,
        /// Fitted parameters written by `tcomp fit --out`.
        #[arg(long, conflicts_with = "demo")]
        model: Option<std::path::PathBuf>,
        /// A run CSV whose T_ columns give the board's channel order.
        #[arg(long, requires = "model")]
        run: Option<std::path::PathBuf>,
        /// Per-channel override of the fit's cross-validated choice, e.g.
        /// `dch3_um=ga-bpn,dch5_um=mlr` (ga-bpn alias net, hybrid, mlr, mlr-static).
        #[arg(long, default_value = "")]
        r#use: String,
        #[arg(long, default_value_t = 200.0)]
        max_correction_um: f64,
        #[arg(long, default_value_t = 1.0)]
        max_rate_um_per_s: f64,
        #[arg(long, default_value_t = 1)]
        model_version: u32,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Add the volumetric correction: the JSON of `tcomp geometry table
        /// --json` (image section kind 3; its sensors are found by name
        /// among the --run file's T_ columns).
        #[arg(long)]
        geometry: Option<std::path::PathBuf>,
        /// Tool length at full scale of the volumetric section (mm); longer
        /// tools are held there and flagged.
        #[arg(long, default_value_t = 500.0, requires = "geometry")]
        tool_max_mm: f64,
        /// Machine position (mm) of the volumetric polynomial's zero, per axis: x,y,z.
        #[arg(long, default_value = "0,0,0", requires = "geometry")]
        geometry_origin_mm: String,
        #[arg(short, long)]
        out: std::path::PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// The board's output for a run, computed by the desktop core (bit-exact
    /// with the firmware), and its error against the measured channels.
    Replay {
        run: std::path::PathBuf,
        image: std::path::PathBuf,
        /// Score rows from this fraction of the run (e.g. 0.6 for the FL_THERMAL test block).
        #[arg(long, default_value_t = 0.0)]
        from: f64,
        #[arg(long, default_value_t = 1.0)]
        to: f64,
        /// Lose a sensor from a time on: `T_t4@1800` (seconds of the run) or
        /// `T_t4@60%` (from that fraction of the rows); repeatable.
        #[arg(long = "fail-sensor", value_name = "NAME@TIME")]
        fail_sensor: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Send a model image to a board over Modbus RTU and check it serves it.
    Upload {
        image: std::path::PathBuf,
        #[command(flatten)]
        link: LinkArgs,
        /// Commit even if the board runs this or a newer model version (going back on purpose).
        #[arg(long)]
        rollback: bool,
        #[arg(long)]
        json: bool,
    },
    /// Poll a board over Modbus RTU and write (or extend) a run CSV.
    Record {
        #[command(flatten)]
        link: LinkArgs,
        #[arg(short, long)]
        out: std::path::PathBuf,
        #[arg(long, default_value_t = 1.0)]
        interval_s: f64,
        #[arg(long, default_value_t = 10)]
        samples: usize,
        /// Continue an existing file (same board, same columns).
        #[arg(long)]
        append: bool,
    },
    /// SVG plots: temperatures, measured error vs the board's correction,
    /// residual before/after, and the sensor clusters.
    Report {
        run: std::path::PathBuf,
        /// Model image: adds the error and residual plots (the board's output, via replay).
        #[arg(long)]
        image: Option<std::path::PathBuf>,
        /// Add the K-means++ cluster map of `select`.
        #[arg(long)]
        select: bool,
        #[arg(short, long)]
        out: std::path::PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Write golden vectors (demo model, inputs, host outputs) for the board's self-test.
    Golden {
        #[arg(short, long)]
        out: std::path::PathBuf,
        #[arg(long, default_value_t = 2000)]
        steps: u32,
        #[arg(long, default_value_t = 99)]
        seed: u64,
    },
    /// Temperature-sensitive points: K-means++ groups, correlation scores, best sensor per group.
    Select(cli::select::SelectArgs),
    /// Fit MLR and GA-BPN models per channel; validate on held-out runs or time blocks.
    Fit(cli::fit::FitArgs),
    /// Simulate a machine's thermal behaviour under a duty cycle into a run CSV.
    Sim(cli::sim::SimArgs),
    /// Diagnose the sim-to-real gap of measured runs against a nominal machine model.
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// Geometric errors: simulate or identify the 21 errors from 14 displacement lines.
    Geometry(cli::geometry::GeometryArgs),
    /// Print a run file's summary (rows, columns, metadata).
    Info {
        run: std::path::PathBuf,
        #[arg(long)]
        json: bool,
    },
}

/// Where the board is: a serial port or a TCP socket carrying RTU frames.
#[derive(clap::Args)]
struct LinkArgs {
    /// RTU over TCP, e.g. 127.0.0.1:5502 (the QEMU bench board).
    #[arg(long, conflicts_with = "serial")]
    tcp: Option<String>,
    /// Serial port of an RS-485 adapter, e.g. /dev/ttyUSB0.
    #[arg(long)]
    serial: Option<String>,
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    #[arg(long, default_value_t = 1)]
    unit: u8,
}

impl LinkArgs {
    fn open(&self) -> anyhow::Result<tcomp_link::board_link::BoardLink> {
        match (&self.tcp, &self.serial) {
            (Some(a), _) => tcomp_link::board_link::BoardLink::tcp(a, self.unit),
            (None, Some(p)) => tcomp_link::board_link::BoardLink::serial(p, self.baud, self.unit),
            (None, None) => {
                anyhow::bail!("say where the board is: --tcp HOST:PORT or --serial PATH")
            }
        }
    }
}

/// A reader that closes the pipe early (`tcomp … --json | head`) ends the
/// program quietly, as Unix tools do (exit 141 = killed by SIGPIPE); any
/// other panic is a one-line internal error without the stack trace.
fn quiet_panics() {
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("panic");
        if msg.contains("Broken pipe") {
            std::process::exit(141);
        }
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!(
            "error: internal error: {msg}{at} (please report it; --debug shows the stack trace)"
        );
    }));
}

/// Errors are one line (`error: what: because`) and exit 1; the stack trace
/// is for developers and only shown with `--debug` or `TCOMP_BACKTRACE=1`,
/// whatever `RUST_BACKTRACE` says (anyhow would otherwise print it with every
/// refused input file).
fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let debug = cli.debug || std::env::var_os("TCOMP_BACKTRACE").is_some_and(|v| v == "1");
    // anyhow decides at the first error whether to capture a backtrace, from
    // these variables: capture exactly when it will be printed.
    std::env::set_var("RUST_LIB_BACKTRACE", if debug { "1" } else { "0" });
    if !debug {
        quiet_panics();
    }
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) if debug => {
            eprintln!("error: {e:?}");
            std::process::ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("error: {}", tcomp_data::cli_error::one_line(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// A model channel the run has no temperature column for would be a
/// permanently failed sensor: the replay would show nothing of the model.
/// A sensor named by ROM code that the run (recording ROM codes) does not
/// hold is replayed as missing, as the board would, and said so.
fn check_channels(
    model: &thermocomp_core::Model,
    run: &tcomp_data::runcsv::Run,
    image: &std::path::Path,
    run_path: &std::path::Path,
) -> anyhow::Result<()> {
    let names: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    let roms = run
        .sensor_roms()
        .with_context(|| format!("in run file {}", run_path.display()))?;
    let columns = names.len();
    let resolved = tcomp_model::replay::sensor_columns(model, &names, &roms);
    for (i, (s, c)) in model.sensors.iter().zip(&resolved).enumerate() {
        match c {
            Some(c) => anyhow::ensure!(
                *c < columns,
                "{} reads temperature channel {} (counted from 0) but {} has {columns} temperature columns",
                image.display(),
                c,
                run_path.display()
            ),
            None => eprintln!(
                "note: model sensor {i} (ROM {}) is not in {}: replayed as a missing sensor",
                tcomp_data::runcsv::format_rom(&s.rom),
                run_path.display()
            ),
        }
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Export {
            demo,
            model,
            run,
            r#use,
            max_correction_um,
            max_rate_um_per_s,
            model_version,
            seed,
            geometry,
            tool_max_mm,
            geometry_origin_mm,
            out,
            json,
        } => {
            let run_for_geometry = run.clone();
            let float = match (demo, model) {
                (true, _) => thermocomp_core::float::demo_model(seed),
                (false, Some(path)) => {
                    let text = std::fs::read_to_string(&path)
                        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
                    let file: tcomp_model::fit::ModelFile = serde_json::from_str(&text)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                    let run = run.ok_or_else(|| {
                        anyhow::anyhow!("--run <csv> gives the board's channel order")
                    })?;
                    let table = tcomp_data::runcsv::Run::read_with_temperatures(&run)?;
                    let columns: Vec<String> = table
                        .temperature_columns()
                        .iter()
                        .map(|c| c.to_string())
                        .collect();
                    let roms = table
                        .sensor_roms()
                        .with_context(|| format!("in run file {}", run.display()))?;
                    let opts = tcomp_model::export::ExportOptions {
                        model_version,
                        max_correction_um,
                        max_rate_um_per_s,
                        choices: tcomp_model::export::parse_choices(&r#use)?,
                        ..Default::default()
                    };
                    let mut float =
                        tcomp_model::export::float_model_from_fit(&file, &columns, &opts)?;
                    tcomp_model::export::name_sensors_by_rom(&mut float, &columns, &roms)?;
                    float
                }
                (false, None) => {
                    anyhow::bail!("say what to export: --demo or --model <fit.json> --run <csv>")
                }
            };
            let section = match geometry {
                Some(path) => Some(geometry_section(
                    &path,
                    &float,
                    run_for_geometry.as_deref(),
                    tool_max_mm,
                    &geometry_origin_mm,
                    max_correction_um,
                )?),
                None => None,
            };
            let summary = tcomp_model::export::export_with(&float, section, &out)?;
            tcomp_model::export::print_summary(&summary, &out, json);
        }
        Command::Replay {
            run,
            image,
            from,
            to,
            fail_sensor,
            json,
        } => {
            // Run file first, then image: each refusal names its own file.
            let mut table = tcomp_data::runcsv::Run::read_with_temperatures(&run)?;
            // Scored as rises from the run's start, as the board compensates.
            let notes: Vec<String> = table
                .errors_as_rises(&run.display().to_string())
                .into_iter()
                .collect();
            let bytes = std::fs::read(&image)
                .map_err(|e| anyhow::anyhow!("reading {}: {e}", image.display()))?;
            let model = thermocomp_core::Model::parse(&bytes)
                .map_err(|e| anyhow::anyhow!("{}: {e}", image.display()))?;
            check_channels(&model, &table, &image, &run)?;
            let failures = fail_sensor
                .iter()
                .map(|f| tcomp_model::replay::parse_failure(f, &table))
                .collect::<anyhow::Result<Vec<_>>>()?;
            let rows = tcomp_model::replay::replay_files_failing(&run, &image, &failures)
                .with_context(|| format!("in run file {}", run.display()))?;
            let n = rows.len();
            let (a, b) = (
                (from.clamp(0.0, 1.0) * n as f64) as usize,
                (to.clamp(0.0, 1.0) * n as f64) as usize,
            );
            let res = tcomp_model::replay::residuals(&table, &rows, &model, a, b);
            let flags = tcomp_model::replay::flag_counts(&rows, a, b);
            if json {
                println!(
                    "{}",
                    serde_json::json!({"rows": n, "scored_rows": [a, b], "failed_sensors": fail_sensor, "channels": res, "status_rows": flags, "notes": notes})
                );
            } else {
                println!("{} samples compensated; scored rows {a}..{b}", n);
                for note in &notes {
                    println!("  note: {note}");
                }
                for r in &res {
                    println!(
                        "  {}: about the run's reference (what the board compensates): MAE {:.2} µm, RMS {:.2} µm (uncompensated {:.2}), peak {:.2} µm, RMS reduction {:.1} %",
                        r.column, r.mae_um, r.rms_um, r.uncompensated_rms_um, r.peak_um, r.reduction_pct
                    );
                    println!(
                        "  {}: about the block's own mean (an operator who re-zeroes): RMS {:.2} µm (uncompensated {:.2}), reduction {:.1} %",
                        r.column, r.rms_about_mean_um, r.uncompensated_rms_about_mean_um, r.reduction_about_mean_pct
                    );
                    println!(
                        "  {}: never worse than no compensation: {}",
                        r.column,
                        if r.never_worse {
                            "yes"
                        } else {
                            "NO — this block is worse with the board"
                        }
                    );
                }
                println!(
                    "  status rows: {} valid, {} out of envelope, {} clamped, {} rate limited, {} stale, {} sensor fault, {} degraded",
                    flags.valid, flags.out_of_envelope, flags.clamped, flags.rate_limited, flags.stale, flags.sensor_fault, flags.degraded
                );
            }
        }
        Command::Upload {
            image,
            link,
            rollback,
            json,
        } => {
            let bytes = std::fs::read(&image)
                .map_err(|e| anyhow::anyhow!("reading {}: {e}", image.display()))?;
            let commit = if rollback {
                tcomp_link::board_link::Commit::Rollback
            } else {
                tcomp_link::board_link::Commit::NewerOnly
            };
            let s = tcomp_link::board_link::upload(&mut link.open()?, &bytes, commit)?;
            if json {
                println!("{}", serde_json::to_string(&s)?);
            } else {
                println!(
                    "uploaded {} bytes; the board serves model version {} crc {}",
                    s.bytes, s.model_version, s.model_crc
                );
                if !s.sensors_not_on_board.is_empty() {
                    println!(
                        "  model sensor(s) {:?}: their ROM codes are on none of the board's channels; it serves without them (fallback or held) until they are on the bus",
                        s.sensors_not_on_board
                    );
                }
            }
        }
        Command::Record {
            link,
            out,
            interval_s,
            samples,
            append,
        } => {
            anyhow::ensure!(
                interval_s > 0.0 && interval_s.is_finite(),
                "--interval-s must be positive"
            );
            let n = tcomp_link::board_link::record(
                &mut link.open()?,
                &out,
                std::time::Duration::from_secs_f64(interval_s),
                samples,
                append,
            )?;
            println!("recorded {n} samples to {}", out.display());
        }
        Command::Report {
            run,
            image,
            select,
            out,
            json,
        } => {
            let files = tcomp_model::plots::report(&run, image.as_deref(), select, &out)?;
            if json {
                println!("{}", serde_json::json!({ "files": files }));
            } else {
                for f in &files {
                    println!("wrote {}", f.display());
                }
            }
        }
        Command::Golden { out, steps, seed } => {
            let n = tcomp_model::export::golden(&out, steps, seed)?;
            println!("wrote {} ({n} bytes, {steps} steps)", out.display());
        }
        Command::Select(args) => cli::select::main(args)?,
        Command::Fit(args) => cli::fit::main(args)?,
        Command::Sim(args) => cli::sim::main(args)?,
        Command::Diagnose(args) => cli::diagnose::main(args)?,
        Command::Geometry(args) => cli::geometry::main(args)?,
        Command::Info { run, json } => {
            let r = tcomp_data::runcsv::Run::read(&run)?;
            if json {
                let v = serde_json::json!({"rows": r.rows(), "columns": r.columns, "meta": r.meta_map()});
                println!("{v}");
            } else {
                println!(
                    "{}: {} rows, columns {}",
                    run.display(),
                    r.rows(),
                    r.columns.join(",")
                );
            }
        }
    }
    Ok(())
}

/// `tcomp export --geometry`: read `geometry table --json`'s polynomial,
/// find its sensors' board channels (the run's T_ columns, by name) and
/// its X, Y, Z position slots (the model's axes of those names, else the
/// first slots the model does not use), quantise it and report the cost.
fn geometry_section(
    path: &std::path::Path,
    float: &thermocomp_core::float::FloatModel,
    run: Option<&std::path::Path>,
    tool_max_mm: f64,
    origin: &str,
    max_correction_um: f64,
) -> anyhow::Result<tcomp_model::export::GeometrySection> {
    use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let poly: tcomp_geometry::volumetric::VolumetricPoly =
        serde_json::from_str(&text).map_err(|e| {
            anyhow::anyhow!(
                "{}: not a `tcomp geometry table --json` output: {e}",
                path.display()
            )
        })?;
    let mut channels = Vec::new();
    if !poly.sensors.is_empty() {
        let run = run.ok_or_else(|| {
            anyhow::anyhow!(
                "{}: the volumetric polynomial reads sensor(s) {}: --run <csv> gives their board channels",
                path.display(),
                poly.sensors.join(", ")
            )
        })?;
        let columns: Vec<String> = tcomp_data::runcsv::Run::read_with_temperatures(run)?
            .temperature_columns()
            .iter()
            .map(|c| c.to_string())
            .collect();
        for s in &poly.sensors {
            let want = if s.starts_with("T_") {
                s.clone()
            } else {
                format!("T_{s}")
            };
            let ch = columns
                .iter()
                .position(|c| *c == want || c == s)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "{}: sensor {s} of the volumetric polynomial is not among the T_ columns of {}",
                        path.display(),
                        run.display()
                    )
                })?;
            let ch = u8::try_from(ch)
                .ok()
                .filter(|&c| usize::from(c) < thermocomp_core::limits::MAX_SENSORS)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "sensor {s} is board channel {ch}; the board reads channels 0..=19"
                    )
                })?;
            channels.push(ch);
        }
    }
    let o: Vec<f64> = origin
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 3 && v.iter().all(|x| x.is_finite()))
        .ok_or_else(|| {
            anyhow::anyhow!("--geometry-origin-mm {origin:?}: expected three numbers x,y,z (mm)")
        })?;
    let mut slots = [0u8; 3];
    let mut used: Vec<usize> = Vec::new();
    for (k, name) in ["X", "Y", "Z"].iter().enumerate() {
        if let Some(i) = float
            .axes
            .iter()
            .position(|a| a.name.eq_ignore_ascii_case(name))
        {
            slots[k] = i as u8;
            used.push(i);
        }
    }
    for (k, name) in ["X", "Y", "Z"].iter().enumerate() {
        if !float.axes.iter().any(|a| a.name.eq_ignore_ascii_case(name)) {
            let free = (0..thermocomp_core::limits::MAX_AXES)
                .find(|i| *i >= float.axes.len() && !used.contains(i))
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "no free PLC position slot for axis {name} of the volumetric section"
                    )
                })?;
            slots[k] = free as u8;
            used.push(free);
        }
    }
    let opts = BoardOptions {
        channels,
        slots,
        origin_mm: [o[0], o[1], o[2]],
        tool_max_mm,
        max_correction_um,
    };
    let v = quantize(&poly, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let report = quantisation_report(&poly, &v, &opts);
    Ok((v, report))
}

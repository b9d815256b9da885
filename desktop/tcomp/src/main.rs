//! `tcomp`: from calibration runs to a model image on the board. This crate
//! only parses the command line and hands each subcommand to the library
//! crates (`tcomp-data`, `-model`, `-geometry`, `-thermal`, `-link`); the
//! per-command argument structs and their glue are in `cli/`.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

mod cli;
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
    #[command(after_help = cli::export::EXAMPLE)]
    Export(cli::export::ExportArgs),
    /// The board's output for a run, computed by the desktop core (bit-exact
    /// with the firmware), and its error against the measured channels.
    #[command(after_help = cli::replay::EXAMPLE)]
    Replay(cli::replay::ReplayArgs),
    /// Send a model image to a board over Modbus RTU and check it serves it.
    Upload {
        /// The model image (`tcomp export -o`).
        image: std::path::PathBuf,
        #[command(flatten)]
        link: LinkArgs,
        /// Commit even if the board runs this or a newer model version (going back on purpose).
        #[arg(long)]
        rollback: bool,
        #[command(flatten)]
        unlock: cli::keys::UnlockArgs,
        /// Send it even if the board has no sensor for some model sensor
        /// now (it serves without them: fallback or held).
        #[arg(long)]
        allow_missing_sensors: bool,
        /// Print the result as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write a new model-signing key pair (Ed25519) for `export --sign`.
    Keygen(cli::keys::KeygenArgs),
    /// Give a board its own unlock key and the public key its models must be
    /// signed with; without --new-unlock-key or --signing-key, show its key state.
    Commission {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        args: cli::keys::CommissionArgs,
    },
    /// Poll a board over Modbus RTU and write (or extend) a run CSV.
    Record {
        #[command(flatten)]
        link: LinkArgs,
        /// The run CSV to write.
        #[arg(short, long)]
        out: std::path::PathBuf,
        /// Seconds between samples.
        #[arg(long, default_value_t = 1.0)]
        interval_s: f64,
        /// Number of samples to record.
        #[arg(long, default_value_t = 10)]
        samples: usize,
        /// Continue an existing file (same board, same columns).
        #[arg(long)]
        append: bool,
        /// The DS18B20 beside the probe (T01…T20) whose drift `dprobe_um`
        /// has removed (default: the board's holding registers 42–43).
        #[arg(long, value_name = "COLUMN", requires = "probe_drift_um_per_k")]
        probe_channel: Option<String>,
        /// The probe's drift, µm/K (`tcomp fit --probe-drift` estimates it).
        #[arg(
            long,
            value_name = "UM_PER_K",
            requires = "probe_channel",
            allow_hyphen_values = true
        )]
        probe_drift_um_per_k: Option<f64>,
    },
    /// SVG plots: temperatures, measured error vs the board's correction,
    /// residual before/after, and the sensor clusters.
    Report {
        /// The run CSV to plot.
        run: std::path::PathBuf,
        /// Model image: adds the error and residual plots (the board's output, via replay).
        #[arg(long)]
        image: Option<std::path::PathBuf>,
        /// Add the K-means++ cluster map of `select`.
        #[arg(long)]
        select: bool,
        /// Folder for the SVG files (created if missing).
        #[arg(short, long)]
        out: std::path::PathBuf,
        /// Print the written files as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write golden vectors (demo model, inputs, host outputs) for the board's self-test.
    Golden {
        /// The golden-vector file to write.
        #[arg(short, long)]
        out: std::path::PathBuf,
        /// Compensator steps to record.
        #[arg(long, default_value_t = 2000)]
        steps: u32,
        /// Seed of the demo model and its inputs.
        #[arg(long, default_value_t = 99)]
        seed: u64,
    },
    /// Temperature-sensitive points: K-means++ groups, correlation scores, best sensor per group.
    Select(cli::select::SelectArgs),
    /// Fit MLR and GA-BPN models per channel; validate on held-out runs or time blocks.
    #[command(after_help = cli::fit::EXAMPLE)]
    Fit(cli::fit::FitArgs),
    /// Simulate a machine's thermal behaviour under a duty cycle into a run CSV.
    Sim(cli::sim::SimArgs),
    /// Diagnose the sim-to-real gap of measured runs against a nominal machine model.
    #[command(after_help = cli::diagnose::EXAMPLE)]
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// Geometric errors: simulate or identify the 21 errors from 14 displacement lines.
    Geometry(cli::geometry::GeometryArgs),
    /// Print a run file's summary (rows, columns, metadata).
    Info {
        /// The run CSV.
        run: std::path::PathBuf,
        /// Print `{"rows", "columns", "meta"}` as JSON.
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
    /// Serial baud rate.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// The board's Modbus unit (slave) address.
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

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Export(args) => cli::export::main(args)?,
        Command::Replay(args) => cli::replay::main(args)?,
        Command::Upload {
            image,
            link,
            rollback,
            unlock,
            allow_missing_sensors,
            json,
        } => {
            let key = unlock.key()?.ok_or_else(|| {
                anyhow::anyhow!(
                    "give the board's unlock key: --unlock-key or TCOMP_UNLOCK_KEY (set at commissioning: tcomp commission --new-unlock-key)"
                )
            })?;
            let bytes = std::fs::read(&image)
                .map_err(|e| anyhow::anyhow!("reading {}: {e}", image.display()))?;
            let commit = if rollback {
                tcomp_link::board_link::Commit::Rollback
            } else {
                tcomp_link::board_link::Commit::NewerOnly
            };
            let opts = tcomp_link::board_link::UploadOptions {
                commit,
                unlock_key: key,
                allow_missing_sensors,
            };
            let s = tcomp_link::board_link::upload(&mut link.open()?, &bytes, &opts)?;
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
            probe_channel,
            probe_drift_um_per_k,
        } => {
            anyhow::ensure!(
                interval_s > 0.0 && interval_s.is_finite(),
                "--interval-s must be positive"
            );
            let drift = match (probe_channel, probe_drift_um_per_k) {
                (Some(c), Some(k)) => {
                    let channel = c
                        .strip_prefix('T')
                        .and_then(|n| n.parse::<usize>().ok())
                        .filter(|n| (1..=20).contains(n))
                        .ok_or_else(|| {
                            anyhow::anyhow!("--probe-channel {c}: expected T01 … T20")
                        })?;
                    Some(tcomp_link::board_link::ProbeDriftSetup {
                        channel: channel - 1,
                        nm_per_k: tcomp_model::probe_drift::register_value(k)?,
                    })
                }
                _ => None,
            };
            let n = tcomp_link::board_link::record_with(
                &mut link.open()?,
                &out,
                std::time::Duration::from_secs_f64(interval_s),
                samples,
                append,
                drift,
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
        Command::Keygen(args) => cli::keys::keygen(args)?,
        Command::Commission { link, args } => cli::keys::commission_board(link.open()?, args)?,
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
                if r.meta.is_empty() {
                    println!("no metadata (`# key: value` lines before the header)");
                } else {
                    println!("metadata:");
                }
                for (k, v) in &r.meta {
                    println!("  {k}: {v}");
                }
            }
        }
    }
    Ok(())
}

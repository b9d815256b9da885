//! `tcomp`: from calibration runs to a model image on the board.
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "tcomp",
    version,
    about = "thermocomp desktop tools: record, select, fit, export, upload, simulate, diagnose"
)]
struct Cli {
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
        #[arg(long, default_value_t = 1)]
        seed: u64,
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
    Select(tcomp::select::SelectArgs),
    /// Fit MLR and GA-BPN models per channel; validate on held-out runs or time blocks.
    Fit(tcomp::fit::cli::FitArgs),
    /// Simulate a machine's thermal behaviour under a duty cycle into a run CSV.
    Sim(tcomp::sim::cli::SimArgs),
    /// Diagnose the sim-to-real gap of measured runs against a nominal machine model.
    Diagnose(tcomp::diagnose::cli::DiagnoseArgs),
    /// Print a run file's summary (rows, columns, metadata).
    Info {
        run: std::path::PathBuf,
        #[arg(long)]
        json: bool,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Export { demo, seed, out, json } => {
            anyhow::ensure!(demo, "say what to export: --demo (fitted models: see `tcomp fit --out`)");
            let summary = tcomp::export::export(&thermocomp_core::float::demo_model(seed), &out)?;
            tcomp::export::print_summary(&summary, &out, json);
        }
        Command::Golden { out, steps, seed } => {
            let n = tcomp::export::golden(&out, steps, seed)?;
            println!("wrote {} ({n} bytes, {steps} steps)", out.display());
        }
        Command::Select(args) => tcomp::select::main(args)?,
        Command::Fit(args) => tcomp::fit::cli::main(args)?,
        Command::Sim(args) => tcomp::sim::cli::main(args)?,
        Command::Diagnose(args) => tcomp::diagnose::cli::main(args)?,
        Command::Info { run, json } => {
            let r = tcomp::runcsv::Run::read(&run)?;
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

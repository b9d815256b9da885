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

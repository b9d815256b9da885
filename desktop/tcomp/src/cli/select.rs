//! `tcomp select`: its arguments and output.

use anyhow::Result;

use tcomp_data::runcsv::Run;
use tcomp_model::select::{print_selection, select};

/// Command-line arguments of `tcomp select`.
#[derive(clap::Args, Debug, Clone)]
pub struct SelectArgs {
    /// Run CSVs (series are concatenated).
    #[arg(required = true)]
    pub runs: Vec<std::path::PathBuf>,
    /// Number of sensor groups m.
    #[arg(long, default_value_t = 5)]
    pub groups: usize,
    /// Seed of the K-means++ start.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print the selection as JSON (`chosen` is what `fit --sensors-from` reads).
    #[arg(long)]
    pub json: bool,
}

/// `tcomp select`.
pub fn main(args: SelectArgs) -> Result<()> {
    let runs = args
        .runs
        .iter()
        .map(|p| {
            let mut run = Run::read_with_temperatures(p)?;
            super::sanity::require_rows(
                &p.display().to_string(),
                &run,
                "select",
                "a correlation over fewer rows says nothing",
            )?;
            // Correlations are taken on rises from the run's start.
            if let Some(note) = run.errors_as_rises(&p.display().to_string()) {
                eprintln!("note: {note}");
            }
            Ok(run)
        })
        .collect::<Result<Vec<_>>>()?;
    let s = select(&runs, args.groups, args.seed)?;
    if args.json {
        println!("{}", serde_json::to_string(&s)?);
    } else {
        print_selection(&s);
    }
    Ok(())
}

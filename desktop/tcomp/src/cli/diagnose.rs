//! `tcomp diagnose <machine.toml|fit> <runs...> [--json] [--report out.md]`

use anyhow::Result;
use std::path::PathBuf;

use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{diagnose, render, Options};
use tcomp_thermal::sim::Machine;

/// `diagnose`'s long help: an example.
pub const EXAMPLE: &str = "Example:
  tcomp diagnose examples/machines/turning-center-16.toml run1.csv run2.csv --report out/diag.md
  tcomp diagnose fit run1.csv run2.csv --json   (no machine file; no spindle_rpm needed)";

#[derive(clap::Args, Debug)]
pub struct DiagnoseArgs {
    /// Nominal machine description (TOML), or `fit` to identify the nominal
    /// model from the runs themselves (no machine file).
    pub machine: String,
    /// Measured runs (run CSV).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Print `{"effects": [...], "where": {...}}`.
    #[arg(long)]
    pub json: bool,
    /// Write a markdown report here (plus `<name>-channels.svg` and
    /// `<name>-phases.svg` beside it when an effect is selected).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Fraction of time (one run) or of runs (several) used to fit.
    #[arg(long, default_value_t = 0.6)]
    pub fit_fraction: f64,
    /// Only try these effects (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Take the machine file as exact: no calibration within its
    /// tolerances (by default every design value may move within its
    /// tolerance, `[tolerance]` in the file or ±25 %, on the fit rows, and
    /// every candidate effect is judged with the same freedom).
    #[arg(long)]
    pub exact: bool,
    /// Accepted for compatibility; no effect (the default calibrates).
    #[arg(long, hide = true)]
    pub calibrate: bool,
}

pub fn main(a: DiagnoseArgs) -> Result<()> {
    anyhow::ensure!(
        a.fit_fraction > 0.05 && a.fit_fraction < 0.95,
        "--fit-fraction = {}: allowed between 0.05 and 0.95",
        a.fit_fraction
    );
    if let Some(t) = a.threads {
        anyhow::ensure!((1..=1024).contains(&t), "--threads = {t}: allowed 1..=1024");
    }
    let runs = a
        .runs
        .iter()
        .map(|p| Run::read_with_temperatures(p).map(|r| (p.display().to_string(), r)))
        .collect::<Result<Vec<_>>>()?;
    let mut opt = Options {
        fit_fraction: a.fit_fraction,
        only: a.only.clone(),
        exact: a.exact,
        calibrate: a.calibrate,
        ..Options::default()
    };
    if let Some(t) = a.threads {
        opt.threads = t.max(1);
    }
    for o in &opt.only {
        anyhow::ensure!(
            tcomp_thermal::sim::ALL_EFFECT_NAMES.contains(&o.as_str()) || o == "periodic",
            "--only: unknown effect `{o}`"
        );
    }
    let d = if a.machine == "fit" {
        tcomp_thermal::diagnose::fitmode::diagnose_fit(&runs, &opt)?
    } else {
        let machine = Machine::load(std::path::Path::new(&a.machine))?;
        let no_rpm: Vec<&str> = runs
            .iter()
            .filter(|(_, r)| r.col("spindle_rpm").is_none())
            .map(|(n, _)| n.as_str())
            .collect();
        anyhow::ensure!(
            no_rpm.is_empty(),
            "{}: no `spindle_rpm` column, and a machine file's heat sources are driven by the spindle speed: `tcomp diagnose fit {}` identifies a nominal model from the runs themselves (no spindle_rpm needed)",
            no_rpm.join(", "),
            a.runs
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(" ")
        );
        diagnose(&machine, &runs, &opt)?
    };
    let names: Vec<String> = runs.iter().map(|r| r.0.clone()).collect();
    if let Some(p) = &a.report {
        // As `report -o` does: the report's folder is made if missing.
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| anyhow::anyhow!("--report: creating {}: {e}", dir.display()))?;
        }
        render::write_report(&d, &names, p)?;
    }

    if a.json {
        println!("{}", d.to_json());
    } else {
        for m in &d.missing {
            println!("missing: {m}");
        }
        for n in d
            .notes
            .iter()
            .filter(|n| n.starts_with("machine file calibrated"))
        {
            println!("{n}");
        }
        print_findings(&d);
        if !d.untestable.is_empty() {
            let names: Vec<&str> = d.untestable.iter().map(|(n, _)| n.as_str()).collect();
            println!(
                "not testable from these runs (why: --json or --report): {}",
                names.join("; ")
            );
        }
        if a.machine == "fit" {
            println!(
                "({} candidate effects tried against the identified nominal, {:.2} s)",
                d.sims, d.seconds
            );
        } else {
            println!("({} simulations, {:.2} s)", d.sims, d.seconds);
        }
    }
    Ok(())
}

/// The ranked findings, effects and design values alike, one line each.
fn print_findings(d: &tcomp_thermal::diagnose::Diagnosis) {
    if !d.ambiguous.is_empty() {
        println!(
            "ambiguous: the held-out data cannot separate {} (nothing is named as the cause)",
            d.ambiguous.join(", ")
        );
        for s in &d.separate_by {
            println!("  to separate {s}");
        }
    } else if d.findings.is_empty() {
        println!("no candidate effect is supported by the data");
    }
    for (i, f) in d.findings.iter().enumerate() {
        let p = f.params_json();
        let what = match p.get("meaning").and_then(|m| m.as_str()) {
            Some(m) => format!(
                "{}: design {} → fitted {} (×{}): {m}",
                p["parameter"].as_str().unwrap_or(""),
                p["design"],
                p["fitted"],
                p["factor"]
            ),
            None => p.to_string(),
        };
        println!(
            "{}. {} {} — held-out gap {} µm → {} µm, {} °C → {} °C, ΔBIC {:.1}",
            i + 1,
            f.name,
            what,
            f.gap_um.map_or("–".into(), |g| format!("{:.3}", g.0 .0)),
            f.gap_um.map_or("–".into(), |g| format!("{:.3}", g.1 .0)),
            f.gap_c.map_or("–".into(), |g| format!("{:.3}", g.0 .0)),
            f.gap_c.map_or("–".into(), |g| format!("{:.3}", g.1 .0)),
            f.dbic
        );
    }
}

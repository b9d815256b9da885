//! `tcomp diagnose <machine.toml|fit> <runs...> [--json] [--report out.md]`

use anyhow::{Context, Result};
use std::path::PathBuf;

use super::{diagnose, nominal, report_md, Options};
use crate::runcsv::Run;
use crate::sim::Machine;

#[derive(clap::Args, Debug)]
pub struct DiagnoseArgs {
    /// Nominal machine description (TOML), or `fit` to fit a simple nominal
    /// model to the first part of the (first) run when no description exists.
    pub machine: String,
    /// Measured runs (run CSV).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Print `{"effects": [...], "where": {...}}`.
    #[arg(long)]
    pub json: bool,
    /// Write a markdown report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Fraction of time (one run) or of runs (several) used to fit.
    #[arg(long, default_value_t = 0.6)]
    pub fit_fraction: f64,
    /// With `fit`: fraction of the run used to fit the nominal model.
    #[arg(long, default_value_t = 0.3)]
    pub nominal_fraction: f64,
    /// With `fit`: save the fitted nominal machine description here.
    #[arg(long)]
    pub save_nominal: Option<PathBuf>,
    /// Only try these effects (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn main(a: DiagnoseArgs) -> Result<()> {
    anyhow::ensure!(
        a.fit_fraction > 0.05 && a.fit_fraction < 0.95,
        "--fit-fraction = {}: allowed between 0.05 and 0.95",
        a.fit_fraction
    );
    if a.machine == "fit" {
        // Checked before the fit: the nominal part lies inside the
        // effect-fit part (first --fit-fraction); the held-out rest was
        // used for neither.
        anyhow::ensure!(
            a.nominal_fraction >= 0.05 && a.nominal_fraction <= a.fit_fraction,
            "--nominal-fraction = {}: allowed 0.05..=--fit-fraction ({})",
            a.nominal_fraction,
            a.fit_fraction
        );
    }
    if let Some(t) = a.threads {
        anyhow::ensure!((1..=1024).contains(&t), "--threads = {t}: allowed 1..=1024");
    }
    let runs = a
        .runs
        .iter()
        .map(|p| Run::read_with_temperatures(p).map(|r| (p.display().to_string(), r)))
        .collect::<Result<Vec<_>>>()?;
    let machine = if a.machine == "fit" {
        let m = nominal::fit_nominal(&runs[0].1, a.nominal_fraction)?;
        if let Some(p) = &a.save_nominal {
            std::fs::write(p, m.to_toml()?)
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
        m
    } else {
        Machine::load(std::path::Path::new(&a.machine))?
    };
    let mut opt = Options {
        fit_fraction: a.fit_fraction,
        only: a.only.clone(),
        ..Options::default()
    };
    if let Some(t) = a.threads {
        opt.threads = t.max(1);
    }
    for o in &opt.only {
        anyhow::ensure!(
            crate::sim::EFFECT_NAMES.contains(&o.as_str()),
            "--only: unknown effect `{o}`"
        );
    }
    let d = diagnose(&machine, &runs, &opt)?;
    let names: Vec<String> = runs.iter().map(|r| r.0.clone()).collect();
    if let Some(p) = &a.report {
        std::fs::write(p, report_md(&d, &names))
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if a.json {
        println!("{}", d.to_json());
    } else {
        if d.findings.is_empty() {
            println!("no candidate effect is supported by the data");
        }
        for (i, f) in d.findings.iter().enumerate() {
            println!(
                "{}. {} {} — held-out gap {} µm → {} µm, {} °C → {} °C, ΔBIC {:.1}",
                i + 1,
                f.name,
                f.params_json(),
                f.gap_um.map_or("–".into(), |g| format!("{:.3}", g.0 .0)),
                f.gap_um.map_or("–".into(), |g| format!("{:.3}", g.1 .0)),
                f.gap_c.map_or("–".into(), |g| format!("{:.3}", g.0 .0)),
                f.gap_c.map_or("–".into(), |g| format!("{:.3}", g.1 .0)),
                f.dbic
            );
        }
        println!("({} simulations, {:.2} s)", d.sims, d.seconds);
    }
    Ok(())
}

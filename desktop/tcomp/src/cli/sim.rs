//! `tcomp sim <machine.toml> --duty <cycle> [--effect NAME=PARAMS ...] [--seed N] [--hours H] -o run.csv`

use anyhow::Result;
use std::path::PathBuf;

use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// Machine description (TOML, see examples/machines/README.md).
    pub machine: PathBuf,
    /// Duty cycle: TOML segment list or CSV (time_s, spindle_rpm, feed_activity, coolant_on, ambient_c).
    #[arg(long)]
    pub duty: PathBuf,
    /// Switch on an effect: NAME=k1:v1,k2:v2 (repeatable), e.g. convection=h:12.
    #[arg(long = "effect")]
    pub effects: Vec<String>,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated duration [h] (default: the duty's length; the last segment holds).
    #[arg(long)]
    pub hours: Option<f64>,
    /// Output sample period [s] (multiple of the 1 s step; default: the duty's or 1 s).
    #[arg(long)]
    pub sample_period: Option<f64>,
    /// Leave out noise and quantisation.
    #[arg(long)]
    pub no_noise: bool,
    /// Output run CSV.
    #[arg(short, long)]
    pub out: PathBuf,
}

pub fn main(a: SimArgs) -> Result<()> {
    let m = Machine::load(&a.machine)?;
    let duty = Duty::load(&a.duty)?;
    let effects = a
        .effects
        .iter()
        .map(|s| Effect::parse(s))
        .collect::<Result<Vec<_>>>()?;
    let t = std::time::Instant::now();
    let run = sim_run(
        &m,
        &duty,
        &SimOptions {
            effects,
            seed: a.seed,
            hours: a.hours,
            sample_period_s: a.sample_period,
            noise: !a.no_noise,
        },
    )?;
    let el = t.elapsed().as_secs_f64();
    run.write(&a.out)?;
    println!(
        "wrote {} ({} rows, {} sensors, {} directions) in {:.3} s",
        a.out.display(),
        run.rows(),
        m.sensor_cols.len(),
        m.dir_cols.len(),
        el
    );
    Ok(())
}

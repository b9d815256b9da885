//! `tcomp replay`: the board's output for a run, computed by the desktop
//! core, and its error against the measured channels.

use anyhow::Context;
use tcomp_model::reference_replay::ReferenceArgs;

#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The run CSV to replay.
    pub run: std::path::PathBuf,
    /// The model image (`tcomp export -o`).
    pub image: std::path::PathBuf,
    /// Score rows from this fraction of the run (e.g. 0.6 for the FL_THERMAL test block).
    #[arg(long, default_value_t = 0.0)]
    pub from: f64,
    /// Score rows up to this fraction of the run.
    #[arg(long, default_value_t = 1.0)]
    pub to: f64,
    /// Lose a sensor from a time on: `T_t4@1800` (seconds of the run) or
    /// `T_t4@60%` (from that fraction of the rows); repeatable.
    #[arg(long = "fail-sensor", value_name = "NAME@TIME")]
    pub fail_sensor: Vec<String>,
    /// Probe references at a gauge and operator re-zeros (issue 28).
    #[command(flatten)]
    pub reference: ReferenceFlags,
    /// Print the figures as JSON (`channels`, `status_rows`, `notes`).
    #[arg(long)]
    pub json: bool,
}

/// `tcomp replay`'s flags for references and re-zeros; the library takes
/// them as [`ReferenceArgs`].
#[derive(clap::Args, Debug, Clone)]
pub struct ReferenceFlags {
    /// Simulate a probe reference at the gauge every this long (`1h`,
    /// `30min`, `900s`, `900`), from the run's start.
    #[arg(long = "reference-every", value_name = "DURATION")]
    pub every: Option<String>,
    /// Shift the clock schedule: the first reference this long after the
    /// run's start, then every `--reference-every` (`10min`; below the
    /// interval). 0 (the default): the first at one interval. Clock phase
    /// moves the figures a lot (a reference minutes before a speed change
    /// teaches little): compare schedules over several phases.
    #[arg(long = "reference-phase", value_name = "DURATION")]
    pub phase: Option<String>,
    /// Also simulate a reference this long after every change of the run's
    /// `spindle_rpm` (a probing cycle triggered by the operating state
    /// rather than the clock), e.g. `10min`.
    #[arg(long = "reference-after-change", value_name = "DURATION")]
    pub after_change: Option<String>,
    /// σ of the simulated probe noise, µm (also the rule's σ_r unless
    /// `--reference-param sigma_ref_um=` says otherwise).
    #[arg(long = "reference-noise-um", default_value_t = 0.3)]
    pub noise_um: f64,
    /// Corrupt a share of the references: `5%:50` = 5 % of them +50 µm.
    #[arg(long = "reference-outliers", value_name = "SHARE%:UM")]
    pub outliers: Option<String>,
    /// Seed of the simulated noise and outliers.
    #[arg(long = "reference-seed", default_value_t = 1)]
    pub seed: u64,
    /// Operator re-zero (touch-off) at this time: seconds of the run or a
    /// percentage of its rows (`60%`); repeatable.
    #[arg(
        long = "reference-at",
        visible_alias = "rezero-at",
        value_name = "TIME"
    )]
    pub rezero_at: Vec<String>,
    /// A parameter of the update rule, NAME=VALUE: sigma_ref_um,
    /// sigma_bias_um, tau_bias_h, sigma_rate_um_h, tau_rate_h, gate_k,
    /// gate_abs_um, max_step_um, max_bias_um, max_rate_um_h; repeatable.
    #[arg(long = "reference-param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// Write every row (time, per direction: measured, model, served with
    /// references) to this CSV.
    #[arg(long = "reference-dump", value_name = "CSV")]
    pub dump: Option<std::path::PathBuf>,
    /// Probe when the board asks (issue 51), by the board's own rule
    /// (math core `ask`, bit for bit): a set time after a spindle-speed
    /// change (the run's `spindle_rpm`; without it the interval rule only)
    /// and whenever the longest interval has passed since the last accepted
    /// reference. The simulated PLC probes at the next sample; a refused
    /// reading leaves the request raised. Not with a clock schedule.
    #[arg(
        long = "reference-when-asked",
        conflicts_with_all = ["every", "phase", "after_change"]
    )]
    pub when_asked: bool,
    /// The board asks this long after a spindle-speed change (default
    /// 15min; 0: never for a change).
    #[arg(long = "ask-settle", value_name = "DURATION", requires = "when_asked")]
    pub ask_settle: Option<String>,
    /// The board asks when this long has passed since the last accepted
    /// reference (default 70min; 0: never).
    #[arg(
        long = "ask-interval",
        value_name = "DURATION",
        requires = "when_asked"
    )]
    pub ask_interval: Option<String>,
    /// A spindle-speed change is a move of at least this, rpm (default 500).
    #[arg(long = "ask-speed-step", value_name = "RPM", requires = "when_asked")]
    pub ask_speed_step: Option<u16>,
}

impl TryFrom<ReferenceFlags> for ReferenceArgs {
    type Error = anyhow::Error;
    fn try_from(f: ReferenceFlags) -> anyhow::Result<ReferenceArgs> {
        let when_asked = f
            .when_asked
            .then(|| {
                tcomp_model::reference_replay::ask_params(
                    f.ask_settle.as_deref(),
                    f.ask_interval.as_deref(),
                    f.ask_speed_step,
                )
            })
            .transpose()?;
        Ok(ReferenceArgs {
            every: f.every,
            phase: f.phase,
            after_change: f.after_change,
            noise_um: f.noise_um,
            outliers: f.outliers,
            seed: f.seed,
            rezero_at: f.rezero_at,
            params: f.params,
            dump: f.dump,
            when_asked,
        })
    }
}

/// `replay`'s long help: an example.
pub const EXAMPLE: &str = "Example:
  tcomp replay shift.csv model.img --from 0.6
  tcomp replay shift.csv model.img --fail-sensor T_spindle@1800 --json
  tcomp replay shift.csv model.img --from 0.6 --to 0.8 --reference-when-asked";

pub fn main(args: ReplayArgs) -> anyhow::Result<()> {
    let ReplayArgs {
        run,
        image,
        from,
        to,
        fail_sensor,
        reference,
        json,
    } = args;
    let reference = ReferenceArgs::try_from(reference)?;
    // Run file first, then image: each refusal names its own file.
    let mut table = tcomp_data::runcsv::Run::read_with_temperatures(&run)?;
    // Scored as rises from the run's start, as the board compensates.
    let mut notes: Vec<String> = table
        .errors_as_rises(&run.display().to_string())
        .into_iter()
        .collect();
    let bytes =
        std::fs::read(&image).map_err(|e| anyhow::anyhow!("reading {}: {e}", image.display()))?;
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
    if flags.stale > 0 && table.col("spindle_rpm").is_none() {
        notes.push(format!(
            "{} row(s) are marked stale because {} has no spindle_rpm column: the board flags its inputs stale when the PLC's spindle speed is not fed, and the replay serves as the board would then (0 rpm); the corrections are computed all the same",
            flags.stale,
            run.display()
        ));
    }
    let refs = reference
        .is_active()
        .then(|| tcomp_model::reference_replay::score(&table, &rows, &model, &reference, a, b))
        .transpose()?;
    if json {
        let mut v = serde_json::json!({"rows": n, "scored_rows": [a, b], "failed_sensors": fail_sensor, "channels": res, "status_rows": flags, "notes": notes});
        if let Some(r) = &refs {
            v["references"] = serde_json::to_value(r)?;
        }
        println!("{v}");
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
            let mae = |v: Option<f64>| v.map_or("-".to_string(), |m| format!("{m:.2} µm"));
            println!(
                "  {}: beyond the training envelope (an input of the serving model past its range by more than the image's margin, {} raw; policy {}): {} rows ({:.1} %), MAE there {}; inside: MAE {}",
                r.column,
                r.envelope_margin_raw,
                r.envelope_policy,
                r.out_of_envelope_rows,
                100.0 * r.out_of_envelope_share,
                mae(r.out_of_envelope_mae_um),
                mae(r.in_envelope_mae_um)
            );
            if let Some(tau) = r.output_lag_s {
                println!("  {}: output low-pass {tau:.0} s (image)", r.column);
            }
            println!(
                "  {}: never worse than no compensation: {}",
                r.column,
                match (r.never_worse, r.never_worse_about_mean) {
                    (true, true) => "yes, about the run's reference and about the block's mean",
                    (true, false) => "about the run's reference yes; about the block's own mean NO (its reduction is negative: the board adds a varying error an operator who re-zeroes would see)",
                    (false, true) => "NO about the run's reference (this block is worse with the board); about the block's own mean yes",
                    (false, false) => "NO — this block is worse with the board, about the reference and about its mean",
                }
            );
        }
        println!(
            "  status rows: {} valid, {} out of envelope, {} clamped, {} rate limited, {} stale, {} sensor fault, {} degraded",
            flags.valid, flags.out_of_envelope, flags.clamped, flags.rate_limited, flags.stale, flags.sensor_fault, flags.degraded
        );
        if let Some(r) = &refs {
            r.print();
        }
    }
    Ok(())
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

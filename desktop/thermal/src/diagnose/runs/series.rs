//! Run files → the signals `diagnose fit` identifies its nominal model on,
//! read exactly as the run-CSV format defines them
//! (`docs/formats/run-csv.md`): `T_ambient` is the ambient input, every
//! other `T_<name>` column is a sensor, `d<name>_um` columns are measured
//! displacements, `spindle_rpm`, `feed_activity` and `coolant_on` are inputs
//! when present. Runs are block-averaged to at most `max_rows` rows and split
//! into interleaved time blocks: the fit blocks identify, the held-out blocks
//! score.

use anyhow::{bail, Result};

use tcomp_data::runcsv::{is_temperature_column, Run};
use tcomp_numerics::stats::block_means;

/// The reserved column of the ambient temperature (an input, never a node).
pub const AMBIENT_COLUMN: &str = "T_ambient";

/// Blocks per run; the held-out ones are `HELD_BLOCKS`. Interleaving lets an
/// effect that starts anywhere in a run be fitted on fit rows and scored on
/// held-out rows while every run (every duty cycle) is used by both parts.
pub const BLOCKS: usize = 5;
pub const HELD_BLOCKS: [usize; 2] = [1, 3];

/// One measured channel on the run's (decimated) grid.
#[derive(Clone, Debug)]
pub struct Signal {
    /// Column name as in the file (`T_T3`, `dx_um`).
    pub name: String,
    /// Values, NaN where the field was empty.
    pub values: Vec<f64>,
}

/// One run, on a uniform grid.
#[derive(Clone, Debug)]
pub struct RunData {
    pub name: String,
    /// Sample period after decimation [s].
    pub dt: f64,
    /// Rows of the file averaged into one row here.
    pub decimation: usize,
    /// Time of each row [s] (the first row of its block).
    pub time: Vec<f64>,
    pub rpm: Option<Vec<f64>>,
    pub feed: Option<Vec<f64>>,
    pub coolant: Option<Vec<f64>>,
    pub ambient: Option<Vec<f64>>,
    pub sensors: Vec<Signal>,
    /// Displacements re-zeroed to their start (µm).
    pub disps: Vec<Signal>,
    /// `true` for held-out rows.
    pub held: Vec<bool>,
}

impl RunData {
    pub fn rows(&self) -> usize {
        self.time.len()
    }
}

/// All runs of a diagnosis, with the channel names pooled over the runs.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub runs: Vec<RunData>,
    /// Sensor columns (union over runs, first-seen order).
    pub sensors: Vec<String>,
    /// Displacement columns (union over runs, first-seen order).
    pub disps: Vec<String>,
    pub has_rpm: bool,
    pub has_feed: bool,
    pub has_coolant: bool,
    pub has_ambient: bool,
    /// One line per missing input: what is missing and what that costs.
    pub missing: Vec<String>,
    pub notes: Vec<String>,
}

impl Dataset {
    /// Noise scale of a channel (°C or µm), pooled over runs.
    pub fn noise(&self, name: &str) -> f64 {
        let floor = if name.starts_with('d') { 0.01 } else { 0.005 };
        let mut acc = Vec::new();
        for r in &self.runs {
            for s in r.sensors.iter().chain(&r.disps) {
                if s.name == name {
                    acc.push(noise_scale(&s.values, floor));
                }
            }
        }
        if acc.is_empty() {
            return floor;
        }
        acc.sort_by(|a, b| a.total_cmp(b));
        acc[acc.len() / 2]
    }
}

/// Noise scale of a series from its second differences (a linear trend
/// cancels): trimmed RMS / √6, floored.
pub fn noise_scale(v: &[f64], floor: f64) -> f64 {
    let mut d: Vec<f64> = v
        .windows(3)
        .filter(|w| w.iter().all(|x| x.is_finite()))
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    if d.len() < 4 {
        return floor;
    }
    d.sort_by(|a, b| a.total_cmp(b));
    let keep = (d.len() as f64 * 0.95).ceil() as usize;
    let ms = d[..keep].iter().map(|x| x * x).sum::<f64>() / keep as f64;
    (ms / 6.0).sqrt().max(floor)
}

/// Values of a column, missing fields held from the last value (the first
/// valid value before it); `None` when the column is absent or empty.
fn held_column(run: &Run, name: &str) -> Option<Vec<f64>> {
    let c = run.col(name)?;
    let first = c.iter().flatten().next().copied()?;
    let mut last = first;
    Some(
        c.iter()
            .map(|v| {
                if let Some(x) = v {
                    last = *x;
                }
                last
            })
            .collect(),
    )
}

fn sensor_columns(run: &Run) -> Vec<String> {
    run.columns
        .iter()
        .filter(|c| is_temperature_column(c) && c.as_str() != AMBIENT_COLUMN)
        .cloned()
        .collect()
}

/// Which inputs every run carries (a column only some runs have is left out).
#[derive(Clone, Copy)]
struct Present {
    rpm: bool,
    feed: bool,
    coolant: bool,
    ambient: bool,
}

/// Channel names pooled over the runs read so far, and the notes.
#[derive(Default)]
struct Pooled {
    sensors: Vec<String>,
    disps: Vec<String>,
    notes: Vec<String>,
}

/// Read runs into a dataset. `max_rows`: block-average longer runs.
pub fn load(runs: &[(String, Run)], max_rows: usize) -> Result<Dataset> {
    if runs.is_empty() {
        bail!("no runs given");
    }
    let all = |name: &str| runs.iter().all(|(_, r)| r.col(name).is_some());
    let present = Present {
        rpm: all("spindle_rpm"),
        feed: all("feed_activity"),
        coolant: all("coolant_on"),
        ambient: all(AMBIENT_COLUMN),
    };
    let mut pooled = Pooled::default();
    let mut out = Vec::new();
    for (name, run) in runs {
        out.push(load_run(name, run, max_rows, present, &mut pooled)?);
    }
    let Pooled {
        mut sensors,
        mut disps,
        mut notes,
    } = pooled;
    if let Some(f) = out.iter().map(|r| r.decimation).max().filter(|f| *f > 1) {
        notes.push(format!(
            "runs block-averaged by up to {f} rows for identification"
        ));
    }
    let mut missing = leave_out_unusable(&mut out, &mut sensors, &mut disps);
    if sensors.is_empty() {
        bail!("no temperature sensor reads in at least half the rows of every run");
    }
    missing.extend(missing_inputs(runs, present));
    if disps.is_empty() {
        missing.push(
            "no displacement column (d<name>_um): every figure is in °C; nothing can be said in µm"
                .into(),
        );
    }
    Ok(Dataset {
        runs: out,
        sensors,
        disps,
        has_rpm: present.rpm,
        has_feed: present.feed,
        has_coolant: present.coolant,
        has_ambient: present.ambient,
        missing,
        notes,
    })
}

/// The median sampling period of a run [s], with a note when the rows are
/// not uniform.
fn median_period(name: &str, t: &[f64], notes: &mut Vec<String>) -> f64 {
    let mut diffs: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    diffs.sort_by(|a, b| a.total_cmp(b));
    let dt = diffs[diffs.len() / 2];
    let worst = diffs
        .iter()
        .map(|d| (d - dt).abs() / dt)
        .fold(0.0, f64::max);
    if worst > 0.1 {
        notes.push(format!(
            "{name}: sampling is not uniform (median {dt} s, worst deviation {:.0} %); rows treated as uniform",
            worst * 100.0
        ));
    }
    dt
}

/// A displacement as its rise against the run's start (the mean of its
/// first three valid samples; the format's reference, and an absolute
/// column is re-zeroed the same way).
fn rise_from_start(v: &[f64]) -> Vec<f64> {
    let first: Vec<f64> = v
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .take(3)
        .collect();
    let z = if first.is_empty() {
        0.0
    } else {
        first.iter().sum::<f64>() / first.len() as f64
    };
    v.iter().map(|x| x - z).collect()
}

/// One run on its decimated grid; its channel names join `pooled`.
fn load_run(
    name: &str,
    run: &Run,
    max_rows: usize,
    present: Present,
    pooled: &mut Pooled,
) -> Result<RunData> {
    let t = run.time_s();
    if t.len() < 20 {
        bail!("run {name}: needs at least 20 rows, has {}", t.len());
    }
    let dt = median_period(name, &t, &mut pooled.notes);
    let n = t.len();
    let f = n.div_ceil(max_rows.max(20)).max(1);
    let starts: Vec<usize> = (0..n).step_by(f).collect();
    // block mean over finite values (NaN when the block has none)
    let avg = |v: &[f64]| block_means(v, f);
    let raw = |c: &str| -> Vec<f64> {
        run.col(c)
            .map(|v| v.iter().map(|x| x.unwrap_or(f64::NAN)).collect())
            .unwrap_or_default()
    };
    let input = |c: &str, present: bool| -> Option<Vec<f64>> {
        if !present {
            return None;
        }
        Some(avg(&held_column(run, c).unwrap_or_else(|| vec![0.0; n])))
    };
    let mut run_sensors = Vec::new();
    for c in sensor_columns(run) {
        if !pooled.sensors.contains(&c) {
            pooled.sensors.push(c.clone());
        }
        run_sensors.push(Signal {
            values: avg(&raw(&c)),
            name: c,
        });
    }
    let absolute = run.meta("error_reference") == Some("absolute");
    let mut run_disps = Vec::new();
    for c in run.error_columns() {
        let c = c.to_string();
        if !pooled.disps.contains(&c) {
            pooled.disps.push(c.clone());
        }
        run_disps.push(Signal {
            values: avg(&rise_from_start(&raw(&c))),
            name: c,
        });
    }
    if absolute && !run_disps.is_empty() {
        pooled.notes.push(format!(
            "{name}: error_reference is absolute; displacements taken as rises from their first valid samples"
        ));
    }
    if run_sensors.is_empty() {
        bail!(
            "run {name}: no temperature sensor column (`T_<name>` other than `{AMBIENT_COLUMN}`)"
        );
    }
    let rows = starts.len();
    let held = (0..rows)
        .map(|k| HELD_BLOCKS.contains(&(k * BLOCKS / rows)))
        .collect();
    Ok(RunData {
        name: name.to_string(),
        dt: dt * f as f64,
        decimation: f,
        time: starts.iter().map(|&s| t[s]).collect(),
        rpm: input("spindle_rpm", present.rpm),
        feed: input("feed_activity", present.feed),
        coolant: input("coolant_on", present.coolant).map(|v| {
            v.into_iter()
                .map(|c| if c >= 0.5 { 1.0 } else { 0.0 })
                .collect()
        }),
        ambient: input(AMBIENT_COLUMN, present.ambient),
        sensors: run_sensors,
        disps: run_disps,
        held,
    })
}

/// Leave out every channel that is dead or stuck in some run
/// (`unusable_channel`): it cannot be identified there, so it is left out
/// of the whole diagnosis and said so, rather than failing the fit or
/// fitting a frozen value. Returns one line per channel left out.
fn leave_out_unusable(
    out: &mut [RunData],
    sensors: &mut Vec<String>,
    disps: &mut Vec<String>,
) -> Vec<String> {
    let mut sparse: Vec<(String, String, String)> = Vec::new();
    for r in out.iter() {
        let moving = r
            .sensors
            .iter()
            .filter(|s| crate::diagnose::signal::moves(&s.values))
            .count();
        let temps = r.sensors.iter().map(|s| (s, "°C", true));
        for (sig, unit, temp) in temps.chain(r.disps.iter().map(|s| (s, "µm", false))) {
            if sparse.iter().any(|x| x.0 == sig.name) {
                continue;
            }
            // a still channel is stuck only if some other temperature moves
            let others_move =
                moving > usize::from(temp && crate::diagnose::signal::moves(&sig.values));
            if let Some(why) =
                crate::diagnose::signal::unusable_channel(&sig.values, unit, others_move)
            {
                sparse.push((sig.name.clone(), r.name.clone(), why));
            }
        }
    }
    let kept = |n: &String| !sparse.iter().any(|x| &x.0 == n);
    sensors.retain(kept);
    disps.retain(kept);
    for r in out.iter_mut() {
        r.sensors.retain(|sig| kept(&sig.name));
        r.disps.retain(|sig| kept(&sig.name));
    }
    sparse
        .iter()
        .map(|(c, run, why)| format!(
            "{c} {why} of run {run} (identification rows): left out (a channel must read, and change, in at least half the rows of every run)"
        ))
        .collect()
}

/// One line per input not in every run: what is missing and what that costs.
fn missing_inputs(runs: &[(String, Run)], present: Present) -> Vec<String> {
    let any = |name: &str| runs.iter().any(|(_, r)| r.col(name).is_some());
    let partly = |c: &str| if any(c) { " in every run" } else { "" };
    let mut missing = Vec::new();
    if !present.rpm {
        missing.push(format!(
            "no spindle_rpm{}: the heat input is not observed, so each sensor is predicted from the other sensors and displacement from the sensors; speed nonlinearity and effects common to all sensors cannot be tested",
            partly("spindle_rpm")
        ));
    }
    if !present.ambient {
        missing.push(format!(
            "no {AMBIENT_COLUMN}{}: the room temperature is not an input, so its changes stay in the residual and ambient drift cannot be told from the room itself",
            partly(AMBIENT_COLUMN)
        ));
    }
    if !present.feed {
        missing.push(format!(
            "no feed_activity{}: heat from the axes is not an input; it is absorbed where it follows the spindle, else left in the residual",
            partly("feed_activity")
        ));
    }
    if !present.coolant {
        missing.push(format!(
            "no coolant_on{}: coolant switching is not an input; a periodic coolant/chiller drive is searched in each sensor's own spectrum",
            partly("coolant_on")
        ));
    }
    missing
}

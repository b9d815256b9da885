//! Measured runs → simulator inputs + measured channels matched to the
//! machine's sensors and directions, decimated for fitting speed.

use anyhow::{bail, Result};

use crate::sim::{Duty, Inputs, Machine};
use tcomp_data::runcsv::Run;
use tcomp_numerics::stats::block_means;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// Temperature sensor (index into machine sensors).
    Temp(usize),
    /// Displacement direction (index into machine directions).
    Disp(usize),
}

#[derive(Clone, Debug)]
pub struct Channel {
    pub name: String,
    pub kind: Kind,
    /// Measured values on the (decimated) grid, NaN where missing.
    /// Displacements are re-zeroed to their value at the start.
    pub meas: Vec<f64>,
    /// Noise scale estimated from the data (°C or µm).
    pub s: f64,
}

#[derive(Clone, Debug)]
pub struct Prepared {
    pub name: String,
    pub inputs: Inputs,
    pub channels: Vec<Channel>,
    /// Rows held out (scored, never fitted); the others are fitted.
    pub held: Vec<bool>,
    /// Decimation factor applied to the run's rows.
    pub decimation: usize,
    pub notes: Vec<String>,
    /// Channels left out of this run, with why (dead or stuck).
    pub missing: Vec<String>,
}

impl Prepared {
    pub fn rows(&self) -> usize {
        self.inputs.len()
    }

    /// Whether row `k` is used to fit.
    pub fn is_fit(&self, k: usize) -> bool {
        !self.held[k]
    }

    /// Hold out rows `[from, n)`.
    pub fn hold_from(&mut self, from: usize) {
        for (k, h) in self.held.iter_mut().enumerate() {
            *h = k >= from;
        }
    }
}

/// Noise scale of a measured series from its first differences (trimmed
/// RMS of the differences / √2), floored at `floor`.
pub fn noise_scale(v: &[f64], floor: f64) -> f64 {
    let mut d: Vec<f64> = v
        .windows(2)
        .filter(|w| w[0].is_finite() && w[1].is_finite())
        .map(|w| (w[1] - w[0]).abs())
        .collect();
    if d.len() < 4 {
        return floor;
    }
    d.sort_by(|a, b| a.total_cmp(b));
    let keep = (d.len() as f64 * 0.95).ceil() as usize;
    let ms: f64 = d[..keep].iter().map(|x| x * x).sum::<f64>() / keep as f64;
    (ms / 2.0).sqrt().max(floor)
}

/// Match a run to the machine and build the simulator inputs on the run's
/// grid. `max_rows`: decimate (block-averaging the inputs) above this.
pub fn prepare(m: &Machine, run: &Run, name: &str, max_rows: usize) -> Result<Prepared> {
    let t = run.time_s();
    if t.len() < 10 {
        bail!("run {name}: needs at least 10 rows, has {}", t.len());
    }
    let mut notes = Vec::new();
    let mut diffs: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    diffs.sort_by(|a, b| a.total_cmp(b));
    let dt = diffs[diffs.len() / 2];
    if !(dt > 0.0) {
        bail!("run {name}: time_s is not increasing");
    }
    let maxdev = diffs
        .iter()
        .map(|d| (d - dt).abs() / dt)
        .fold(0.0, f64::max);
    if maxdev > 0.1 {
        notes.push(format!(
            "{name}: sampling is not uniform (median {dt} s, worst deviation {:.0} %); rows treated as uniform",
            maxdev * 100.0
        ));
    }
    let duty = Duty::from_run(run, name)?;
    let full = duty.inputs_rows(m.spec.ambient_c);
    let n = full.len();
    let f = n.div_ceil(max_rows.max(10)).max(1);
    let rows: Vec<usize> = (0..n).step_by(f).collect();
    let avg = |v: &[f64]| block_means(v, f);
    // spindle speed: average the heat-relevant quantity is not possible
    // without the machine, so the block mean of rpm is used (exact for
    // blocks of constant speed).
    let inputs = Inputs {
        t0: full.t0,
        dt: dt * f as f64,
        rpm: avg(&full.rpm),
        feed: avg(&full.feed),
        coolant: avg(&full.coolant)
            .into_iter()
            .map(|c| if c >= 0.5 { 1.0 } else { 0.0 })
            .collect(),
        ambient: avg(&full.ambient),
    };
    let mut channels = Vec::new();
    for (i, col) in m.sensor_cols.iter().enumerate() {
        if let Some(c) = run.col(col) {
            let meas: Vec<f64> = rows.iter().map(|&r| c[r].unwrap_or(f64::NAN)).collect();
            let s = noise_scale(
                &c.iter().map(|v| v.unwrap_or(f64::NAN)).collect::<Vec<_>>(),
                0.018,
            );
            channels.push(Channel {
                name: col.clone(),
                kind: Kind::Temp(i),
                meas,
                s,
            });
        }
    }
    for (i, col) in m.dir_cols.iter().enumerate() {
        if let Some(c) = run.col(col) {
            let raw: Vec<f64> = c.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
            let first: Vec<f64> = raw
                .iter()
                .take(5)
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            let z = if first.is_empty() {
                0.0
            } else {
                first.iter().sum::<f64>() / first.len() as f64
            };
            let meas: Vec<f64> = rows.iter().map(|&r| raw[r] - z).collect();
            let s = noise_scale(&raw, 0.01);
            channels.push(Channel {
                name: col.clone(),
                kind: Kind::Disp(i),
                meas,
                s,
            });
        }
    }
    // a dead or stuck channel is left out of this run (NaN: neither fitted
    // nor scored) and said so, rather than fitted as a frozen value
    let mut missing = Vec::new();
    let raw_of = |name: &str| -> Vec<f64> {
        run.col(name)
            .map(|c| c.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
            .unwrap_or_default()
    };
    let moving = channels
        .iter()
        .filter(|c| {
            matches!(c.kind, Kind::Temp(_)) && crate::diagnose::signal::moves(&raw_of(&c.name))
        })
        .count();
    for ch in channels.iter_mut() {
        let raw = raw_of(&ch.name);
        let temp = matches!(ch.kind, Kind::Temp(_));
        let unit = if temp { "°C" } else { "µm" };
        // a still channel is stuck only if some other temperature moves
        let others_move = moving > usize::from(temp && crate::diagnose::signal::moves(&raw));
        if let Some(why) = crate::diagnose::signal::unusable_channel(&raw, unit, others_move) {
            missing.push(format!(
                "{} {why} of run {name}: left out of that run",
                ch.name
            ));
            ch.meas.iter_mut().for_each(|v| *v = f64::NAN);
        }
    }
    if channels.is_empty() {
        bail!(
            "run {name}: none of the machine's columns ({}, {}) is in the run",
            m.sensor_cols.join(","),
            m.dir_cols.join(",")
        );
    }
    let nr = rows.len();
    Ok(Prepared {
        name: name.to_string(),
        inputs,
        channels,
        held: vec![false; nr],
        decimation: f,
        notes,
        missing,
    })
}

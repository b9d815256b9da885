//! A nominal machine description fitted to the first part of a run, for
//! measured data that comes without a machine description.
//!
//! Each temperature sensor becomes its own first-order node (no links):
//! `C dT/dt = −G (T − T_start) + w (n/n_max)^e`, with `C` fixed at 10 kJ/K
//! and `G`, `w` from least squares on the finite differences of the first
//! part (e chosen from 1, 1.5, 2). Each displacement channel becomes a
//! direction `d = Σ α·L_i·(T_i − T_i,start)` with `L_i` from ridge
//! least squares on the measured temperatures of the same part. The machine
//! is assumed to be at rest and in equilibrium at the start. This is a
//! deliberately small grey-box model: the diagnosis then asks which
//! physical term explains what it misses later in the run.

use anyhow::{bail, Result};

use crate::runcsv::Run;
use crate::sim::linalg::lstsq_cols;
use crate::sim::machine::{
    BendingSite, DirectionSpec, EffectSites, MachineSpec, NodeSpec, Noise, SensorSpec, SourceSpec,
    TermSpec,
};
use crate::sim::Machine;

const C_NODE: f64 = 10_000.0;

pub fn fit_nominal(run: &Run, fraction: f64) -> Result<Machine> {
    if !(fraction > 0.05 && fraction < 0.95) {
        bail!("nominal fraction must be between 0.05 and 0.95");
    }
    let t = run.time_s();
    let n_all = t.len();
    let n = ((n_all as f64) * fraction) as usize;
    if n < 50 {
        bail!("too few rows ({n}) in the first part to fit a nominal model");
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    let rpm: Vec<f64> = run
        .col("spindle_rpm")
        .ok_or_else(|| anyhow::anyhow!("run has no spindle_rpm column"))?
        .iter()
        .map(|v| v.unwrap_or(0.0))
        .collect();
    let n_max = rpm.iter().copied().fold(0.0, f64::max).max(1.0);
    let tcols: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    if tcols.is_empty() {
        bail!("run has no temperature columns");
    }
    let series = |c: &str| -> Vec<f64> {
        let col = run.col(c).unwrap_or(&[]);
        let mut last = f64::NAN;
        col.iter()
            .map(|v| {
                if let Some(x) = v {
                    last = *x;
                }
                last
            })
            .collect()
    };
    let start = |v: &[f64]| -> f64 {
        let f: Vec<f64> = v
            .iter()
            .take(5)
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        f.iter().sum::<f64>() / f.len().max(1) as f64
    };
    let temps: Vec<Vec<f64>> = tcols.iter().map(|c| series(c)).collect();
    let t0: Vec<f64> = temps.iter().map(|v| start(v)).collect();
    let mut sorted = t0.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let ambient = sorted[sorted.len() / 2];
    let mut nodes = Vec::new();
    let mut sources = Vec::new();
    let mut sensors = Vec::new();
    let mut rise = Vec::new();
    for (i, c) in tcols.iter().enumerate() {
        let name = c.strip_prefix("T_").unwrap_or(c).to_string();
        let v = &temps[i];
        let mut best: Option<(f64, f64, f64, f64)> = None; // (sse, g, w, e)
        for e in [1.0, 1.5, 2.0] {
            let x1: Vec<f64> = (0..n - 1).map(|k| -(v[k] - t0[i])).collect();
            let x2: Vec<f64> = (0..n - 1).map(|k| (rpm[k] / n_max).powf(e)).collect();
            let y: Vec<f64> = (0..n - 1).map(|k| (v[k + 1] - v[k]) / dt).collect();
            let ok: Vec<usize> = (0..n - 1)
                .filter(|&k| x1[k].is_finite() && y[k].is_finite())
                .collect();
            let cols = vec![
                ok.iter().map(|&k| x1[k]).collect::<Vec<_>>(),
                ok.iter().map(|&k| x2[k]).collect(),
            ];
            let yy: Vec<f64> = ok.iter().map(|&k| y[k]).collect();
            if let Some(w) = lstsq_cols(&cols, &yy, 1e-9) {
                let sse: f64 = ok
                    .iter()
                    .enumerate()
                    .map(|(j, &k)| (yy[j] - w[0] * x1[k] - w[1] * x2[k]).powi(2))
                    .sum();
                if best.is_none_or(|b| sse < b.0) {
                    best = Some((sse, w[0], w[1], e));
                }
            }
        }
        let (_, lam, beta, e) = best.unwrap_or((0.0, 1e-4, 0.0, 1.0));
        let lam = lam.clamp(1e-6, 0.1); // time constants 10 s .. 11 days
        nodes.push(NodeSpec {
            name: name.clone(),
            c_j_per_k: C_NODE,
            g_amb_w_per_k: lam * C_NODE,
            area_m2: 1.0,
            amb_offset_c: t0[i] - ambient,
        });
        sources.push(SourceSpec {
            node: name.clone(),
            w_at_nmax: beta.max(0.0) * C_NODE,
            exponent: e,
        });
        rise.push((beta.max(0.0) / lam, name.clone()));
        sensors.push(SensorSpec {
            name: name.clone(),
            node: name.clone(),
        });
    }
    // directions from the measured temperatures of the first part
    let alpha = crate::sim::machine::ALPHA_STEEL;
    let mut directions = Vec::new();
    for c in run.error_columns() {
        let d = series(c);
        let d0 = start(&d);
        let ok: Vec<usize> = (0..n)
            .filter(|&k| d[k].is_finite() && temps.iter().all(|v| v[k].is_finite()))
            .collect();
        let cols: Vec<Vec<f64>> = temps
            .iter()
            .zip(&t0)
            .map(|(v, z)| ok.iter().map(|&k| alpha * 1e3 * (v[k] - z)).collect())
            .collect();
        let y: Vec<f64> = ok.iter().map(|&k| d[k] - d0).collect();
        let scale: f64 = cols
            .iter()
            .map(|c| c.iter().map(|x| x * x).sum::<f64>())
            .sum::<f64>()
            / cols.len() as f64;
        let l = lstsq_cols(&cols, &y, 1e-3 * scale.max(1e-12)).unwrap_or(vec![0.0; cols.len()]);
        let name = c
            .strip_prefix('d')
            .and_then(|s| s.strip_suffix("_um"))
            .unwrap_or(c)
            .to_string();
        directions.push(DirectionSpec {
            name,
            terms: tcols
                .iter()
                .zip(&l)
                .map(|(tc, li)| TermSpec {
                    node: tc.strip_prefix("T_").unwrap_or(tc).to_string(),
                    length_mm: (li * 10.0).round() / 10.0,
                })
                .collect(),
        });
    }
    rise.sort_by(|a, b| b.0.total_cmp(&a.0));
    let bending = match (rise.first(), rise.last(), directions.last()) {
        (Some(a), Some(b), Some(d)) if a.1 != b.1 => Some(BendingSite {
            a: a.1.clone(),
            b: b.1.clone(),
            direction: d.name.clone(),
        }),
        _ => None,
    };
    let spec = MachineSpec {
        name: format!("nominal-fit-{}", run.meta("run").unwrap_or("run")),
        description: format!(
            "grey-box nominal model fitted to the first {:.0} % of the run: one first-order node per sensor, directions by ridge least squares",
            fraction * 100.0
        ),
        ambient_c: ambient,
        n_max_rpm: n_max,
        rated_power_w: 0.0,
        motor_loss_frac: 0.0,
        motor_node: None,
        alpha_per_k: alpha,
        noise: Noise::default(),
        nodes,
        links: vec![],
        bearings: vec![],
        sources,
        rod: None,
        sensors,
        directions,
        effects: EffectSites { coolant_nodes: vec![], ballscrew_nodes: vec![], bending },
    };
    Machine::compile(spec)
}

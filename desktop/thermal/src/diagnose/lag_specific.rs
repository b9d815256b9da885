//! Whether a lag the body-map test sees on a sensor is the sensor's own
//! (`diagnose fit`). The body map (`open_effects::sensor_lags`) only shows
//! that the displacements are better explained with one sensor taken as
//! read while everything else is smoothed: heat the sensors do not see
//! (a ball screw, a bearing law, a drift of the air, a changed film) makes
//! the displacement lead the sensors in the same way. A lag of the
//! sensor's own reading keeps its steady value and only delays it: the
//! body is the reading plus τ·dx/dt. So, with the sensor's lagged rise
//! (weight L) and its own transient x − lag_τ(x) (weight M) both free in
//! the body map, the transient's weight implies the lag, τ' = τ·M/L
//! (pooled over the displacements), and for a lag of the sensor:
//!
//! - **it is the lag the body map found** (all runs): τ' within a stated
//!   factor of τ, and positive (a negative weight is a lead, not a lag);
//! - **in every frequency band**: x − lag_τ(x) is a high-pass with its
//!   corner at 1/τ; at the neighbouring taus of the grid (τ/1.5, 1.5·τ) it
//!   weighs other frequencies, and a first-order lag (its phase atan(ωτ')
//!   grows with frequency as that lag's and no other) implies the same τ';
//! - **in every run**: fitted on each run alone (each run its own duty),
//!   the same τ' again.
//!
//! Heat the sensors miss gives the displacement a lead of its own, whose
//! weight bears no relation to the sensor's steady weight: the implied
//! lag lands elsewhere, changes with the band or the run, or is negative.
//! (The sensor's reading against its neighbours alone was tried first and
//! does not separate: a sensor on a node slower than its neighbours reads
//! as lagged against them, and on the development runs false lags fitted
//! their neighbours better than true ones.)
//!
//! A lag that fits the displacement without this signature is not named;
//! `diagnose fit` lists it as untestable with the numbers.

use serde_json::{json, Value};

use super::ident::Problem;
use super::lag::lag_signal;
use super::stats::r4;
use super::types::Finding;

/// Largest factor between the lag a sensor's transient implies and the
/// body map's lag, over all runs and in each run fitted alone. A factor
/// 2.25 is two steps of the 1.5× lag grid: one for where the true lag
/// falls between grid points, one for the estimate's own scatter.
pub const TAU_AGREE: f64 = 2.25;

fn rise(v: &[f64]) -> Vec<f64> {
    let mut last = v.iter().copied().find(|x| x.is_finite()).unwrap_or(0.0);
    let z = last;
    v.iter()
        .map(|&x| {
            if x.is_finite() {
                last = x;
            }
            last - z
        })
        .collect()
}

/// The body map of each displacement `disp` at lag `tau` on the runs
/// `runs` (fit rows, level per run, ridge λ 10⁻⁶ on unit-RMS columns),
/// every sensor's rise lagged by `tau` and sensor `s`'s own transient
/// x − lag(x) added: per displacement the weights of `s`'s lagged rise
/// and of its transient (`None` when a fit fails).
fn body_weights(
    p: &Problem,
    disp: &[usize],
    s: usize,
    tau: f64,
    runs: &[usize],
) -> Option<Vec<(f64, f64)>> {
    let ds = p.ds;
    let ns = ds.sensors.len();
    let nr = runs.len();
    // run → column → values: the lagged sensor rises, then the transient
    let cols: Vec<Vec<Vec<f64>>> = runs
        .iter()
        .map(|&r| {
            let dt = ds.runs[r].dt;
            let mut c: Vec<Vec<f64>> = (0..ns)
                .map(|i| lag_signal(&rise(&p.meas[r][i]), dt, tau))
                .collect();
            let x = rise(&p.meas[r][s]);
            c.push(x.iter().zip(&c[s]).map(|(a, b)| a - b).collect());
            c
        })
        .collect();
    let nc = cols[0].len();
    let mut out = Vec::new();
    for &o in disp {
        let target: Vec<Vec<f64>> = runs
            .iter()
            .map(|&r| {
                let y = rise(&p.meas[r][o]);
                let y = lag_signal(&y, ds.runs[r].dt, tau);
                y.iter()
                    .zip(&p.meas[r][o])
                    .map(|(a, m)| if m.is_finite() { *a } else { f64::NAN })
                    .collect()
            })
            .collect();
        let mut rows = Vec::new();
        for (ri, &r) in runs.iter().enumerate() {
            let run = &ds.runs[r];
            for k in 0..run.rows() {
                if !run.held[k] && target[ri][k].is_finite() {
                    rows.push((ri, k));
                }
            }
        }
        if rows.len() < 3 * (nc + nr) + 10 {
            return None;
        }
        let scale: Vec<f64> = (0..nc)
            .map(|j| {
                let ss: f64 = rows.iter().map(|&(ri, k)| cols[ri][j][k].powi(2)).sum();
                let rms = (ss / rows.len() as f64).sqrt();
                if rms > 1e-12 {
                    1.0 / rms
                } else {
                    0.0
                }
            })
            .collect();
        let x = nalgebra::DMatrix::from_fn(rows.len(), nc + nr, |i, j| {
            let (ri, k) = rows[i];
            if j < nc {
                cols[ri][j][k] * scale[j]
            } else if j - nc == ri {
                1.0
            } else {
                0.0
            }
        });
        let y =
            nalgebra::DVector::from_iterator(rows.len(), rows.iter().map(|&(ri, k)| target[ri][k]));
        let b = tcomp_data::linalg::ridge(&x, &y, 1e-6)?;
        out.push((b[s] * scale[s], b[ns] * scale[ns]));
    }
    Some(out)
}

/// The lag the sensor's transient implies on the runs `runs`: with its
/// lagged rise (weight L per displacement) and its transient
/// x − lag_τ(x) (weight M) both free in the body map at lag τ, a reading
/// that lags its body by τ' needs M·τ = L·τ' on every displacement (the
/// body is the reading plus τ'·dx/dt, a lag keeps the steady value):
/// τ' = τ·ΣwML/ΣwL², w the displacements' 1/noise². Also the share of
/// the map's steady weight the sensor carries, ΣwL²·var(x) against the
/// displacements' own variance (`None` when the fit fails or L is 0).
fn implied_lag(p: &Problem, disp: &[usize], s: usize, tau: f64, runs: &[usize]) -> Option<f64> {
    let w = body_weights(p, disp, s, tau, runs)?;
    let (mut ml, mut ll) = (0.0, 0.0);
    for (&(l, m), &o) in w.iter().zip(disp) {
        let wo = 1.0 / p.outputs[o].noise.powi(2);
        ml += wo * m * l;
        ll += wo * l * l;
    }
    (ll > 0.0).then(|| tau * ml / ll)
}

/// Whether `tau` agrees with the body map's `body_tau` within
/// `TAU_AGREE` (a body-map lag at the grid's long end is a lower bound).
fn agrees(tau: f64, body_tau: f64, body_is_lower_bound: bool) -> bool {
    let r = tau / body_tau;
    r >= 1.0 / TAU_AGREE && (r <= TAU_AGREE || body_is_lower_bound)
}

/// The lag signature of sensor `s` (index among the outputs) against the
/// displacements `disp`, given the body map's lag: the evidence object
/// (`specific`, and `why_not` when not).
pub fn signature(
    p: &Problem,
    disp: &[usize],
    s: usize,
    body_tau: f64,
    body_is_lower_bound: bool,
) -> Value {
    let nr = p.ds.runs.len();
    let all: Vec<usize> = (0..nr).collect();
    let whole = implied_lag(p, disp, s, body_tau, &all);
    let per_run: Vec<Option<f64>> = (0..nr)
        .map(|r| implied_lag(p, disp, s, body_tau, &[r]))
        .collect();
    // the transient x − lag_τ(x) is a high-pass with its corner at 1/τ:
    // at the grid's neighbouring taus it weighs other frequencies, where a
    // first-order lag implies the same time constant (its phase, atan(ωτ),
    // grows with frequency as that lag's and no other)
    let bands: Vec<(f64, Option<f64>)> = [body_tau / 1.5, body_tau * 1.5]
        .iter()
        .map(|&t| (t, implied_lag(p, disp, s, t, &all)))
        .collect();
    let mut why: Vec<String> = Vec::new();
    let mut check = |t: Option<f64>, what: &str| {
        match t {
        None => why.push(format!("{what}: the displacements give the sensor no steady weight")),
        Some(t) if !agrees(t, body_tau, body_is_lower_bound) => why.push(format!(
            "{what}: its transient implies a lag of {t:.0} s, not the body map's {body_tau:.0} s within a factor {TAU_AGREE}"
        )),
        Some(_) => {}
    }
    };
    check(whole, "all runs");
    for (t, l) in &bands {
        check(*l, &format!("band of the {t:.0} s transient"));
    }
    for (r, t) in per_run.iter().enumerate() {
        check(*t, &format!("run {} alone", p.ds.runs[r].name));
    }
    json!({
        "specific": why.is_empty(),
        "implied_tau_s": whole.map(r4),
        "implied_tau_s_per_run": per_run.iter().map(|t| t.map(r4)).collect::<Vec<_>>(),
        "why_not": why,
        "implied_tau_s_bands": bands.iter().map(|(t, l)| json!({"transient_tau_s": r4(*t), "implied_tau_s": l.map(r4)})).collect::<Vec<_>>(),
        "rule": format!("the body map at the found tau with the sensor's lagged rise (weight L) and its own transient x − lag(x) (weight M) both free: a lag of its reading keeps its steady value, so the transient's weight implies the lag, τ·M/L (pooled over the displacements); it must agree with the found tau within a factor {TAU_AGREE} over all runs and in each run fitted alone"),
    })
}

/// The `untestable` entries for lags the body map supports but whose
/// signature is not the sensor's own (their scored findings, best-ranked
/// first), one per sensor.
pub fn untestable<'a>(lags: impl Iterator<Item = &'a Finding>) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = Vec::new();
    for f in lags {
        let s = f.evidence["channel"].as_str().unwrap_or("?");
        let name = format!("sensor_lag (not specific) on {s}");
        if v.iter().any(|(n, _)| *n == name) {
            continue;
        }
        let tau = f.params.as_ref().and_then(|p| p["tau_s"].as_f64());
        let why: Vec<&str> = f.evidence["own_reading"]["why_not"]
            .as_array()
            .map(|a| a.iter().filter_map(|w| w.as_str()).collect())
            .unwrap_or_default();
        v.push((name, format!(
            "with {s} taken as read, a lag of {:.0} s fits the displacement better, but {s}'s reading does not show a lag of its own: {}; heat that the sensors do not see (a ball screw, a bearing, the air, a changed film) makes the displacement lead the sensors in the same way. A reference sensor beside {s}, or a run with fast heat steps, would separate them",
            tau.unwrap_or(f64::NAN),
            why.join("; ")
        )));
    }
    v
}

//! Candidate effects of `diagnose fit`: only those an identified nominal
//! cannot absorb. Each is added to the nominal as extra regressors (or a
//! re-mapped sensor), fitted jointly on the fit blocks and scored on the
//! held-out blocks in the unit it shows in (°C, µm).
//!
//! - `sensor_offset`: a step in one sensor at one time of one run (an
//!   offset that changes inside a run), located by a change-point scan of
//!   that sensor's nominal residual on the fit rows;
//! - `sensor_lag`: a sensor that lags its body: displacement, a static map
//!   of the true node temperatures, seen through a first-order lag, is
//!   better explained with that sensor as read than lagged like the others;
//! - `coolant`: a periodic coolant/chiller drive, its period from the
//!   sensors' own residual spectra (gated by `coolant_on` when present);
//! - `bearing_nonlinear`: spindle heat steeper in speed than the textbook
//!   law (n and n^(5/3)), tested on runs of different speeds against a
//!   reference that also carries the spindle's switched inputs;
//! - `ambient_drift`: a slow drift common to every sensor that `T_ambient`
//!   does not carry; tried and reported, never claimed.
//!
//! The step, the speed law and the candidate type live in their own files
//! (`sensor_step`, `speed_law`, `candidate`); they are re-exported here.

use serde_json::json;

pub use super::candidate::Candidate;
pub use super::sensor_step::sensor_steps;
pub use super::speed_law::{
    runs_of_different_speeds, speed_levels, speed_nonlinearity, speed_nonlinearity_against_nominal,
    MIN_SPEED_LEVELS, STEEP_EXPONENTS,
};
use crate::diagnose::ident::{ModelFit, OutFit, Problem, Structure};
use crate::diagnose::signal::{held, held_rise, r4};
use tcomp_numerics::linalg::RidgeFactor;

/// Relative fit-row shrink of the lagged body map to claim a sensor lag:
/// above the largest seen on clean runs (0.19 on the open-world benchmark's
/// clean cases, 0.22 on 90 clean two-speed pairs of its duty generator).
pub const LAG_MIN_FIT_REL: f64 = 0.25;
/// ... and in every run at least half of that: a lag is the sensor's and
/// shows in every run, heat that differs between runs does not.
pub const LAG_MIN_RUN_REL: f64 = 0.1;

/// The body map of each displacement of `outs` seen through a lag of `tau`: the
/// displacement is a static linear map of the true node temperatures, so
/// its lagged version is the same map of the lagged temperatures. Every
/// sensor rise and the displacement pass through the same first-order lag
/// (`lag_signal`, exact for a linear map) except the sensor `own`, which
/// enters as read: if that sensor already lags its body by `tau`, its
/// reading is the lagged body temperature and the map becomes exact; for
/// any other sensor, taking it un-lagged only adds a lead. Per-run level +
/// Σ L_i·rise_i, ridge least squares on the fit rows. `injected` puts a
/// lag of its own on one sensor's reading first (the test's power, see
/// `lag_reach`).
fn lagged_body_maps(
    p: &Problem,
    outs: &[usize],
    tau: f64,
    own: Option<usize>,
    injected: Option<(usize, f64)>,
) -> Vec<OutFit> {
    let ds = p.ds;
    let ns = ds.sensors.len();
    let nr = ds.runs.len();
    let cols: Vec<Vec<Vec<f64>>> = ds
        .runs
        .iter()
        .enumerate()
        .map(|(r, run)| {
            (0..ns)
                .map(|i| {
                    let mut x = held_rise(&p.meas[r][i]);
                    if let Some((_, t)) = injected.filter(|j| j.0 == i) {
                        x = crate::diagnose::signal::lag_signal(&x, run.dt, t);
                    }
                    if own == Some(i) {
                        x
                    } else {
                        crate::diagnose::signal::lag_signal(&x, run.dt, tau)
                    }
                })
                .collect()
        })
        .collect();
    // the sensors' lagged rises and the fit rows' factor do not depend
    // on the output: built once, reused while the rows are the same
    let mut last: Option<(Vec<(usize, usize)>, RidgeFactor)> = None;
    outs.iter()
        .map(|&o| {
            let target: Vec<Vec<f64>> = ds
                .runs
                .iter()
                .enumerate()
                .map(|(r, run)| {
                    let y = crate::diagnose::signal::lag_signal(&held(&p.meas[r][o]), run.dt, tau);
                    y.iter()
                        .zip(&p.meas[r][o])
                        .map(|(a, m)| if m.is_finite() { *a } else { f64::NAN })
                        .collect()
                })
                .collect();
            let nc = ns;
            let k = nc + nr;
            let mut rows = Vec::new();
            for (r, run) in ds.runs.iter().enumerate() {
                for kk in 0..run.rows() {
                    if !run.held[kk] && target[r][kk].is_finite() {
                        rows.push((r, kk));
                    }
                }
            }
            let val = |r: usize, kk: usize, j: usize| -> f64 {
                if j < nc {
                    cols[r][j][kk]
                } else if j - nc == r {
                    1.0
                } else {
                    0.0
                }
            };
            let mut f = OutFit {
                k,
                ..Default::default()
            };
            let coef = if rows.len() > k + 2 {
                let x = || {
                    nalgebra::DMatrix::from_fn(rows.len(), k, |i, j| val(rows[i].0, rows[i].1, j))
                };
                let y = nalgebra::DVector::from_iterator(
                    rows.len(),
                    rows.iter().map(|&(r, kk)| target[r][kk]),
                );
                ridge_on(&mut last, &rows, x, &y)
            } else {
                None
            };
            let Some(coef) = coef else {
                let held = (0..ds.runs.len())
                    .map(|r| {
                        let run = &ds.runs[r];
                        (0..run.rows())
                            .filter(|&kk| run.held[kk] && p.meas[r][o][kk].is_finite())
                            .count()
                    })
                    .sum();
                let sizes: Vec<usize> = ds.runs.iter().map(|r| r.rows()).collect();
                return OutFit::failed(k, &sizes, rows.len(), held);
            };
            // with `own`: that sensor's coefficient as lagged and as read
            f.extra_coef = own.map(|i| coef[i]).into_iter().collect();
            for (r, run) in ds.runs.iter().enumerate() {
                let mut res = Vec::with_capacity(run.rows());
                for kk in 0..run.rows() {
                    let pred: f64 = (0..k).map(|j| coef[j] * val(r, kk, j)).sum();
                    let e = target[r][kk] - pred;
                    if !e.is_finite() {
                        res.push(f64::NAN);
                        continue;
                    }
                    f.add_residual(e, run.held[kk]);
                    res.push(e);
                }
                f.resid.push(res);
            }
            f
        })
        .collect()
}

/// The ridge fit (λ 10⁻⁶) of `y` on the matrix `x` builds for `rows`:
/// the factor of `last` when it was made for the same rows (the same
/// matrix), else a new one kept in `last`.
fn ridge_on(
    last: &mut Option<(Vec<(usize, usize)>, RidgeFactor)>,
    rows: &[(usize, usize)],
    x: impl FnOnce() -> nalgebra::DMatrix<f64>,
    y: &nalgebra::DVector<f64>,
) -> Option<nalgebra::DVector<f64>> {
    if last.as_ref().is_none_or(|(r, _)| r.as_slice() != rows) {
        *last = Some((rows.to_vec(), RidgeFactor::new(&x(), 1e-6)));
    }
    let (_, factor) = last.as_ref()?;
    let y = nalgebra::DMatrix::from_column_slice(y.len(), 1, y.as_slice());
    factor.solve(&y).map(|b| b.column(0).into_owned())
}

/// The displacement outputs a body map explains (`None` without one, or
/// with fewer than two sensors: no lag test).
fn body_map_outputs(p: &Problem) -> Option<Vec<usize>> {
    let disp: Vec<usize> = (0..p.outputs.len())
        .filter(|&o| p.outputs[o].is_disp)
        .collect();
    (!disp.is_empty() && p.ds.sensors.len() >= 2).then_some(disp)
}

/// Fit-row cost of body-map fits of the displacements `disp` (noise units).
fn body_cost(p: &Problem, disp: &[usize], fits: &[OutFit]) -> f64 {
    fits.iter()
        .zip(disp)
        .map(|(f, &o)| f.sse_fit / p.outputs[o].noise.powi(2))
        .sum()
}

/// The same cost on the fit rows of run `r` alone.
fn body_cost_run(p: &Problem, disp: &[usize], fits: &[OutFit], r: usize) -> f64 {
    let held = &p.ds.runs[r].held;
    fits.iter()
        .zip(disp)
        .map(|(f, &o)| {
            f.resid.get(r).map_or(0.0, |res| {
                res.iter()
                    .zip(held)
                    .filter(|(e, &h)| !h && e.is_finite())
                    .map(|(e, _)| e * e)
                    .sum::<f64>()
            }) / p.outputs[o].noise.powi(2)
        })
        .sum()
}

/// The body map's relative fit-row gain (all runs, least run) for sensor
/// `s` taken as read against every signal lagged by `tau`.
fn body_gain(p: &Problem, disp: &[usize], base: &[OutFit], own: &[OutFit]) -> (f64, f64) {
    let all = 1.0 - body_cost(p, disp, own) / body_cost(p, disp, base).max(1e-12);
    let least = (0..p.ds.runs.len())
        .map(|r| 1.0 - body_cost_run(p, disp, own, r) / body_cost_run(p, disp, base, r).max(1e-12))
        .fold(f64::INFINITY, f64::min);
    (all, least)
}

/// Reach of the lag test on each sensor: the shortest lag of `LAG_GRID`
/// that, put on that sensor's reading, the body-map test would see
/// (relative fit-row gain ≥ `LAG_MIN_FIT_REL`, and ≥ `LAG_MIN_RUN_REL` in
/// every run); `None` when not even the longest would be seen (the
/// displacements weigh that sensor too little: a lagging sensor cannot be
/// told from a slower node). The runs' own lags, if any, stay in: this
/// measures how much the displacements carry the sensor, not whether it
/// lags. Empty without a displacement.
pub fn lag_reach(p: &Problem) -> Vec<Option<f64>> {
    use rayon::prelude::*;
    let Some(disp) = body_map_outputs(p) else {
        return Vec::new();
    };
    let ns = p.ds.sensors.len();
    let seen = |s: usize, tau: f64| -> bool {
        let inj = Some((s, tau));
        let base = lagged_body_maps(p, &disp, tau, None, inj);
        let own = lagged_body_maps(p, &disp, tau, Some(s), inj);
        let (all, least) = body_gain(p, &disp, &base, &own);
        all >= LAG_MIN_FIT_REL && least >= LAG_MIN_RUN_REL
    };
    (0..ns)
        .into_par_iter()
        .map(|s| {
            // the gain grows with the lag: the longest first, then the
            // shortest seen by bisection over the grid
            let last = LAG_GRID.len() - 1;
            if !seen(s, LAG_GRID[last]) {
                return None;
            }
            let (mut lo, mut hi) = (0usize, last);
            if seen(s, LAG_GRID[0]) {
                return Some(LAG_GRID[0]);
            }
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if seen(s, LAG_GRID[mid]) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            Some(LAG_GRID[hi])
        })
        .collect()
}

/// Lag grid [s] for `sensor_lag`.
pub const LAG_GRID: [f64; 9] = [
    60.0, 90.0, 135.0, 200.0, 300.0, 450.0, 675.0, 1000.0, 1500.0,
];

/// Sensor lag against the body: for each lag `tau` of the grid, the body
/// map of every displacement with all signals lagged by `tau` (the
/// reference) against the same map with one sensor taken as read (it
/// already lags by `tau`). Per sensor, the `tau` with the largest relative
/// fit-row gain. Returns the candidates and, for each, its reference fit.
pub fn sensor_lags(p: &Problem) -> Vec<(Candidate, ModelFit)> {
    use rayon::prelude::*;
    let Some(disp) = body_map_outputs(p) else {
        return Vec::new();
    };
    let ns = p.ds.sensors.len();
    let no = p.outputs.len();
    let assemble = |fits: Vec<OutFit>| ModelFit {
        outs: (0..no)
            .map(|o| {
                disp.iter()
                    .position(|&d| d == o)
                    .map_or_else(OutFit::default, |i| fits[i].clone())
            })
            .collect(),
    };
    // per tau: reference fits, then per sensor the fits with it as read
    let per_tau: Vec<(Vec<OutFit>, Vec<Vec<OutFit>>)> = LAG_GRID
        .par_iter()
        .map(|&tau| {
            let base = lagged_body_maps(p, &disp, tau, None, None);
            let own: Vec<Vec<OutFit>> = (0..ns)
                .map(|s| lagged_body_maps(p, &disp, tau, Some(s), None))
                .collect();
            (base, own)
        })
        .collect();
    let mut out = Vec::new();
    for s in 0..ns {
        // the tau of the largest relative gain; a lag belongs to the sensor,
        // so it shows in every run: also the least gain over the runs (heat
        // that differs between runs, e.g. a speed law, bends the static map
        // in one run only)
        let gains: Vec<(f64, f64)> = per_tau
            .iter()
            .map(|(base, own)| body_gain(p, &disp, base, &own[s]))
            .collect();
        let Some((ti, &(gain, run_gain))) = gains
            .iter()
            .enumerate()
            .max_by(|a, b| a.1 .0.total_cmp(&b.1 .0))
        else {
            continue;
        };
        // the shortest tau whose gain would pass the claim's margins (the
        // reach of the test on this sensor, `lag_reach`)
        let shortest_seen = gains
            .iter()
            .position(|&(g, least)| g >= LAG_MIN_FIT_REL && least >= LAG_MIN_RUN_REL)
            .map(|i| LAG_GRID[i]);
        let tau = LAG_GRID[ti];
        let (base, own) = &per_tau[ti];
        // a best tau at the grid's short end is no lag at all (flagged, never
        // claimed); at the long end the sensor is still located (the gain is
        // a property of the sensor, the reference only gets smoother with
        // tau), and tau_s is reported as a lower bound
        let mut at_bound = Vec::new();
        if ti == 0 {
            at_bound.push(format!("tau_s = {tau} (short end of the search)"));
        }
        let tau_lower_bound = ti == LAG_GRID.len() - 1;
        // where the body map supports a lag, whether the sensor's own
        // reading shows one (`lag_specific`)
        let own_reading = (gain >= LAG_MIN_FIT_REL && run_gain >= LAG_MIN_RUN_REL)
            .then(|| super::lag_specific::signature(p, &disp, s, tau, tau_lower_bound));
        out.push((
            Candidate {
                name: "sensor_lag",
                params: json!({"sensor": p.ds.sensors[s], "tau_s": tau}),
                affected: disp.clone(),
                fit: assemble(own[s].clone()),
                k_extra: 1,
                at_bound,
                evidence: json!({
                    "channel": p.ds.sensors[s],
                    "fit_rel_gain": r4(gain),
                    "tau_s_is_lower_bound": tau_lower_bound,
                    "fit_rel_gain_least_run": r4(run_gain),
                    "shortest_tau_seen_s": shortest_seen,
                    "own_reading": own_reading,
                    "reference": "body map: each displacement as a static linear map of the sensor rises; with every signal seen through a first-order lag of tau_s (reference) against the same with this sensor taken as read (it already lags its body by tau_s)",
                }),
            },
            assemble(base.clone()),
        ));
    }
    out
}

/// Periods searched for a coolant/chiller drive [s].
pub const PERIOD_RANGE: (f64, f64) = (240.0, 5400.0);

/// Periodic drive: the period with the most residual power summed over
/// the sensors (noise-normalised, fit rows, per-run sine and cosine), then
/// sine/cosine of it and its second harmonic (a sawtooth) added to every
/// output, per run (phase is free per run), gated by `coolant_on`.
pub fn periodic(p: &Problem, st: &Structure, nom: &ModelFit) -> Option<Candidate> {
    let ds = p.ds;
    let dt_max = ds.runs.iter().map(|r| r.dt).fold(0.0, f64::max);
    let lo = PERIOD_RANGE.0.max(4.0 * dt_max);
    let hi = PERIOD_RANGE.1;
    if lo >= hi {
        return None;
    }
    let gate = |r: usize, k: usize| -> f64 { ds.runs[r].coolant.as_ref().map_or(1.0, |c| c[k]) };
    // power of a sinusoid of period `per` in output o's fit-row residual
    let power = |o: usize, per: f64| -> f64 {
        let w = 2.0 * std::f64::consts::PI / per;
        let mut gain = 0.0;
        for (r, run) in ds.runs.iter().enumerate() {
            let e = &nom.outs[o].resid[r];
            let (mut ss, mut cc, mut sc, mut ys, mut yc, mut s1, mut c1, mut y1, mut n) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for k in 0..run.rows() {
                if run.held[k] || !e[k].is_finite() {
                    continue;
                }
                let g = gate(r, k);
                let t = run.time[k];
                let (s, c) = ((w * t).sin() * g, (w * t).cos() * g);
                ss += s * s;
                cc += c * c;
                sc += s * c;
                ys += e[k] * s;
                yc += e[k] * c;
                s1 += s;
                c1 += c;
                y1 += e[k];
                n += 1.0;
            }
            if n < 10.0 {
                continue;
            }
            // remove the mean (the run's level is in the nominal)
            let (ss, cc, sc) = (ss - s1 * s1 / n, cc - c1 * c1 / n, sc - s1 * c1 / n);
            let (ys, yc) = (ys - y1 * s1 / n, yc - y1 * c1 / n);
            let det = ss * cc - sc * sc;
            if det <= 1e-12 {
                continue;
            }
            let a = (cc * ys - sc * yc) / det;
            let b = (ss * yc - sc * ys) / det;
            gain += a * ys + b * yc;
        }
        gain / p.outputs[o].noise.powi(2)
    };
    let temps: Vec<usize> = (0..p.outputs.len())
        .filter(|&o| !p.outputs[o].is_disp)
        .collect();
    let total = |per: f64| -> (f64, usize, f64) {
        let mut best = (0usize, 0.0);
        let mut sum = 0.0;
        for &o in &temps {
            let g = power(o, per);
            sum += g;
            if g > best.1 {
                best = (o, g);
            }
        }
        (sum, best.0, best.1)
    };
    let n_grid = 160;
    let grid: Vec<f64> = (0..n_grid)
        .map(|i| (lo.ln() + (hi.ln() - lo.ln()) * i as f64 / (n_grid - 1) as f64).exp())
        .collect();
    let spectrum: Vec<(f64, usize, f64)> = grid.iter().map(|&per| total(per)).collect();
    let (mut i_best, mut best) = (0usize, f64::MIN);
    for (i, s) in spectrum.iter().enumerate() {
        if s.0 > best {
            best = s.0;
            i_best = i;
        }
    }
    // refine around the peak
    let mut per = grid[i_best];
    let a = grid[i_best.saturating_sub(1)];
    let b = grid[(i_best + 1).min(n_grid - 1)];
    let mut pk = spectrum[i_best];
    for j in 0..=40 {
        let q = a + (b - a) * j as f64 / 40.0;
        let v = total(q);
        if v.0 > pk.0 {
            pk = v;
            per = q;
        }
    }
    let mut powers: Vec<f64> = spectrum.iter().map(|s| s.0).collect();
    powers.sort_by(|a, b| a.total_cmp(b));
    let median = powers[powers.len() / 2].max(1e-12);
    let w = 2.0 * std::f64::consts::PI / per;
    let extra = move |_o: usize, r: usize| -> Vec<Vec<f64>> {
        let run = &ds.runs[r];
        let nr = ds.runs.len();
        let mut cols = Vec::new();
        for rr in 0..nr {
            for h in [1.0, 2.0] {
                for f in [f64::sin, f64::cos] {
                    cols.push(
                        (0..run.rows())
                            .map(|k| {
                                if rr == r {
                                    f(h * w * run.time[k]) * gate(r, k)
                                } else {
                                    0.0
                                }
                            })
                            .collect(),
                    );
                }
            }
        }
        cols
    };
    let (fit, took) = p.fit_where_supported(st, &extra, nom);
    if took.is_empty() {
        return None;
    }
    let mut at_bound = Vec::new();
    if i_best == 0 || i_best == n_grid - 1 {
        at_bound.push(format!(
            "period_s = {per:.0} (end of the {lo:.0}–{hi:.0} s search)"
        ));
    }
    Some(Candidate {
        name: "coolant",
        params: json!({"period_s": r4(per), "sensor": p.outputs[pk.1].name, "gated_by_coolant_on": ds.has_coolant}),
        k_extra: 4 * ds.runs.len() * took.len() + 1,
        affected: took,
        fit,
        at_bound,
        evidence: json!({
            "period_s": r4(per),
            "strongest_sensor": p.outputs[pk.1].name,
            "peak_over_median_power": r4(pk.0 / median),
            "spectrum": "sum over sensors of the noise-normalised power of a sinusoid in the nominal residual, fit rows",
        }),
    })
}

/// Ambient drift that `T_ambient` does not carry: one slow shape common to
/// all sensors (per run: a ramp and a 24 h sine/cosine in time), its shape
/// from the mean sensor residual, each output with its own gain.
pub fn ambient_drift(p: &Problem, st: &Structure, nom: &ModelFit) -> Option<Candidate> {
    let ds = p.ds;
    let temps: Vec<usize> = (0..p.outputs.len())
        .filter(|&o| !p.outputs[o].is_disp)
        .collect();
    if temps.len() < 2 {
        return None;
    }
    // common-mode residual per run, fitted with the drift shape on fit rows
    let day = 2.0 * std::f64::consts::PI / 86400.0;
    let shape_cols = |t: f64| [t / 3600.0, (day * t).sin(), (day * t).cos()];
    let mut shapes: Vec<Vec<f64>> = Vec::new();
    for (r, run) in ds.runs.iter().enumerate() {
        let mut rows = Vec::new();
        let mut y = Vec::new();
        for k in 0..run.rows() {
            if run.held[k] {
                continue;
            }
            let v: Vec<f64> = temps
                .iter()
                .map(|&o| nom.outs[o].resid[r][k])
                .filter(|x| x.is_finite())
                .collect();
            if v.len() * 2 < temps.len() {
                continue;
            }
            rows.push(k);
            y.push(v.iter().sum::<f64>() / v.len() as f64);
        }
        let t0 = run.time[0];
        let x = nalgebra::DMatrix::from_fn(rows.len(), 4, |i, j| {
            if j == 0 {
                1.0
            } else {
                shape_cols(run.time[rows[i]] - t0)[j - 1]
            }
        });
        let yv = nalgebra::DVector::from_vec(y);
        let c = tcomp_numerics::linalg::ridge(&x, &yv, 1e-6)?;
        shapes.push(
            run.time
                .iter()
                .map(|t| {
                    let s = shape_cols(t - t0);
                    c[1] * s[0] + c[2] * s[1] + c[3] * s[2]
                })
                .collect(),
        );
    }
    let shapes2 = shapes.clone();
    let extra = move |_o: usize, r: usize| -> Vec<Vec<f64>> { vec![shapes2[r].clone()] };
    let (fit, took) = p.fit_where_supported(st, &extra, nom);
    // a drift of the air reaches every sensor: most must take it
    if took.iter().filter(|&&o| !p.outputs[o].is_disp).count() * 10 < temps.len() * 7 {
        return None;
    }
    let amp = shapes.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    Some(Candidate {
        name: "ambient_drift",
        params: json!({"peak_c": r4(amp)}),
        k_extra: 3 * ds.runs.len() + took.len(),
        affected: took,
        fit,
        at_bound: Vec::new(),
        evidence: json!({
            "shape": "per run: ramp + 24 h sine/cosine fitted to the mean sensor residual (fit rows)",
            "peak_c": r4(amp),
            "caveat": if ds.has_ambient {
                "a drift of the air at the machine beyond what T_ambient measured"
            } else {
                "no T_ambient column: this is the room's own temperature change, an input the data lack, not a drift beyond a measured ambient"
            },
        }),
    })
}

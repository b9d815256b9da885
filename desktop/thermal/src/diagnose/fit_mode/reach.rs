//! What these runs can show of an effect beyond the identified nominal's
//! own freedom: the computed part of `diagnose fit`'s `untestable` list.
//!
//! An effect's signature (its driver through one of the nominal's modes,
//! unit steady gain) is fitted by the nominal's own columns (inputs through
//! the modes, run levels, free decays) on the fit rows; what the nominal
//! cannot absorb is what is left of it on the held-out rows. When even the
//! signature that keeps most is absorbed beyond `SPEED_MIN_KEPT`, the runs
//! cannot tell the effect from the nominal's own freedom.

use nalgebra::DMatrix;
use serde_json::{json, Value};

use crate::diagnose::effects::STEEP_EXPONENTS;
use crate::diagnose::ident::{Problem, Structure, RIDGE};
use crate::diagnose::signal::lag;
use crate::diagnose::signal::r4;
use tcomp_numerics::linalg::ridge_multi;

/// Held-out RMS share of a steeper speed law's signature that the nominal
/// must leave for the runs to test it. Below it (the nominal's own n and
/// n^e terms through its modes absorb ≥ 88.5 % of every steeper law's
/// signature: the runs' speeds do not spread enough), the speed-law test
/// never named a true steep law on the benchmarks' development seeds (open
/// world seeds 7, 11 and cross model seed 11: 10 such cases, all 0.066–0.111
/// and silent; every named one kept ≥ 0.1197, seed 3's case 18 the lowest).
pub const SPEED_MIN_KEPT: f64 = 0.115;

/// The held-out RMS share the nominal's columns of output `o` leave of each
/// signature (fitted on the fit rows where `o` is measured; `sigs[i][r]`
/// is signature `i` over run `r`). `None` when too few rows.
pub fn kept_shares(
    p: &Problem,
    st: &Structure,
    o: usize,
    sigs: &[Vec<Vec<f64>>],
) -> Option<Vec<f64>> {
    let nr = p.ds.runs.len();
    let blocks: Vec<_> = (0..nr).map(|r| p.columns(st, o, r)).collect();
    let n_shared = blocks.first().map_or(0, |b| b.0.len());
    let mut own_off = Vec::with_capacity(nr);
    let mut n_cols = n_shared;
    for b in &blocks {
        own_off.push(n_cols);
        n_cols += b.1.len();
    }
    let (mut fit, mut held) = (Vec::new(), Vec::new());
    for (r, run) in p.ds.runs.iter().enumerate() {
        for k in (0..run.rows()).filter(|&k| p.meas[r][o][k].is_finite()) {
            if run.held[k] {
                held.push((r, k));
            } else {
                fit.push((r, k));
            }
        }
    }
    if fit.len() <= n_cols + 2 || held.is_empty() || sigs.is_empty() {
        return None;
    }
    let design = |rows: &[(usize, usize)]| {
        let mut x = DMatrix::<f64>::zeros(rows.len(), n_cols);
        for (i, &(r, k)) in rows.iter().enumerate() {
            for (j, c) in blocks[r].0.iter().enumerate() {
                x[(i, j)] = c[k];
            }
            for (j, c) in blocks[r].1.iter().enumerate() {
                x[(i, own_off[r] + j)] = c[k];
            }
        }
        x
    };
    let target = |rows: &[(usize, usize)]| {
        DMatrix::from_fn(rows.len(), sigs.len(), |i, s| sigs[s][rows[i].0][rows[i].1])
    };
    let coef = ridge_multi(&design(&fit), &target(&fit), RIDGE)?;
    let y_held = target(&held);
    let res = &y_held - design(&held) * coef;
    Some(
        (0..sigs.len())
            .map(|s| {
                let own = y_held.column(s).norm_squared().max(1e-300);
                (res.column(s).norm_squared() / own).sqrt()
            })
            .collect(),
    )
}

/// How much of a steeper speed law these runs can show beyond the nominal
/// (`st`): over `STEEP_EXPONENTS` and the nominal's modes, the largest
/// held-out share of the signature `(n/n_max)^p` through one mode that the
/// nominal's own columns leave (fitted on the fit rows of the temperature
/// output measured on most rows; with `spindle_rpm` every temperature
/// output has the same columns). `None` without speed or rows.
pub fn speed_law_kept(p: &Problem, st: &Structure) -> Option<(f64, Value)> {
    if !p.ds.has_rpm {
        return None;
    }
    let o = (0..p.outputs.len())
        .filter(|&o| !p.outputs[o].is_disp)
        .max_by_key(|&o| {
            p.meas
                .iter()
                .map(|run| run[o].iter().filter(|x| x.is_finite()).count())
                .sum::<usize>()
        })?;
    let mut which = Vec::new();
    let mut sigs = Vec::new();
    for &pw in &STEEP_EXPONENTS {
        for &tau in &st.modes {
            which.push((pw, tau));
            sigs.push(
                p.ds.runs
                    .iter()
                    .map(|run| {
                        let u: Vec<f64> = run.rpm.as_ref().map_or_else(
                            || vec![0.0; run.rows()],
                            |rpm| rpm.iter().map(|n| (n.abs() / p.n_max).powf(pw)).collect(),
                        );
                        lag(&u, run.dt, tau, 0.0)
                    })
                    .collect(),
            );
        }
    }
    let kept = kept_shares(p, st, o, &sigs)?;
    let (i, best) = kept
        .iter()
        .copied()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    Some((
        best,
        json!({
            "kept_share": r4(best),
            "exponent": which[i].0,
            "tau_s": which[i].1,
            "fitted_on": p.outputs[o].name,
            "min_kept_share": SPEED_MIN_KEPT,
        }),
    ))
}

/// Held-out RMS share of an air drift's signature (a ramp of the air
/// beyond `T_ambient`, through one of the nominal's modes) that the
/// nominal must leave for the runs to test `ambient_drift`. Below it the
/// nominal's own columns (`T_ambient` through the modes with a free gain,
/// run levels, free decays) reproduce a ramp on the held-out rows to within
/// that share: a drift the runs show only as a different ambient gain.
pub const AMBIENT_MIN_KEPT: f64 = 0.115;

/// How much of an air drift beyond `T_ambient` these runs can show beyond
/// the nominal: over the nominal's modes, the largest held-out share of the
/// signature "air ramp of 1 °C/h through that mode" that the nominal's own
/// columns leave, fitted on the fit rows of each temperature output (the
/// largest over outputs: without spindle_rpm each has its own drivers).
/// `None` without `T_ambient` (then a drift is the room's own change, an
/// input the data lack) or rows.
pub fn ambient_drift_kept(p: &Problem, st: &Structure) -> Option<(f64, Value)> {
    if !p.ds.has_ambient {
        return None;
    }
    let sigs: Vec<Vec<Vec<f64>>> = st
        .modes
        .iter()
        .map(|&tau| {
            p.ds.runs
                .iter()
                .map(|run| {
                    let t0 = run.time.first().copied().unwrap_or(0.0);
                    let u: Vec<f64> = run.time.iter().map(|t| (t - t0) / 3600.0).collect();
                    lag(&u, run.dt, tau, 0.0)
                })
                .collect()
        })
        .collect();
    // with spindle_rpm every temperature output has the same columns: one
    // output decides; without it each output is driven by the others
    let temps: Vec<usize> = (0..p.outputs.len())
        .filter(|&o| !p.outputs[o].is_disp)
        .collect();
    let outs: Vec<usize> = if p.ds.has_rpm {
        temps.iter().copied().take(1).collect()
    } else {
        temps
    };
    let mut best: Option<(f64, usize, usize)> = None;
    for o in outs {
        let Some(kept) = kept_shares(p, st, o, &sigs) else {
            continue;
        };
        for (i, k) in kept.into_iter().enumerate() {
            if best.is_none_or(|b| k > b.0) {
                best = Some((k, i, o));
            }
        }
    }
    let (k, i, o) = best?;
    Some((
        k,
        json!({
            "kept_share": r4(k),
            "tau_s": st.modes[i],
            "fitted_on": p.outputs[o].name,
            "min_kept_share": AMBIENT_MIN_KEPT,
        }),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tcomp_data::runcsv::Run;

    /// Two 8 h runs whose speed steps through `levels` (fractions of 9000
    /// rpm, rest between), sensors driven by n and n^1.5 through 600 s and
    /// 4800 s, white noise.
    fn runs(levels: &[f64], seed: u64) -> Vec<(String, Run)> {
        let mut g = tcomp_numerics::rng::Rng::paired(seed);
        let dt = 30.0;
        let n = 960;
        (0..2)
            .map(|r| {
                let rpm: Vec<f64> = (0..n)
                    .map(|k| {
                        let i = k / 80 + 3 * r;
                        if i % 4 == 3 {
                            0.0
                        } else {
                            9000.0 * levels[i % levels.len()]
                        }
                    })
                    .collect();
                let u: Vec<f64> = rpm.iter().map(|x| x / 9000.0).collect();
                let u15: Vec<f64> = u.iter().map(|x| x.powf(1.5)).collect();
                let fast = lag(&u, dt, 600.0, 0.0);
                let slow = lag(&u15, dt, 4800.0, 0.0);
                let mut run = Run::default();
                let col = |v: Vec<f64>| v.into_iter().map(Some).collect::<Vec<_>>();
                run.push_column("time_s", col((0..n).map(|k| k as f64 * dt).collect()))
                    .unwrap();
                run.push_column("spindle_rpm", col(rpm)).unwrap();
                for (name, a, b) in [("T_a", 6.0, 2.0), ("T_b", 1.0, 4.0)] {
                    let v = (0..n)
                        .map(|k| 20.0 + a * fast[k] + b * slow[k] + 0.02 * g.normal())
                        .collect();
                    run.push_column(name, col(v)).unwrap();
                }
                (format!("run{r}"), run)
            })
            .collect()
    }

    fn kept(levels: &[f64]) -> f64 {
        let ds = crate::diagnose::runs::load(&runs(levels, 3), 1500).unwrap();
        let p = Problem::new(&ds);
        let (st, _) = p.identify();
        speed_law_kept(&p, &st).unwrap().0
    }

    /// Two 8 h runs as `runs`, with a `T_ambient` column `amb(t)` (plus
    /// its sensor's noise) that both sensors follow through 2400 s.
    fn ambient_kept(amb: &dyn Fn(f64) -> f64) -> f64 {
        let mut g = tcomp_numerics::rng::Rng::paired(5);
        let dt = 30.0;
        let runs: Vec<(String, Run)> = (0..2)
            .map(|r| {
                let n = 960;
                let rpm: Vec<f64> = (0..n)
                    .map(|k| 9000.0 * [0.2, 1.0, 0.45, 0.0, 0.7, 0.3][(k / 80 + 3 * r) % 6])
                    .collect();
                let u: Vec<f64> = rpm.iter().map(|x| x / 9000.0).collect();
                let fast = lag(&u, dt, 600.0, 0.0);
                let a: Vec<f64> = (0..n).map(|k| amb(k as f64 * dt)).collect();
                let follow = lag(&a, dt, 2400.0, a[0]);
                let mut run = Run::default();
                let col = |v: Vec<f64>| v.into_iter().map(Some).collect::<Vec<_>>();
                run.push_column("time_s", col((0..n).map(|k| k as f64 * dt).collect()))
                    .unwrap();
                run.push_column("spindle_rpm", col(rpm)).unwrap();
                for (name, gain) in [("T_a", 6.0), ("T_b", 2.0)] {
                    let v = (0..n)
                        .map(|k| follow[k] + gain * fast[k] + 0.02 * g.normal())
                        .collect();
                    run.push_column(name, col(v)).unwrap();
                }
                let am = a.iter().map(|x| x + 0.02 * g.normal()).collect();
                run.push_column("T_ambient", col(am)).unwrap();
                (format!("run{r}"), run)
            })
            .collect();
        let ds = crate::diagnose::runs::load(&runs, 1500).unwrap();
        let p = Problem::new(&ds);
        let (st, _) = p.identify();
        ambient_drift_kept(&p, &st).unwrap().0
    }

    #[test]
    fn an_air_ramp_is_testable_unless_t_ambient_itself_ramps() {
        // a still room: T_ambient carries no ramp, so a ramp of the air
        // beyond it is left to the drift test
        let still = ambient_kept(&|_| 20.0);
        assert!(still >= AMBIENT_MIN_KEPT, "still room kept {still}");
        // T_ambient itself ramps over the runs: its free gain through the
        // nominal's modes reproduces any further ramp of the air
        let ramp = ambient_kept(&|t| 20.0 + 0.3 * t / 3600.0);
        assert!(ramp < AMBIENT_MIN_KEPT, "ramping T_ambient kept {ramp}");
    }

    #[test]
    fn speeds_spread_over_the_range_can_test_a_steeper_law_a_narrow_band_cannot() {
        // from a fifth of the top speed to the top: (n/n_max)^p bends away
        // from n and n^1.5 and the nominal cannot absorb it
        let wide = kept(&[0.2, 1.0, 0.45, 0.7, 0.3, 0.9]);
        assert!(wide >= SPEED_MIN_KEPT, "wide band kept {wide}");
        // 85–100 % of the top speed: every law is nearly a line there, so
        // the nominal's own speed terms absorb any steeper one
        let narrow = kept(&[0.85, 1.0, 0.9, 0.95]);
        assert!(narrow < SPEED_MIN_KEPT, "narrow band kept {narrow}");
        assert!(narrow < 0.5 * wide, "{narrow} vs {wide}");
    }
}

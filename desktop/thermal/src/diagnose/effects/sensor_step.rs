//! `sensor_offset`: a step in one sensor at one time of one run (an offset
//! that changes inside a run), located by a change-point scan of that
//! sensor's nominal residual on the fit rows.

use serde_json::json;

use super::candidate::{with_outputs, Candidate};
use crate::diagnose::ident::{ModelFit, Problem, Structure};
use crate::diagnose::signal::r4;

/// Smallest step claimed, in noise units and in °C (1/16 °C: one DS18B20 count).
pub const STEP_MIN_NOISE: f64 = 5.0;
pub const STEP_MIN_C: f64 = 0.125;

/// Smallest step claimed against the channel's remaining fit-row residual
/// RMS (with the step fitted): a fault stands out of what the model misses.
/// On the open-world benchmark (3 seeds) found steps stood at ≥ 6× that RMS,
/// and the steps the scan found on clean runs at ≤ 4.2×.
pub const STEP_MIN_MISFIT: f64 = 5.0;

/// A jump near an input change is taken for a step only by its excess over
/// this many times the sensor's largest jump near any other input change (on
/// clean open-world runs the first start from cold jumps up to 2× the rest).
const STEP_OVER_CHANGE_JUMPS: f64 = 3.0;

/// Rows on each side of a jump.
const JUMP_W: usize = 3;

fn window_mean(e: &[f64], a: usize, b: usize) -> f64 {
    crate::diagnose::signal::mean_finite(e[a..b].iter().copied())
}

/// How long after a run's first spindle start the nominal's misfit of the
/// start from cold may still read as a jump [s]: 2.5 × the shortest time
/// constant of its grid (on the first simulator's turning centre a heated
/// sensor read as a 0.18 °C step 100 s after the start). Other input
/// changes keep `JUMP_W + 1` rows: a longer window there hid real steps.
const AFTER_FIRST_START_S: f64 = 2.5 * crate::diagnose::ident::TAU_GRID[0];

/// Rows at least `JUMP_W + 1` rows away from any change of an input, and
/// `AFTER_FIRST_START_S` after the run's first spindle start.
fn quiet_rows(run: &crate::diagnose::runs::RunData) -> Vec<bool> {
    let n = run.rows();
    let mut quiet = vec![true; n];
    for inp in [&run.rpm, &run.feed, &run.coolant].into_iter().flatten() {
        for k in 1..n {
            if (inp[k] - inp[k - 1]).abs() > 1e-9 {
                let a = k.saturating_sub(JUMP_W + 1);
                let b = (k + JUMP_W + 1).min(n);
                quiet[a..b].iter_mut().for_each(|q| *q = false);
            }
        }
    }
    if let Some(k) = run
        .rpm
        .as_ref()
        .and_then(|rpm| (1..n).find(|&k| rpm[k - 1] == 0.0 && rpm[k] != 0.0))
    {
        let after = ((AFTER_FIRST_START_S / run.dt).ceil() as usize).max(JUMP_W + 1);
        quiet[k..(k + after).min(n)]
            .iter_mut()
            .for_each(|q| *q = false);
    }
    quiet
}

/// Step in one sensor: per sensor, the best change point on the fit rows,
/// then a joint refit of that sensor's model with the step column.
pub fn sensor_steps(p: &Problem, st: &Structure, nom: &ModelFit) -> Vec<Candidate> {
    let ds = p.ds;
    let mut out = Vec::new();
    for (o, output) in p.outputs.iter().enumerate() {
        if output.is_disp {
            continue;
        }
        // the sharpest jump of the nominal residual (mean of 3 rows after
        // minus 3 rows before); the rows place the time only, the size is
        // fitted on the fit rows. Near an input change the model's fast
        // dynamics may miss, so there a jump counts only by how far it
        // exceeds `STEP_OVER_CHANGE_JUMPS` × this sensor's largest jump near
        // every other input change (a fault that happens as the duty changes
        // is still found; a run's first start from cold, which the model
        // misses most, is not taken for one)
        let mut best: Option<(f64, usize, usize)> = None;
        // (run, row, |jump|, segment of rows near one input change or None)
        let mut jumps: Vec<(usize, usize, f64, Option<usize>)> = Vec::new();
        let mut segments = 0usize;
        for (r, run) in ds.runs.iter().enumerate() {
            let e = &nom.outs[o].resid[r];
            let quiet = quiet_rows(run);
            let mut in_segment = false;
            for k in JUMP_W..run.rows().saturating_sub(JUMP_W) {
                if !quiet[k] && !in_segment {
                    segments += 1;
                }
                in_segment = !quiet[k];
                let j = (window_mean(e, k, k + JUMP_W) - window_mean(e, k - JUMP_W, k)).abs();
                if j.is_finite() {
                    jumps.push((r, k, j, (!quiet[k]).then(|| segments - 1)));
                }
            }
        }
        let mut segment_max = vec![0.0f64; segments];
        for &(_, _, j, seg) in &jumps {
            if let Some(g) = seg {
                segment_max[g] = segment_max[g].max(j);
            }
        }
        for &(r, k, j, seg) in &jumps {
            let score = match seg {
                None => j,
                Some(g) => {
                    let others = segment_max
                        .iter()
                        .enumerate()
                        .filter(|&(h, _)| h != g)
                        .fold(0.0f64, |m, (_, &v)| m.max(v));
                    j - STEP_OVER_CHANGE_JUMPS * others
                }
            };
            if best.is_none_or(|b| score > b.0) {
                best = Some((score, r, k));
            }
        }
        let Some((_, r, start)) = best else {
            continue;
        };
        // the onset positions the search weighed inside held-out rows: an
        // onset found there was chosen on the rows that then judge it
        // (`fit_mode::undecided` corrects its held-out test for them)
        let onsets_held = jumps
            .iter()
            .filter(|&&(rr, k, _, _)| ds.runs[rr].held[k])
            .count();
        let run = &ds.runs[r];
        let extra = move |oo: usize, rr: usize| -> Vec<Vec<f64>> {
            if oo != o {
                return Vec::new();
            }
            let rows = ds.runs[rr].rows();
            vec![(0..rows)
                .map(|k| if rr == r && k >= start { 1.0 } else { 0.0 })
                .collect()]
        };
        let of = p.fit_output(st, o, Some(&extra), None);
        let step = of.extra_coef.first().copied().unwrap_or(0.0);
        // a step within a few noise steps is not a sensor fault
        if step.abs() < STEP_MIN_NOISE * output.noise || step.abs() < STEP_MIN_C {
            continue;
        }
        // nor is one within what the model still misses on that channel:
        // where the nominal is off by 0.1 °C a 0.15 °C "step" is its misfit
        let misfit = (of.sse_fit / of.n_fit.max(1) as f64).sqrt();
        if step.abs() < STEP_MIN_MISFIT * misfit {
            continue;
        }
        // a fault is a jump: the nominal residual must change by at least
        // half the step within ±3 rows of it (model error spreads out)
        let e = &nom.outs[o].resid[r];
        let jump = window_mean(e, start, (start + JUMP_W).min(run.rows()))
            - window_mean(e, start.saturating_sub(JUMP_W), start);
        if !(jump * step.signum() >= 0.5 * step.abs()) {
            continue;
        }
        let t_s = run.time[start] - run.time[0];
        // fit rows after the step: within one block's worth, the nominal's
        // slow modes can absorb it there (the held-out rows then decide)
        let fit_rows_after = (start..run.rows()).filter(|&k| !run.held[k]).count();
        let few_fit_rows_after = fit_rows_after * crate::diagnose::runs::BLOCKS <= run.rows();
        // an onset inside a held-out block shows on the fit rows only as a
        // level change between fit blocks (`fit_mode::undecided`)
        let onset_held = run.held[start];
        let fit = with_outputs(nom, vec![(o, of)]);
        out.push(Candidate {
            name: "sensor_offset",
            params: json!({"sensor": output.name, "offset_c": r4(step), "run": run.name, "from_s": r4(t_s)}),
            affected: vec![o],
            fit,
            // size + location (run, time)
            k_extra: 3,
            at_bound: Vec::new(),
            evidence: json!({"channel": output.name, "run": run.name, "from_s": r4(t_s), "fit_rows_after": fit_rows_after, "few_fit_rows_after": few_fit_rows_after, "onset_held": onset_held, "onsets_searched_held": onsets_held, "onsets_searched": jumps.len(), "step_over_misfit_rms": r4(step.abs() / misfit.max(1e-12)), "located_by": "sharpest jump of the sensor's nominal residual (3 rows after vs 3 before, all rows, away from input changes): the time only; the size is fitted on the fit rows, and the jump must be at least half of it"}),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_start_from_cold_is_not_quiet_for_longer_than_later_changes() {
        // 10 s rows: spindle starts at row 20, stops at row 60, starts again
        // at row 100
        let n = 200;
        let rpm: Vec<f64> = (0..n)
            .map(|k| {
                if (20..60).contains(&k) || k >= 100 {
                    6000.0
                } else {
                    0.0
                }
            })
            .collect();
        let run = crate::diagnose::runs::RunData {
            name: "r".into(),
            dt: 10.0,
            decimation: 1,
            time: (0..n).map(|k| k as f64 * 10.0).collect(),
            rpm: Some(rpm),
            feed: None,
            coolant: None,
            ambient: None,
            sensors: Vec::new(),
            disps: Vec::new(),
            held: vec![false; n],
        };
        let quiet = quiet_rows(&run);
        let after = (AFTER_FIRST_START_S / 10.0).ceil() as usize;
        assert!(after > JUMP_W + 1);
        // the first start: not quiet for AFTER_FIRST_START_S
        assert!((20..20 + after).all(|k| !quiet[k]));
        assert!(quiet[20 + after]);
        // a later change: JUMP_W + 1 rows on each side only
        assert!((96..100 + JUMP_W + 1).all(|k| !quiet[k]));
        assert!(quiet[100 + JUMP_W + 1] && quiet[95]);
    }
}

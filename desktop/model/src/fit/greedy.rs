//! Input choice for `--features auto`: blocked time folds of the training
//! rows, and the greedy forward selection that adds, one at a time, the
//! candidate that lowers the MLR's held-out error the most, within the
//! board's inputs.

use anyhow::{bail, Result};

use super::mlr::fit_mlr;
use super::model::Model;
use super::samples::{normalize_rows, ranged_specs, Samples, SeriesCache};
use super::split::Segment;
use tcomp_data::runcsv::Run;

/// Blocked K-fold over the training time span: each training segment is cut
/// into `k` consecutive time blocks; fold `f` validates on block `f` of every
/// segment and fits on the other blocks. Returns `(fit, validate)` per fold.
pub fn blocked_folds(
    runs: &[Run],
    train: &[Segment],
    k: usize,
) -> Vec<(Vec<Segment>, Vec<Segment>)> {
    let k = k.max(2);
    let mut folds = vec![(Vec::new(), Vec::new()); k];
    for seg in train {
        let t = runs[seg.run].time_s();
        if seg.end <= seg.start {
            continue;
        }
        let (t0, t1) = (t[seg.start], t[seg.end - 1]);
        let mut cuts = vec![seg.start];
        for f in 1..k {
            let ct = t0 + (t1 - t0) * f as f64 / k as f64;
            let c = (seg.start..seg.end).find(|&r| t[r] > ct).unwrap_or(seg.end);
            cuts.push(c.max(*cuts.last().unwrap_or(&seg.start)));
        }
        cuts.push(seg.end);
        for f in 0..k {
            for g in 0..k {
                let s = Segment {
                    run: seg.run,
                    start: cuts[g],
                    end: cuts[g + 1],
                };
                if s.end > s.start {
                    if g == f {
                        folds[f].1.push(s);
                    } else {
                        folds[f].0.push(s);
                    }
                }
            }
        }
    }
    folds
}

/// Rows (at most) each fold's fit and held-out parts use during input
/// selection and cross-validation; runs sampled densely are strided to it
/// (8,000 rows over a fold spanning hours are seconds apart, far below any
/// thermal time constant; FL_THERMAL's 15 s rows are never strided).
pub const SELECT_ROWS: usize = 8_000;

/// Sum of squared errors (and rows) of an MLR on candidate columns `idx`,
/// fitted on `tr`, scored on `va` (both gathered with every candidate).
fn mlr_block_sse(
    cache: &SeriesCache,
    tr: &Samples,
    va: &Samples,
    idx: &[usize],
    channel: &str,
) -> Result<(f64, usize)> {
    mlr_block_sse_cols(cache, tr, va, idx, idx, channel)
}

/// As [`mlr_block_sse`], with the rows' columns of candidates `idx` at
/// positions `cols`.
fn mlr_block_sse_cols(
    cache: &SeriesCache,
    tr: &Samples,
    va: &Samples,
    idx: &[usize],
    cols: &[usize],
    channel: &str,
) -> Result<(f64, usize)> {
    if tr.y.is_empty() || va.y.is_empty() {
        return Ok((0.0, 0));
    }
    let pick = |s: &Samples| Samples {
        x: s.x
            .iter()
            .map(|r| cols.iter().map(|&i| r[i]).collect())
            .collect(),
        y: s.y.clone(),
        rows: vec![],
    };
    let (tr, va) = (pick(tr), pick(va));
    let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
    let m = fit_mlr(ranged_specs(&kinds, &tr), &tr, channel)?;
    let xn = normalize_rows(&m.features, &va.x);
    let sse = xn
        .iter()
        .zip(&va.y)
        .map(|(r, t)| (m.predict_norm(r) - t).powi(2))
        .sum::<f64>();
    Ok((sse, va.y.len()))
}

/// Greedy forward selection: add the candidate that lowers the MLR error on
/// held-out time blocks of the training data the most (summed over `folds`);
/// stop at `max_inputs` or when the gain is below 1 %. Returns candidate
/// indices and their cross-validated mean squared error (µm²).
///
/// `in_use` are candidates other channels already put on the board (free to
/// share); any other candidate costs one of `new_budget` board inputs. Only
/// the first `n_candidates` of the cache are candidates (the others are the
/// lag grid's, which [`super::lags::choose_lags`] moves a chosen input to).
#[allow(clippy::too_many_arguments)]
pub fn greedy_select(
    cache: &SeriesCache,
    runs: &[Run],
    folds: &[(Vec<Segment>, Vec<Segment>)],
    channel: &str,
    max_inputs: usize,
    in_use: &[usize],
    new_budget: usize,
    n_candidates: usize,
) -> Result<(Vec<usize>, f64)> {
    // Each fold's rows, gathered once with every candidate (the rows do not
    // depend on the inputs).
    let n_candidates = n_candidates.min(cache.kinds.len());
    let all: Vec<usize> = (0..n_candidates).collect();
    let gathered = folds
        .iter()
        .map(|(fit, val)| {
            Ok((
                cache.samples_capped(runs, fit, &all, channel, SELECT_ROWS)?,
                cache.samples_capped(runs, val, &all, channel, SELECT_ROWS)?,
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut chosen: Vec<usize> = Vec::new();
    let mut best_err = f64::INFINITY;
    while chosen.len() < max_inputs {
        let mut round_best: Option<(usize, f64)> = None;
        let new_used = chosen.iter().filter(|c| !in_use.contains(c)).count();
        for c in 0..n_candidates {
            if chosen.contains(&c) || (!in_use.contains(&c) && new_used >= new_budget) {
                continue;
            }
            let mut idx = chosen.clone();
            idx.push(c);
            let (mut sse, mut n) = (0.0, 0usize);
            for (tr, va) in &gathered {
                let (s, k) = mlr_block_sse(cache, tr, va, &idx, channel)?;
                sse += s;
                n += k;
            }
            if n == 0 {
                bail!("channel {channel}: no rows with a value to select features on");
            }
            let err = sse / n as f64;
            if round_best.is_none_or(|(_, e)| err < e) {
                round_best = Some((c, err));
            }
        }
        match round_best {
            Some((c, e)) if e < best_err * 0.99 => {
                chosen.push(c);
                best_err = e;
            }
            _ => break,
        }
    }
    if chosen.is_empty() {
        bail!(
            "channel {channel}: no usable input found within the board's {} inputs",
            thermocomp_core::limits::MAX_INPUTS
        );
    }
    Ok((chosen, best_err))
}

/// The MLR's blocked-CV mean squared error (µm²) on candidates `idx` over
/// `folds` (what [`greedy_select`] reports for its choice).
pub fn blocked_mse(
    cache: &SeriesCache,
    runs: &[Run],
    folds: &[(Vec<Segment>, Vec<Segment>)],
    channel: &str,
    idx: &[usize],
) -> Result<f64> {
    let (mut sse, mut n) = (0.0, 0usize);
    for (fit, val) in folds {
        let tr = cache.samples_capped(runs, fit, idx, channel, SELECT_ROWS)?;
        let va = cache.samples_capped(runs, val, idx, channel, SELECT_ROWS)?;
        let pos: Vec<usize> = (0..idx.len()).collect();
        let (s, k) = mlr_block_sse_cols(cache, &tr, &va, idx, &pos, channel)?;
        sse += s;
        n += k;
    }
    if n == 0 {
        bail!("channel {channel}: no rows with a value to cross-validate on");
    }
    Ok(sse / n as f64)
}

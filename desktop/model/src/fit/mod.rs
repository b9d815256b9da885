//! `tcomp fit`: MLR baseline and the GA-BPN network (genetic search of the
//! initial weights, then Levenberg–Marquardt refinement), trained on the
//! board's own features ([`features`]: the math core's pipeline — 1/16 °C
//! readings, the reference row, gaps, lag filters per whole model step):
//! sensor rises / differences / spindle speed, optional first-order lags,
//! normalization of each input to [−1, 1] by its training range.
//!
//! Validation is always on held-out runs or later time blocks — never a random
//! row split.

pub mod choice;
pub mod fallback;
pub mod features;
pub mod model;
pub mod net;
pub mod pipeline;
pub mod plan;
pub mod split;

use anyhow::{bail, Context, Result};

use serde::{Deserialize, Serialize};

use tcomp_data::runcsv::Run;

// The fit's types and its run splits, at `fit::` as before they had files of their own.
pub use model::*;
pub use split::*;

// ------------------------------------------------------------------ features

/// The raw (un-normalized) input series of one feature over a whole run, as
/// the board computes it ([`features::board_series`]): °C or rpm, NaN on rows
/// where the board computes no feature.
pub fn feature_series(run: &Run, kind: &FeatureKind, tau_s: Option<f64>) -> Result<Vec<f64>> {
    let mut s = features::board_series(run, &[(kind.clone(), tau_s)])?;
    Ok(s.pop().unwrap_or_default())
}

/// Several features' series over a run: `out[feature][row]`.
pub fn feature_columns(run: &Run, kinds: &[(FeatureKind, Option<f64>)]) -> Result<Vec<Vec<f64>>> {
    features::board_series(run, kinds)
}

/// Predict a whole run on the board's features (NaN on rows with a sensor gap).
pub fn predict_run<M: Model + ?Sized>(m: &M, run: &Run) -> Result<Vec<f64>> {
    let kinds: Vec<_> = m
        .features()
        .iter()
        .map(|f| (f.kind.clone(), f.tau_s))
        .collect();
    let cols = feature_columns(run, &kinds)?;
    Ok((0..run.rows())
        .map(|r| {
            let x: Vec<f64> = cols.iter().map(|c| c[r]).collect();
            m.predict_raw(&x)
        })
        .collect())
}

// ------------------------------------------------------------------- samples

/// Rows gathered from segments: raw inputs, target (µm) and where they came from.
#[derive(Clone, Debug, Default)]
pub struct Samples {
    pub x: Vec<Vec<f64>>,
    pub y: Vec<f64>,
    /// (run index, row index) of each sample.
    pub rows: Vec<(usize, usize)>,
}

/// Precomputed input series: `series[feature][run][row]`.
pub struct SeriesCache {
    pub kinds: Vec<(FeatureKind, Option<f64>)>,
    pub series: Vec<Vec<Vec<f64>>>,
}

impl SeriesCache {
    pub fn new(runs: &[Run], kinds: Vec<(FeatureKind, Option<f64>)>) -> Result<SeriesCache> {
        let mut series = vec![Vec::with_capacity(runs.len()); kinds.len()];
        for run in runs {
            for (f, col) in feature_columns(run, &kinds)?.into_iter().enumerate() {
                series[f].push(col);
            }
        }
        Ok(SeriesCache { kinds, series })
    }

    /// The board computes features `idx` at row `r` of run `run` (no gap).
    #[inline]
    fn usable(&self, idx: &[usize], run: usize, r: usize) -> bool {
        idx.iter().all(|&f| self.series[f][run][r].is_finite())
    }

    /// Samples of features `idx` over the segments; rows without a target or
    /// where the board computes no feature (a sensor gap) are skipped.
    pub fn samples(
        &self,
        runs: &[Run],
        segs: &[Segment],
        idx: &[usize],
        channel: &str,
    ) -> Result<Samples> {
        self.samples_capped(runs, segs, idx, channel, usize::MAX)
    }

    /// As [`SeriesCache::samples`], but every k-th row with a target so that
    /// at most `max_rows` are gathered (selection and cross-validation on a
    /// densely sampled run: the rows are far closer than any time constant).
    pub fn samples_capped(
        &self,
        runs: &[Run],
        segs: &[Segment],
        idx: &[usize],
        channel: &str,
        max_rows: usize,
    ) -> Result<Samples> {
        // One pass finds the usable rows (every feature computed, a target
        // present); the stride then picks from them without testing again.
        let mut usable: Vec<(usize, usize, f64)> = Vec::new();
        for seg in segs {
            let y = runs[seg.run]
                .col(channel)
                .with_context(|| format!("run {} has no column `{channel}`", seg.run + 1))?;
            usable.extend((seg.start..seg.end).filter_map(|r| {
                let t = y[r]?;
                self.usable(idx, seg.run, r).then_some((seg.run, r, t))
            }));
        }
        let stride = usable.len().div_ceil(max_rows.max(1)).max(1);
        let mut s = Samples::default();
        for &(run, r, t) in usable.iter().step_by(stride) {
            s.x.push(idx.iter().map(|&f| self.series[f][run][r]).collect());
            s.y.push(t);
            s.rows.push((run, r));
        }
        Ok(s)
    }
}

impl Samples {
    /// Every k-th row so that at most `max_rows` remain (thermal runs are
    /// sampled far faster than their time constants: an evenly strided
    /// subset carries nearly all the information at a fraction of the cost).
    pub fn strided(&self, max_rows: usize) -> Samples {
        let stride = self.y.len().div_ceil(max_rows.max(1)).max(1);
        if stride == 1 {
            return self.clone();
        }
        Samples {
            x: self.x.iter().step_by(stride).cloned().collect(),
            y: self.y.iter().step_by(stride).copied().collect(),
            rows: self.rows.iter().step_by(stride).copied().collect(),
        }
    }
}

/// Feature specs with ranges from the training samples.
pub fn ranged_specs(kinds: &[(FeatureKind, Option<f64>)], train: &Samples) -> Vec<FeatureSpec> {
    kinds
        .iter()
        .enumerate()
        .map(|(i, (k, t))| {
            let mut min = f64::INFINITY;
            let mut max = f64::NEG_INFINITY;
            for r in &train.x {
                min = min.min(r[i]);
                max = max.max(r[i]);
            }
            if !min.is_finite() {
                (min, max) = (0.0, 1.0);
            }
            FeatureSpec {
                kind: k.clone(),
                tau_s: *t,
                min,
                max,
            }
        })
        .collect()
}

pub fn normalize_rows(specs: &[FeatureSpec], x: &[Vec<f64>]) -> Vec<Vec<f64>> {
    x.iter()
        .map(|r| specs.iter().zip(r).map(|(f, &v)| f.normalize(v)).collect())
        .collect()
}

// ----------------------------------------------------------------------- MLR

/// Least-squares MLR on normalized inputs.
pub fn fit_mlr(specs: Vec<FeatureSpec>, train: &Samples, channel: &str) -> Result<MlrParams> {
    let xn = normalize_rows(&specs, &train.x);
    let c = tcomp_data::linalg::least_squares(&xn, &train.y, true, 1e-9 * train.y.len() as f64)
        .with_context(|| format!("channel {channel}: linear fit"))?;
    Ok(MlrParams {
        features: specs,
        c0: c[0],
        coef: c[1..].to_vec(),
        channel: channel.to_string(),
    })
}

// ------------------------------------------------------------------- metrics

/// Validation figures of one channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub mae_um: f64,
    pub rms_um: f64,
    pub peak_um: f64,
    /// 100·(1 − RMS residual / RMS raw error).
    pub reduction_pct: f64,
    pub raw_rms_um: f64,
    pub n: usize,
}

pub fn metrics(y: &[f64], pred: &[f64]) -> Metrics {
    let n = y.len();
    if n == 0 {
        return Metrics::default();
    }
    let (mut sa, mut s2, mut peak, mut r2) = (0.0, 0.0, 0.0f64, 0.0);
    for (&t, &p) in y.iter().zip(pred) {
        let e = t - p;
        sa += e.abs();
        s2 += e * e;
        peak = peak.max(e.abs());
        r2 += t * t;
    }
    let rms = (s2 / n as f64).sqrt();
    let raw = (r2 / n as f64).sqrt();
    Metrics {
        mae_um: sa / n as f64,
        rms_um: rms,
        peak_um: peak,
        reduction_pct: if raw > 0.0 {
            100.0 * (1.0 - rms / raw)
        } else {
            0.0
        },
        raw_rms_um: raw,
        n,
    }
}

// ------------------------------------------------------------ feature choice

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
    if tr.y.is_empty() || va.y.is_empty() {
        return Ok((0.0, 0));
    }
    let pick = |s: &Samples| Samples {
        x: s.x
            .iter()
            .map(|r| idx.iter().map(|&i| r[i]).collect())
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
/// share); any other candidate costs one of `new_budget` board inputs.
pub fn greedy_select(
    cache: &SeriesCache,
    runs: &[Run],
    folds: &[(Vec<Segment>, Vec<Segment>)],
    channel: &str,
    max_inputs: usize,
    in_use: &[usize],
    new_budget: usize,
) -> Result<(Vec<usize>, f64)> {
    // Each fold's rows, gathered once with every candidate (the rows do not
    // depend on the inputs).
    let all: Vec<usize> = (0..cache.kinds.len()).collect();
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
        for c in 0..cache.kinds.len() {
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

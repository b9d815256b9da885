//! The output low-pass per channel (issue 51 item 1): a causal first-order
//! lag on the chosen model's correction, chosen by the forward-chaining CV
//! over the training blocks, or none.
//!
//! Why: a model whose temperature inputs respond faster than the structure
//! moves serves a wobble of minutes that is in the model, not in the
//! machine (FL_THERMAL ch5: ~12 min). About an hourly reference that wobble
//! is most of what is left. Lagging each input separately costs a board
//! input per lagged copy (the 12-input limit then drops fallbacks); a lag
//! on the output is one state per direction, and for a linear model it is
//! the same as the same lag on every input.
//!
//! The rule is the per-input lag search's ([`super::lags`]): on the
//! training rows' forward folds (fit on the blocks before, validate on the
//! next) the chosen inputs' linear model (`mlr`, `mlr-static`; a `ridge`
//! refitted with its chosen penalty) is validated with
//! its output low-passed at each candidate time constant; a candidate is
//! kept only when the error about each hour's anchor (what a reference
//! leaves) is lower by more than 1 % pooled and, fold by fold, beyond 2
//! standard errors of the paired log ratios, and the plain error (what a
//! board without references serves) is not higher by more than 1 % pooled.
//! Of those, the largest anchored gain. (The per-input lag search asks a
//! gain of both errors: a new input can fit the drift better. A low-pass of
//! the same output cannot: it only trades, so the plain error guards
//! against a loss and the anchored error must show the gain.) No lag for
//! networks (their stand-in would not be the served function).

use std::collections::BTreeMap;

use anyhow::Result;
use tcomp_data::runcsv::Run;

use super::envelope::ChosenInfo;
use super::greedy::blocked_folds;
use super::lags::{anchors, gain_beyond_noise, log_ratios, FoldScores, ANCHOR_S, MIN_GAIN};
use super::mlr::fit_mlr;
use super::model::{FeatureSpec, MlrParams, Model, ModelFile};
use super::ridge::{all_blocks, fit_ridge, forward_folds};
use super::samples::{ranged_specs, Samples, SeriesCache};
use super::split::Segment;

/// Candidate time constants, seconds (a geometric-ish grid from 5 min to
/// 30 min: the fast responses a reference cannot remove).
pub const OUTPUT_TAUS_S: [f64; 5] = [300.0, 600.0, 900.0, 1200.0, 1800.0];
/// Time blocks the training rows are cut into (the fit's default).
const BLOCKS: usize = 5;

/// What the choice found for one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputLag {
    /// Chosen time constant, seconds (0: none).
    pub tau_s: f64,
    /// Forward-CV RMS (µm) plain and about each hour's anchor, without and
    /// with the chosen lag.
    pub before: (f64, f64),
    pub after: (f64, f64),
}

/// The linear chosen model's inputs of `ch` (None for any other model).
fn linear_features<'a>(file: &'a ModelFile, ch: &str) -> Option<&'a [FeatureSpec]> {
    let pick = |v: &'a [MlrParams]| v.iter().find(|m| m.channel == ch);
    match file.chosen.get(ch).map(String::as_str) {
        Some("mlr") => Some(&pick(&file.mlr)?.features),
        Some("mlr-static") => Some(&pick(&file.mlr_static)?.features),
        Some("ridge") => Some(&pick(&file.ridge)?.features),
        _ => None,
    }
}

/// Per linear chosen channel, the output lag the forward folds support.
pub fn choose(
    runs: &[Run],
    train: &[Segment],
    file: &ModelFile,
    chosen: &BTreeMap<String, ChosenInfo>,
) -> Result<BTreeMap<String, OutputLag>> {
    let blocks = all_blocks(&blocked_folds(runs, train, BLOCKS));
    let folds = forward_folds(&blocks);
    let mut out = BTreeMap::new();
    for ch in file.chosen.keys() {
        let Some(feats) = linear_features(file, ch) else {
            continue;
        };
        let kinds: Vec<_> = feats.iter().map(|f| (f.kind.clone(), f.tau_s)).collect();
        let cache = SeriesCache::new(runs, kinds.clone())?;
        let idx: Vec<usize> = (0..kinds.len()).collect();
        let mut rows = Vec::new();
        for (fit, val) in &folds {
            let tr = cache.samples(runs, fit, &idx, ch)?;
            let va = cache.samples(runs, val, &idx, ch)?;
            if tr.y.len() < 2 * idx.len() + 2 || va.y.is_empty() {
                continue;
            }
            let specs = ranged_specs(&kinds, &tr);
            let m = match chosen.get(ch).and_then(|c| c.ridge_penalty) {
                Some(l) => fit_ridge(specs, &tr, l, ch)?,
                None => fit_mlr(specs, &tr, ch)?,
            };
            let pred: Vec<f64> = va.x.iter().map(|x| m.predict_raw(x)).collect();
            rows.push((va, pred));
        }
        let score = |tau: f64| fold_scores(runs, &rows, tau);
        let base = score(0.0);
        if base.rows.len() < 2 {
            continue;
        }
        let best = OUTPUT_TAUS_S
            .iter()
            .filter_map(|&tau| {
                let s = score(tau);
                anchored_gain_no_loss(&s, &base).map(|g| (tau, s, g))
            })
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let rms = |s: &FoldScores| {
            let p = s.pooled();
            (p.plain.sqrt(), p.anchored.sqrt())
        };
        let before = rms(&base);
        let (tau_s, after) = best.map_or((0.0, before), |(t, s, _)| (t, rms(&s)));
        out.insert(
            ch.clone(),
            OutputLag {
                tau_s,
                before,
                after,
            },
        );
    }
    Ok(out)
}

/// The anchored gain of `new` over `old` (the mean per-fold log ratio's
/// opposite) when it is one beyond the fold-to-fold noise and the pooled
/// plain error is not higher by more than [`MIN_GAIN`].
fn anchored_gain_no_loss(new: &FoldScores, old: &FoldScores) -> Option<f64> {
    if new.rows != old.rows {
        return None;
    }
    let (n, o) = (new.pooled(), old.pooled());
    if n.plain > o.plain * (1.0 + MIN_GAIN) || n.anchored >= o.anchored * (1.0 - MIN_GAIN) {
        return None;
    }
    gain_beyond_noise(&log_ratios(&new.anchored, &old.anchored))
}

/// Causal first-order lag of `pred` over the rows of `s` (time from each
/// row's run; restarted at a new run or a step back in time), as the board
/// filters its served correction: exact for a zero-order-held input.
pub fn low_pass(runs: &[Run], s: &Samples, pred: &[f64], tau_s: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(pred.len());
    let mut prev: Option<(usize, f64, f64)> = None;
    for (&(run, r), &p) in s.rows.iter().zip(pred) {
        let t = runs[run].time_at(r);
        let v = match prev {
            Some((pr, pt, pv)) if tau_s > 0.0 && pr == run && t >= pt => {
                pv + (1.0 - (-(t - pt) / tau_s).exp()) * (p - pv)
            }
            _ => p,
        };
        out.push(v);
        prev = Some((run, t, v));
    }
    out
}

/// Held-out errors per fold with the predictions low-passed at `tau_s`.
fn fold_scores(runs: &[Run], rows: &[(Samples, Vec<f64>)], tau_s: f64) -> FoldScores {
    let mut out = FoldScores::default();
    for (va, pred) in rows {
        let f = low_pass(runs, va, pred, tau_s);
        let e: Vec<f64> = va.y.iter().zip(&f).map(|(y, p)| y - p).collect();
        let an = anchors(runs, va, ANCHOR_S);
        let n = e.len() as f64;
        out.plain.push(e.iter().map(|v| v * v).sum::<f64>() / n);
        let anchored = e.iter().zip(&an).map(|(v, &a)| (v - e[a]).powi(2));
        out.anchored.push(anchored.sum::<f64>() / n);
        out.rows.push(e.len());
    }
    out
}

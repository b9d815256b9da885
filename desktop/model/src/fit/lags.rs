//! A lag per input, chosen by cross-validation (issues 50 item 5, 51 item 1).
//!
//! The greedy forward selection ([`super::greedy`]) picks inputs among the
//! coarse lags of `FitConfig::lags`; a denser grid there lets it stack two
//! lags of one sensor (near-collinear) instead of finding the right one.
//! Here each chosen input keeps its sensor (or the spindle speed) and only
//! its first-order lag moves along `FitConfig::lag_grid` (geometric, minutes
//! to hours: sensor, housing and structure time constants): one input at a
//! time, scored by the MLR over the forward-chaining time-blocked folds of
//! the training rows ([`super::ridge::forward_folds`]: every fold forecasts
//! later blocks from earlier ones) on two errors: the held-out error, and
//! the held-out error about its value at the start of each hour
//! ([`ANCHOR_S`]: what a reference leaves, the model's fast response). The
//! lag with the lowest anchored error among those that do not raise the
//! plain error by more than [`MIN_GAIN`] is kept when it lowers the anchored
//! error by more than [`MIN_GAIN`]; passes repeat until no input moves. The
//! ridge candidate reads the same inputs, so it gets the same lags. Only
//! training rows are read: the lag filters are causal, so no held-out row
//! feeds a training row's feature.
//!
//! Off by default (`FitConfig::lag_grid` empty; `tcomp fit --lag-grid`):
//! on FL_THERMAL the fold errors do not single out the 15-min lags that
//! halve ch5's error under hourly references, and the moves they do make
//! raise the held-out error without references (BENCHMARKS.md).

use anyhow::Result;

use super::greedy::SELECT_ROWS;
use super::mlr::fit_mlr;
use super::model::{feature_name, Model};
use super::ridge::{all_blocks, forward_folds};
use super::samples::{normalize_rows, ranged_specs, Samples, SeriesCache};
use super::split::Segment;
use tcomp_data::runcsv::Run;

/// The default lag grid, seconds: 0 (no lag), then 225 s · 2^k up to 8 h —
/// a DS18B20 in its housing (minutes), a spindle cartridge or slide
/// (quarter to one hour), a column or bed (hours). Geometric, so each
/// decade of time constants gets the same share of candidates.
pub const LAG_GRID: [f64; 9] = [
    0.0, 225.0, 450.0, 900.0, 1800.0, 3600.0, 7200.0, 14400.0, 28800.0,
];

/// A new lag is kept only when it lowers the forward-chaining CV error by
/// more than this fraction (the greedy selection's own stopping gain).
pub const MIN_GAIN: f64 = 0.01;

/// The window of the anchored error, seconds: one hour, the reference
/// interval the probe loop is held to (issue 51: hourly references, the
/// board asking at most ~70 min apart). Within it only the model's response
/// to changes over minutes to an hour counts, not the slow drift a
/// reference removes.
pub const ANCHOR_S: f64 = 3600.0;

/// Passes over the inputs at most (each pass moves every input once).
const MAX_PASSES: usize = 3;

/// One input whose lag the cross-validation moved.
#[derive(Clone, Debug, PartialEq)]
pub struct LagMove {
    /// Position in the channel's inputs.
    pub input: usize,
    /// Candidate index before and after.
    pub from: usize,
    pub to: usize,
    /// Forward-chaining CV errors before and after.
    pub before: LagScore,
    pub after: LagScore,
}

/// The fold rows of the forward-chaining CV over the training blocks of
/// `folds`, gathered once with every candidate, with each held-out row's
/// anchor (the first row of its [`ANCHOR_S`] window).
struct ForwardRows {
    folds: Vec<(Samples, Samples, Vec<usize>)>,
}

/// Two CV errors of one set of inputs (mean squared, µm²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagScore {
    /// The held-out error itself.
    pub plain: f64,
    /// The held-out error about its value at the start of each
    /// [`ANCHOR_S`] window: what is left after a reference re-anchors the
    /// correction (the model's fast response).
    pub anchored: f64,
}

/// Each held-out row's anchor: the first row of its window of `window_s`
/// seconds (a new window at each new run, backwards step in time, or once
/// `window_s` has passed since the anchor).
fn anchors(runs: &[Run], s: &Samples, window_s: f64) -> Vec<usize> {
    let mut out = Vec::with_capacity(s.rows.len());
    let mut a = 0usize;
    for (k, &(run, r)) in s.rows.iter().enumerate() {
        let t = runs[run].time_s()[r];
        let (ar, arow) = s.rows[a];
        let ta = runs[ar].time_s()[arow];
        if k == 0 || ar != run || t < ta || t - ta >= window_s {
            a = k;
        }
        out.push(a);
    }
    out
}

impl ForwardRows {
    fn new(
        cache: &SeriesCache,
        runs: &[Run],
        folds: &[(Vec<Segment>, Vec<Segment>)],
        cols: &[usize],
        channel: &str,
    ) -> Result<ForwardRows> {
        let blocks = all_blocks(folds);
        let folds = forward_folds(&blocks)
            .iter()
            .map(|(fit, val)| {
                let va = cache.samples_capped(runs, val, cols, channel, SELECT_ROWS)?;
                let an = anchors(runs, &va, ANCHOR_S);
                Ok((
                    cache.samples_capped(runs, fit, cols, channel, SELECT_ROWS)?,
                    va,
                    an,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ForwardRows { folds })
    }

    /// Pooled held-out errors of the MLR on columns `pick` (positions into
    /// the gathered columns); `None` when no fold has rows enough.
    fn score(
        &self,
        cache: &SeriesCache,
        cols: &[usize],
        pick: &[usize],
        ch: &str,
    ) -> Option<LagScore> {
        let (mut sse, mut ssa, mut n) = (0.0, 0.0, 0usize);
        let kinds: Vec<_> = pick.iter().map(|&p| cache.kinds[cols[p]].clone()).collect();
        for (tr, va, an) in &self.folds {
            if tr.y.len() < 2 * pick.len() + 2 || va.y.is_empty() {
                continue;
            }
            let sel = |s: &Samples| -> Vec<Vec<f64>> {
                s.x.iter()
                    .map(|r| pick.iter().map(|&p| r[p]).collect())
                    .collect()
            };
            let trs = Samples {
                x: sel(tr),
                y: tr.y.clone(),
                rows: vec![],
            };
            let m = fit_mlr(ranged_specs(&kinds, &trs), &trs, ch).ok()?;
            let xn = normalize_rows(&m.features, &sel(va));
            let e: Vec<f64> = xn
                .iter()
                .zip(&va.y)
                .map(|(r, y)| y - m.predict_norm(r))
                .collect();
            sse += e.iter().map(|v| v * v).sum::<f64>();
            ssa += e
                .iter()
                .zip(an)
                .map(|(v, &a)| (v - e[a]).powi(2))
                .sum::<f64>();
            n += va.y.len();
        }
        (n > 0).then(|| LagScore {
            plain: sse / n as f64,
            anchored: ssa / n as f64,
        })
    }
}

/// Moves the lag of each input of `idx` (candidate indices into `cache`)
/// to the one the forward-chaining CV over the training blocks of `folds`
/// prefers, among the candidates of the same kind in `cache`. A candidate
/// not in `in_use` costs one of `budget` new board inputs (as in the greedy
/// selection); two inputs never share a candidate. Returns the new inputs
/// and the moves made (none when the folds have too few rows).
pub fn choose_lags(
    cache: &SeriesCache,
    runs: &[Run],
    folds: &[(Vec<Segment>, Vec<Segment>)],
    channel: &str,
    idx: &[usize],
    in_use: &[usize],
    budget: usize,
) -> Result<(Vec<usize>, Vec<LagMove>)> {
    let mut idx = idx.to_vec();
    // Columns gathered: every candidate of the same kind as an input.
    let cols: Vec<usize> = (0..cache.kinds.len())
        .filter(|&c| idx.iter().any(|&i| cache.kinds[i].0 == cache.kinds[c].0))
        .collect();
    let pos = |c: usize| cols.iter().position(|&x| x == c);
    let rows = ForwardRows::new(cache, runs, folds, &cols, channel)?;
    let to_pick = |idx: &[usize]| -> Vec<usize> { idx.iter().filter_map(|&c| pos(c)).collect() };
    let Some(mut best) = rows.score(cache, &cols, &to_pick(&idx), channel) else {
        return Ok((idx, vec![]));
    };
    let mut moves = Vec::new();
    for _ in 0..MAX_PASSES {
        let mut moved = false;
        for k in 0..idx.len() {
            let mut round: Option<(usize, LagScore)> = None;
            for &c in &cols {
                if idx.contains(&c) || cache.kinds[c].0 != cache.kinds[idx[k]].0 {
                    continue;
                }
                let mut trial = idx.clone();
                trial[k] = c;
                if trial.iter().filter(|i| !in_use.contains(i)).count() > budget {
                    continue;
                }
                let Some(e) = rows.score(cache, &cols, &to_pick(&trial), channel) else {
                    continue;
                };
                // The plain error may not rise beyond the gain (no trade of
                // the drift for the fast response).
                let ok = e.plain <= best.plain * (1.0 + MIN_GAIN);
                if ok && round.is_none_or(|(_, r)| e.anchored < r.anchored) {
                    round = Some((c, e));
                }
            }
            if let Some((c, e)) = round {
                if e.anchored < best.anchored * (1.0 - MIN_GAIN) {
                    moves.push(LagMove {
                        input: k,
                        from: idx[k],
                        to: c,
                        before: best,
                        after: e,
                    });
                    idx[k] = c;
                    best = e;
                    moved = true;
                }
            }
        }
        if !moved {
            break;
        }
    }
    Ok((idx, moves))
}

/// The note a channel's lag moves leave in the fit's report.
pub fn lag_note(channel: &str, cache: &SeriesCache, moves: &[LagMove]) -> String {
    let name = |c: usize| feature_name(&cache.kinds[c].0, cache.kinds[c].1);
    let list: Vec<String> = moves
        .iter()
        .map(|m| {
            format!(
                "{} -> {} (CV RMS {:.2} -> {:.2} µm, about each {:.0}-min anchor {:.2} -> {:.2} µm)",
                name(m.from),
                name(m.to),
                m.before.plain.sqrt(),
                m.after.plain.sqrt(),
                ANCHOR_S / 60.0,
                m.before.anchored.sqrt(),
                m.after.anchored.sqrt()
            )
        })
        .collect();
    format!(
        "{channel}: input lags chosen by forward-chaining CV on the training blocks: {}",
        list.join(", ")
    )
}

//! `tcomp fit`: MLR baseline and the GA-BPN network (genetic search of the
//! initial weights, then Levenberg–Marquardt refinement), trained on the
//! board's own features ([`features`]: the math core's pipeline — 1/16 °C
//! readings, the reference row, gaps, lag filters per whole model step):
//! sensor rises / differences / spindle speed, optional first-order lags,
//! normalization of each input to [−1, 1] by its training range.
//!
//! Validation is always on held-out runs or later time blocks — never a random
//! row split.

pub mod cli;
pub mod fallback;
pub mod features;
pub mod net;
pub mod rng;
pub mod run;

use std::ops::Range;

use anyhow::{bail, Context, Result};

use serde::{Deserialize, Serialize};

use crate::runcsv::Run;

// ---------------------------------------------------------------- model types

/// What an input measures (before the optional lag).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum FeatureKind {
    /// `T_i(t) − T_i(t_ref)`, `t_ref` = the board's reference row: the first
    /// row of the run at which the sensors are valid (column name).
    SensorRise(String),
    /// `T_a − T_b` (column names).
    SensorDiff(String, String),
    /// Spindle speed, rpm.
    Spindle,
}

/// One network / MLR input: kind, optional first-order lag, training range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureSpec {
    pub kind: FeatureKind,
    /// First-order lag time constant in seconds (`None`: no lag).
    pub tau_s: Option<f64>,
    /// Training range: inputs are clamped to it and mapped to [−1, 1].
    pub min: f64,
    pub max: f64,
}

/// The n_in–n_hidden–1 network of one displacement channel:
/// `h_j = sigmoid(b1_j + Σ_i W1[j][i]·xn_i)`, `y_um = b2 + Σ_j w2_j·h_j`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetParams {
    pub features: Vec<FeatureSpec>,
    /// `w1[j][i]`: hidden unit j, input i.
    pub w1: Vec<Vec<f64>>,
    pub b1: Vec<f64>,
    pub w2: Vec<f64>,
    pub b2: f64,
    /// Displacement column this network predicts (e.g. `dch3_um`).
    pub channel: String,
}

/// Multiple linear regression of one channel: `y_um = c0 + Σ c_i·xn_i`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlrParams {
    pub features: Vec<FeatureSpec>,
    pub c0: f64,
    pub coef: Vec<f64>,
    pub channel: String,
}

/// What `fit --out` writes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Lagged MLR per channel (model name `mlr`).
    pub mlr: Vec<MlrParams>,
    /// Ensemble members per channel (model name `ga-bpn`): the channel's
    /// prediction is the mean of its members.
    pub nets: Vec<NetParams>,
    /// Static MLR on the selected sensors per channel (model name `mlr-static`).
    #[serde(default)]
    pub mlr_static: Vec<MlrParams>,
    /// The model blocked cross-validation on the training rows chose per
    /// channel (`mlr-static`, `mlr`, `hybrid` or `ga-bpn`); what `export`
    /// ships by default.
    #[serde(default)]
    pub chosen: std::collections::BTreeMap<String, String>,
    /// Residual networks per channel (model name `hybrid`): the channel's
    /// hybrid prediction is its lagged MLR (`mlr`) plus the mean of these
    /// members, trained on the MLR's training residual. The board sums a
    /// table and networks of the same direction, so it ships as both.
    #[serde(default)]
    pub hybrid_nets: Vec<NetParams>,
    /// Per channel, the blend's weight `w` on the lagged MLR (model name
    /// `blend`: `w·mlr + (1−w)·ga-bpn`, the same inputs), chosen on the
    /// out-of-fold predictions of the blocked cross-validation.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub blend: std::collections::BTreeMap<String, f64>,
    /// Per channel, models without each of its sensors (degraded mode, issue 15).
    #[serde(default)]
    pub fallbacks: Vec<fallback::FallbackParams>,
}

/// Model names, simplest first (the order ties are broken in): `none` (no
/// compensation: the board serves 0 about the run's reference) is the
/// simplest of all, so a model must beat it by more than the margin to ship;
/// the hybrid is
/// anchored on the lagged MLR (its network only corrects the residual), so it
/// is taken as simpler than the free network; the blend carries both the
/// lagged MLR's table and the networks, so it comes last: it is chosen only
/// when it beats each of its parts by more than the margin.
pub const MODEL_NAMES: [&str; 6] = ["none", "mlr-static", "mlr", "hybrid", "ga-bpn", "blend"];

/// `w·mlr + (1−w)·ensemble` on the same inputs (model name `blend`). The
/// board ships it as the MLR's table with every term scaled by `w` and the
/// networks with their output layers scaled by `(1−w)/k`: one direction's
/// table and networks, which it sums.
pub struct Blend<'a> {
    pub mlr: &'a MlrParams,
    pub nets: NetEnsemble<'a>,
    pub w: f64,
}

impl<'a> Blend<'a> {
    /// The blend of `channel` in a fit file (None without its parts).
    pub fn of(file: &'a ModelFile, channel: &str) -> Option<Self> {
        let mlr = file.mlr.iter().find(|m| m.channel == channel)?;
        let nets = NetEnsemble::of(&file.nets, channel)?;
        let w = *file.blend.get(channel)?;
        Some(Blend { mlr, nets, w })
    }
}

impl Model for Blend<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.mlr.features
    }
    fn channel(&self) -> &str {
        &self.mlr.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.w * self.mlr.predict_norm(xn) + (1.0 - self.w) * self.nets.predict_norm(xn)
    }
}

/// The weight `w ∈ [0, 1]` minimising `Σ (y − w·a − (1−w)·b)²` over the
/// given `(y, a, b)` rows (least squares in one unknown, clamped); 1 (all
/// `a`) when `a` and `b` never differ.
pub fn blend_weight<'a>(rows: impl Iterator<Item = (&'a f64, &'a f64, &'a f64)>) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (y, a, b) in rows {
        let d = a - b;
        num += (y - b) * d;
        den += d * d;
    }
    if den > 0.0 && num.is_finite() {
        (num / den).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Lagged MLR plus a network ensemble on its residual, same inputs.
pub struct Hybrid<'a> {
    pub mlr: &'a MlrParams,
    pub residual: NetEnsemble<'a>,
}

impl<'a> Hybrid<'a> {
    /// The hybrid of `channel` in a fit file (None without its parts).
    pub fn of(file: &'a ModelFile, channel: &str) -> Option<Self> {
        let mlr = file.mlr.iter().find(|m| m.channel == channel)?;
        let residual = NetEnsemble::of(&file.hybrid_nets, channel)?;
        Some(Hybrid { mlr, residual })
    }
}

impl Model for Hybrid<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.mlr.features
    }
    fn channel(&self) -> &str {
        &self.mlr.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.mlr.predict_norm(xn) + self.residual.predict_norm(xn)
    }
}

/// The networks of one channel, averaged: the ensemble that goes on the board.
pub struct NetEnsemble<'a> {
    pub members: Vec<&'a NetParams>,
}

impl<'a> NetEnsemble<'a> {
    /// The members fitted for `channel` (None if there are none).
    pub fn of(nets: &'a [NetParams], channel: &str) -> Option<Self> {
        let members: Vec<&NetParams> = nets.iter().filter(|n| n.channel == channel).collect();
        (!members.is_empty()).then_some(NetEnsemble { members })
    }
}

impl Model for NetEnsemble<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.members[0].features
    }
    fn channel(&self) -> &str {
        &self.members[0].channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        let k = self.members.len() as f64;
        self.members.iter().map(|m| m.predict_norm(xn)).sum::<f64>() / k
    }
}

impl FeatureKind {
    pub fn columns(&self) -> Vec<&str> {
        match self {
            FeatureKind::SensorRise(a) => vec![a],
            FeatureKind::SensorDiff(a, b) => vec![a, b],
            FeatureKind::Spindle => vec!["spindle_rpm"],
        }
    }
}

/// Short name: `rise(T_t3)`, `T_t3-T_t5`, `rpm`, with `@<tau>s` for a lag.
pub fn feature_name(kind: &FeatureKind, tau_s: Option<f64>) -> String {
    let base = match kind {
        FeatureKind::SensorRise(a) => a.clone(),
        FeatureKind::SensorDiff(a, b) => format!("{a}-{b}"),
        FeatureKind::Spindle => "rpm".to_string(),
    };
    match tau_s {
        Some(t) => format!("{base}@{t}"),
        None => base,
    }
}

/// Parse `T_t3`, `T_t3@3600`, `T_t3-T_t5@1800`, `rpm@600` (lag in seconds;
/// `@0` means no lag).
pub fn parse_feature(s: &str) -> Result<(FeatureKind, Option<f64>)> {
    let s = s.trim();
    let (base, tau) = match s.split_once('@') {
        Some((b, t)) => {
            let v: f64 =
                t.trim().trim_end_matches('s').parse().with_context(|| {
                    format!("feature `{s}`: lag `{t}` is not a number of seconds")
                })?;
            if !(v >= 0.0 && v.is_finite()) {
                bail!("feature `{s}`: lag must be ≥ 0 s");
            }
            (b.trim(), if v > 0.0 { Some(v) } else { None })
        }
        None => (s, None),
    };
    let kind = if base == "rpm" || base == "spindle_rpm" || base == "spindle" {
        FeatureKind::Spindle
    } else if let Some((a, b)) = base.split_once('-') {
        FeatureKind::SensorDiff(a.trim().to_string(), b.trim().to_string())
    } else if base.is_empty() {
        bail!("empty feature name");
    } else {
        FeatureKind::SensorRise(base.to_string())
    };
    Ok((kind, tau))
}

impl FeatureSpec {
    pub fn name(&self) -> String {
        feature_name(&self.kind, self.tau_s)
    }
    /// Clamp to [min, max] and map to [−1, 1].
    #[inline]
    pub fn normalize(&self, x: f64) -> f64 {
        let span = self.max - self.min;
        if span <= 0.0 {
            return 0.0;
        }
        2.0 * (x.clamp(self.min, self.max) - self.min) / span - 1.0
    }
}

/// A fitted model of one channel: MLR or network.
pub trait Model {
    fn features(&self) -> &[FeatureSpec];
    fn channel(&self) -> &str;
    /// Prediction in µm from normalized inputs.
    fn predict_norm(&self, xn: &[f64]) -> f64;
    /// Prediction in µm from raw (un-normalized) inputs.
    fn predict_raw(&self, x: &[f64]) -> f64 {
        let xn: Vec<f64> = self
            .features()
            .iter()
            .zip(x)
            .map(|(f, &v)| f.normalize(v))
            .collect();
        self.predict_norm(&xn)
    }
    /// Predict a whole run on the board's features (NaN on rows with a sensor gap).
    fn predict_run(&self, run: &Run) -> Result<Vec<f64>> {
        let kinds: Vec<_> = self
            .features()
            .iter()
            .map(|f| (f.kind.clone(), f.tau_s))
            .collect();
        let cols = feature_columns(run, &kinds)?;
        Ok((0..run.rows())
            .map(|r| {
                let x: Vec<f64> = cols.iter().map(|c| c[r]).collect();
                self.predict_raw(&x)
            })
            .collect())
    }
}

impl Model for MlrParams {
    fn features(&self) -> &[FeatureSpec] {
        &self.features
    }
    fn channel(&self) -> &str {
        &self.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.c0 + self.coef.iter().zip(xn).map(|(c, x)| c * x).sum::<f64>()
    }
}

impl Model for NetParams {
    fn features(&self) -> &[FeatureSpec] {
        &self.features
    }
    fn channel(&self) -> &str {
        &self.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        let mut y = self.b2;
        for j in 0..self.b1.len() {
            let z = self.b1[j] + self.w1[j].iter().zip(xn).map(|(w, x)| w * x).sum::<f64>();
            y += self.w2[j] * net::sigmoid(z);
        }
        y
    }
}

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

// -------------------------------------------------------------------- splits

/// Rows `[start, end)` of run `run` (an index into the runs list).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Segment {
    pub run: usize,
    pub start: usize,
    pub end: usize,
}

/// Chronological split of `n` rows at fractions `a < b`: train `[0, ⌊a·n⌋)`,
/// validation `[⌊a·n⌋, ⌊b·n⌋)` (the FL_THERMAL protocol).
pub fn chrono_split(n: usize, a: f64, b: f64) -> Result<(Range<usize>, Range<usize>)> {
    if !(0.0 < a && a < b && b <= 1.0) {
        bail!("--split-chrono a,b needs 0 < a < b ≤ 1, got {a},{b}");
    }
    let i = (a * n as f64).floor() as usize;
    let j = ((b * n as f64).floor() as usize).min(n);
    if i == 0 || j <= i {
        bail!("--split-chrono {a},{b}: an empty part on {n} rows");
    }
    Ok((0..i, i..j))
}

/// Split a training segment by time: the first `1 − frac` of its time span
/// for fitting, the last `frac` for early stopping / selection.
pub fn time_block_split(run: &Run, seg: Segment, frac: f64) -> (Segment, Segment) {
    let t = run.time_s();
    if seg.end <= seg.start + 1 {
        return (
            seg,
            Segment {
                start: seg.end,
                ..seg
            },
        );
    }
    let t0 = t[seg.start];
    let t1 = t[seg.end - 1];
    let cut_t = t0 + (1.0 - frac) * (t1 - t0);
    let cut = (seg.start..seg.end)
        .find(|&r| t[r] > cut_t)
        .unwrap_or(seg.end);
    (Segment { end: cut, ..seg }, Segment { start: cut, ..seg })
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
    let c = crate::linalg::least_squares(&xn, &train.y, true, 1e-9 * train.y.len() as f64)
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

//! The `fit` pipeline: plan the chronological / held-out split, choose the
//! inputs, fit MLR and GA-BPN per channel, validate on held-out rows only.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use super::features;
use super::net::{self, Net, NetOpts};
use super::*;
use crate::runcsv::Run;
use crate::select::{self, Selection};

/// How the inputs are chosen.
#[derive(Clone, Debug)]
pub enum FeatureChoice {
    /// Greedy forward selection (MLR on a training time block) among rises of
    /// the candidate sensors and the spindle speed, each at every lag.
    Auto,
    /// Exactly these inputs.
    List(Vec<(FeatureKind, Option<f64>)>),
}

/// Which sensors `auto` may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Candidates {
    /// The sensors `select` chooses on the training rows.
    Selected,
    /// Every temperature column.
    All,
}

#[derive(Clone, Debug)]
pub struct FitConfig {
    pub split_chrono: Option<(f64, f64)>,
    pub features: FeatureChoice,
    /// Candidate lags for `auto`, seconds (0 = no lag).
    pub lags: Vec<f64>,
    pub max_inputs: usize,
    pub candidates: Candidates,
    pub groups: usize,
    /// Channels to fit (default: every `d..._um` column).
    pub channels: Option<Vec<String>>,
    pub net: NetOpts,
    /// Fraction of the training time span used for early stopping / selection.
    pub es_frac: f64,
    /// Time blocks for the blocked cross-validation of `auto` (1 = the
    /// early-stopping block only).
    pub select_folds: usize,
    pub progress: bool,
    pub skip_net: bool,
    /// A simpler model is chosen when its CV RMS is within this fraction of the best.
    pub choice_margin: f64,
    /// Also fit and cross-validate the hybrid (lagged MLR + networks on its residual).
    pub hybrid: bool,
    /// Stop a network candidate's cross-validation once it cannot be chosen.
    pub cv_drop: bool,
    /// Also score (and offer) the blend `w·mlr + (1−w)·ga-bpn` (off by
    /// default: on FL_THERMAL its cross-validated edge on ch5 does not hold
    /// on the test block, and it scores the network on every fold).
    pub blend: bool,
    /// Fit fallback models without each model sensor (`fallback.rs`).
    pub fallbacks: bool,
    /// ... and without each pair of model sensors.
    pub fallback_pairs: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            split_chrono: None,
            features: FeatureChoice::Auto,
            lags: vec![0.0, 1800.0, 3600.0, 7200.0, 10800.0, 21600.0],
            max_inputs: 5,
            candidates: Candidates::Selected,
            groups: 5,
            channels: None,
            net: NetOpts::default(),
            es_frac: 0.15,
            select_folds: 5,
            progress: false,
            skip_net: false,
            choice_margin: 0.02,
            hybrid: false,
            cv_drop: true,
            blend: false,
            fallbacks: true,
            fallback_pairs: false,
        }
    }
}

/// Runs and the segments used for training and validation.
#[derive(Clone, Debug)]
pub struct Plan {
    pub runs: Vec<Run>,
    pub labels: Vec<String>,
    pub train: Vec<Segment>,
    pub val: Vec<Segment>,
}

impl Plan {
    /// The first `n_train` runs train; the rest validate whole. With a
    /// chronological split `a,b`, each training run contributes `[0,a)` to
    /// training and `[a,b)` to validation.
    pub fn new(
        runs: Vec<Run>,
        labels: Vec<String>,
        n_train: usize,
        split: Option<(f64, f64)>,
    ) -> Result<Plan> {
        if n_train == 0 {
            bail!("fit: no training runs given");
        }
        let mut train = Vec::new();
        let mut val = Vec::new();
        for (i, r) in runs.iter().enumerate() {
            let n = r.rows();
            if i < n_train {
                match split {
                    Some((a, b)) => {
                        let (tr, va) =
                            chrono_split(n, a, b).with_context(|| format!("run {}", labels[i]))?;
                        train.push(Segment {
                            run: i,
                            start: tr.start,
                            end: tr.end,
                        });
                        val.push(Segment {
                            run: i,
                            start: va.start,
                            end: va.end,
                        });
                    }
                    None => train.push(Segment {
                        run: i,
                        start: 0,
                        end: n,
                    }),
                }
            } else {
                val.push(Segment {
                    run: i,
                    start: 0,
                    end: n,
                });
            }
        }
        if val.is_empty() {
            bail!("fit: nothing to validate on: give --validate <runs> or --split-chrono a,b");
        }
        Ok(Plan {
            runs,
            labels,
            train,
            val,
        })
    }

    /// Training segments split by time into (fit part, early-stopping block).
    pub fn inner_block(&self, frac: f64) -> (Vec<Segment>, Vec<Segment>) {
        let mut inner = Vec::new();
        let mut block = Vec::new();
        for s in &self.train {
            let (a, b) = time_block_split(&self.runs[s.run], *s, frac);
            inner.push(a);
            block.push(b);
        }
        (inner, block)
    }
}

/// Per-run figures.
#[derive(Clone, Debug, Serialize)]
pub struct RunMetrics {
    pub run: String,
    pub channel: String,
    #[serde(flatten)]
    pub metrics: Metrics,
}

#[derive(Clone, Debug, Serialize)]
pub struct ModelReport {
    pub name: String,
    /// Pooled over all validation rows, per channel.
    pub channels: BTreeMap<String, Metrics>,
    pub per_run: Vec<RunMetrics>,
}

/// What the network training did on one channel.
#[derive(Clone, Debug, Default, Serialize)]
pub struct NetInfo {
    pub ga_best_mse_norm: f64,
    pub lm_iters: usize,
    pub best_iter: usize,
    pub es_val_mse_norm: Option<f64>,
    pub ga_s: f64,
    pub lm_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct ChannelInfo {
    pub channel: String,
    pub features: Vec<String>,
    pub train_rows: usize,
    pub val_rows: usize,
    /// Blocked cross-validation RMS of the MLR on the chosen inputs (training rows only).
    pub cv_rms_um: Option<f64>,
    /// Blocked cross-validation per candidate model (training rows only): what chose it.
    pub cv: BTreeMap<String, CvScore>,
    pub net: Option<NetInfo>,
}

#[derive(Clone, Debug, Serialize)]
pub struct FitReport {
    pub models: Vec<ModelReport>,
    /// Per channel, the model cross-validation chose (what `export` ships).
    pub chosen: BTreeMap<String, String>,
    /// What the board's limits ruled out, and how the runs were read.
    pub notes: Vec<String>,
    pub inputs: Vec<ChannelInfo>,
    pub selection: Option<Selection>,
    pub train_segments: Vec<Segment>,
    pub val_segments: Vec<Segment>,
    /// Fallback models per channel and excluded sensor(s), with their figures.
    pub fallbacks: Vec<super::fallback::FallbackReport>,
    #[serde(skip)]
    pub model_file: ModelFile,
}

fn progress_bar(show: bool, len: u64, msg: String) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg:>18} [{bar:40}] {pos}/{len} {elapsed}") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(msg);
    pb
}

/// Train one channel's network: GA on the fit part, LM with early stopping on
/// the time block, then (optionally) LM on all training rows for the best
/// number of steps from the same GA start. Inputs are raw; `specs` carry the
/// training ranges.
fn train_gabpn_once(
    specs: &[FeatureSpec],
    channel: &str,
    inner: &Samples,
    block: &Samples,
    full: &Samples,
    opts: &NetOpts,
    pb: &ProgressBar,
) -> (NetParams, NetInfo) {
    let n = full.y.len().max(1) as f64;
    let mean = full.y.iter().sum::<f64>() / n;
    let sd = (full.y.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n)
        .sqrt()
        .max(1e-9);
    let prep = |s: &Samples| -> (Vec<Vec<f64>>, Vec<f64>) {
        (
            normalize_rows(specs, &s.x),
            s.y.iter().map(|v| (v - mean) / sd).collect(),
        )
    };
    let (xi, yi) = prep(inner);
    let (xb, yb) = prep(block);
    let (xf, yf) = prep(full);
    let mut info = NetInfo::default();
    let t0 = Instant::now();
    let (ga_net, hist) = net::ga_search(&xi, &yi, opts, pb);
    info.ga_best_mse_norm = hist.last().copied().unwrap_or(f64::NAN);
    info.ga_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let val = if yb.is_empty() {
        None
    } else {
        Some((xb.as_slice(), yb.as_slice()))
    };
    let es = net::train_lm(&ga_net, &xi, &yi, val, opts.lm_iters, opts, pb);
    info.best_iter = es.best_iter;
    info.es_val_mse_norm = es.val_mse;
    let final_net: Net = if opts.refit_full && val.is_some() {
        let r = net::train_lm(&ga_net, &xf, &yf, None, es.best_iter.max(1), opts, pb);
        info.lm_iters = es.iters + r.iters;
        r.net
    } else {
        info.lm_iters = es.iters;
        es.net
    };
    info.lm_s = t1.elapsed().as_secs_f64();
    let (w1, b1, w2, b2) = final_net.unpack();
    let params = NetParams {
        features: specs.to_vec(),
        w1,
        b1,
        w2: w2.iter().map(|w| w * sd).collect(),
        b2: b2 * sd + mean,
        channel: channel.to_string(),
    };
    (params, info)
}

/// Train one channel's ensemble: `opts.ensemble` networks from seeds
/// `seed, seed+1, …`, trained in parallel; the board serves their mean.
/// Rows are strided to `opts.max_rows` for the gradient steps.
pub fn train_ensemble(
    specs: &[FeatureSpec],
    channel: &str,
    inner: &Samples,
    block: &Samples,
    full: &Samples,
    opts: &NetOpts,
    pb: &ProgressBar,
) -> (Vec<NetParams>, Vec<NetInfo>) {
    use rayon::prelude::*;
    let inner = inner.strided(opts.max_rows);
    let block = block.strided(opts.max_rows / 2);
    let full = full.strided(opts.max_rows);
    (0..opts.ensemble.max(1))
        .into_par_iter()
        .map(|k| {
            let o = NetOpts {
                seed: opts.seed.wrapping_add(k as u64),
                ..opts.clone()
            };
            train_gabpn_once(specs, channel, &inner, &block, &full, &o, pb)
        })
        .unzip()
}

fn validate<M: Model>(m: &M, s: &Samples, plan: &Plan, per_run: &mut Vec<RunMetrics>) -> Metrics {
    let pred: Vec<f64> = s.x.iter().map(|r| m.predict_raw(r)).collect();
    for (ri, label) in plan.labels.iter().enumerate() {
        let (y, p): (Vec<f64>, Vec<f64>) = s
            .rows
            .iter()
            .zip(s.y.iter().zip(&pred))
            .filter(|((r, _), _)| *r == ri)
            .map(|(_, (y, p))| (*y, *p))
            .unzip();
        if !y.is_empty() {
            per_run.push(RunMetrics {
                run: label.clone(),
                channel: m.channel().to_string(),
                metrics: metrics(&y, &p),
            });
        }
    }
    metrics(&s.y, &pred)
}

/// Candidate inputs for `auto`.
pub fn candidates(
    sensors: &[String],
    lags: &[f64],
    with_spindle: bool,
) -> Vec<(FeatureKind, Option<f64>)> {
    let tau = |l: f64| if l > 0.0 { Some(l) } else { None };
    let mut out = Vec::new();
    for s in sensors {
        for &l in lags {
            out.push((FeatureKind::SensorRise(s.clone()), tau(l)));
        }
    }
    if with_spindle {
        for &l in lags {
            out.push((FeatureKind::Spindle, tau(l)));
        }
    }
    out
}

/// Read runs and fit.
pub fn run_fit(train: &[PathBuf], validate_runs: &[PathBuf], cfg: &FitConfig) -> Result<FitReport> {
    let mut runs = Vec::new();
    let mut labels = Vec::new();
    let mut notes = Vec::new();
    for p in train.iter().chain(validate_runs) {
        let mut run = Run::read(p)?;
        // The model predicts rises from the run's start (what the board serves).
        notes.extend(run.errors_as_rises(&p.display().to_string()));
        runs.push(run);
        labels.push(p.display().to_string());
    }
    let plan = Plan::new(runs, labels, train.len(), cfg.split_chrono)?;
    let mut report = fit_plan(&plan, cfg)?;
    notes.append(&mut report.notes);
    report.notes = notes;
    Ok(report)
}

/// Cross-validated figures of one model on one channel (training rows only).
#[derive(Clone, Debug, Default, Serialize)]
pub struct CvScore {
    /// Pooled over the held-out blocks of every fold.
    pub rms_um: f64,
    pub mae_um: f64,
    pub rows: usize,
    pub fold_rms_um: Vec<f64>,
    /// Stopped before its last fold: it could no longer be chosen (its
    /// figures cover only the folds it ran, latest first).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub dropped: bool,
    /// `blend` only: the weight on the lagged MLR the fit ships, chosen on
    /// every fold's out-of-fold predictions. The figures above are nested:
    /// each fold is scored with the weight chosen on the other folds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
}

/// Errors collected over folds.
#[derive(Default)]
struct CvAcc {
    sq: f64,
    abs: f64,
    n: usize,
    folds: Vec<f64>,
}

impl CvAcc {
    fn add_fold(&mut self, y: &[f64], pred: &[f64]) {
        let (mut sq, mut n) = (0.0, 0usize);
        for (t, p) in y.iter().zip(pred) {
            let e = t - p;
            sq += e * e;
            self.abs += e.abs();
            n += 1;
        }
        if n > 0 {
            self.sq += sq;
            self.n += n;
            self.folds.push((sq / n as f64).sqrt());
        }
    }
    fn score(&self) -> Option<CvScore> {
        (self.n > 0).then(|| CvScore {
            rms_um: (self.sq / self.n as f64).sqrt(),
            mae_um: self.abs / self.n as f64,
            rows: self.n,
            fold_rms_um: self.folds.clone(),
            dropped: false,
            weight: None,
        })
    }
}

/// Each fit segment split by time into (fit part, early-stopping block).
fn split_blocks(plan: &Plan, segs: &[Segment], frac: f64) -> (Vec<Segment>, Vec<Segment>) {
    segs.iter()
        .map(|s| time_block_split(&plan.runs[s.run], *s, frac))
        .unzip()
}

/// `s` with the target replaced by its residual after `m` (what the hybrid's
/// networks learn).
fn residual_samples<M: Model>(m: &M, s: &Samples) -> Samples {
    Samples {
        y: s.x
            .iter()
            .zip(&s.y)
            .map(|(r, y)| y - m.predict_raw(r))
            .collect(),
        x: s.x.clone(),
        rows: s.rows.clone(),
    }
}

/// The hybrid's residual networks: an ensemble trained on the residual of
/// `mlr`, kept only if it lowers the residual on the early-stopping time
/// block (otherwise no networks: the hybrid is the MLR alone).
fn train_hybrid(
    mlr: &MlrParams,
    specs: &[FeatureSpec],
    inner: &Samples,
    block: &Samples,
    full: &Samples,
    opts: &NetOpts,
    pb: &ProgressBar,
) -> Vec<NetParams> {
    let rb = residual_samples(mlr, block);
    let (members, _) = train_ensemble(
        specs,
        &mlr.channel,
        &residual_samples(mlr, inner),
        &rb,
        &residual_samples(mlr, full),
        opts,
        pb,
    );
    if rb.y.is_empty() {
        return members;
    }
    let ens = NetEnsemble {
        members: members.iter().collect(),
    };
    let (mut with, mut without) = (0.0, 0.0);
    for (r, y) in rb.x.iter().zip(&rb.y) {
        with += (y - ens.predict_raw(r)).powi(2);
        without += y * y;
    }
    if with < without {
        members
    } else {
        vec![]
    }
}

/// Which network candidates to fit and score.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetCandidates {
    /// The free GA-BPN ensemble (`ga-bpn`).
    pub net: bool,
    /// Lagged MLR + GA-BPN ensemble on its residual (`hybrid`).
    pub hybrid: bool,
    /// `w·mlr + (1−w)·ga-bpn` with `w` from the out-of-fold predictions
    /// (`blend`; needs `net`, and scores the network on every fold).
    pub blend: bool,
}

/// Blocked time cross-validation of every candidate model of one channel on
/// the training rows: each fold refits the model on the other blocks and
/// scores it on its own block. Validation rows are never touched.
///
/// The linear models are scored on every fold. A network candidate is then
/// scored fold by fold, the latest time block first, and dropped as soon as
/// it cannot be chosen: its pooled squared error so far, divided by all the
/// held-out rows (as if the remaining folds scored zero), already puts its
/// RMS at or above the best linear model's RMS / (1 + margin) (the choice
/// would then take the linear model). A dropped candidate reports the folds
/// it ran and `dropped: true`, and is not admissible.
///
/// With `with.blend` the network is scored on every fold (never dropped)
/// and the blend `w·mlr + (1−w)·ga-bpn` is scored from the same
/// out-of-fold predictions: fold `f` with the weight that minimises the
/// squared error on the other folds (nested, so the one fitted parameter
/// does not flatter its figure); `weight` is the one chosen on all folds.
#[allow(clippy::too_many_arguments)]
pub(crate) fn cross_validate(
    cache: &SeriesCache,
    plan: &Plan,
    folds: &[(Vec<Segment>, Vec<Segment>)],
    idx: &[usize],
    static_idx: &[usize],
    ch: &str,
    cfg: &FitConfig,
    with: NetCandidates,
) -> Result<BTreeMap<String, CvScore>> {
    let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
    let skinds: Vec<_> = static_idx.iter().map(|&i| cache.kinds[i].clone()).collect();
    let (mut acc_static, mut acc_mlr) = (CvAcc::default(), CvAcc::default());
    // No compensation: the target is the error about the run's start, so 0.
    let mut acc_none = CvAcc::default();
    // Per usable fold: (fold index, specs, fitted MLR, fit rows, held-out rows).
    let mut kept = Vec::new();
    for (f, (fit, val)) in folds.iter().enumerate() {
        let tr = cache.samples_capped(&plan.runs, fit, idx, ch, SELECT_ROWS)?;
        let va = cache.samples_capped(&plan.runs, val, idx, ch, SELECT_ROWS)?;
        if tr.y.len() < 2 * idx.len() + 2 || va.y.is_empty() {
            continue;
        }
        let specs = ranged_specs(&kinds, &tr);
        let m = fit_mlr(specs.clone(), &tr, ch)?;
        let p_mlr: Vec<f64> = va.x.iter().map(|r| m.predict_raw(r)).collect();
        acc_mlr.add_fold(&va.y, &p_mlr);
        acc_none.add_fold(&va.y, &vec![0.0; va.y.len()]);
        if !static_idx.is_empty() {
            let trs = cache.samples_capped(&plan.runs, fit, static_idx, ch, SELECT_ROWS)?;
            let vas = cache.samples_capped(&plan.runs, val, static_idx, ch, SELECT_ROWS)?;
            let ms = fit_mlr(ranged_specs(&skinds, &trs), &trs, ch)?;
            let p: Vec<f64> = vas.x.iter().map(|r| ms.predict_raw(r)).collect();
            acc_static.add_fold(&vas.y, &p);
        }
        kept.push((f, specs, m, tr, va, p_mlr));
    }
    let mut out = BTreeMap::new();
    for (name, acc) in [
        ("none", &acc_none),
        ("mlr-static", &acc_static),
        ("mlr", &acc_mlr),
    ] {
        if let Some(sc) = acc.score() {
            out.insert(name.to_string(), sc);
        }
    }
    let n_total = acc_mlr.n;
    let linear_best = out.values().map(|s| s.rms_um).fold(f64::INFINITY, f64::min);
    // Out-of-fold network predictions per kept fold (for the blend).
    let mut net_preds: Vec<Option<Vec<f64>>> = vec![None; kept.len()];
    let with_blend = with.blend && with.net;
    for (name, on) in [("hybrid", with.hybrid), ("ga-bpn", with.net)] {
        if !on {
            continue;
        }
        let may_drop = cfg.cv_drop && !(with_blend && name == "ga-bpn");
        let bar = linear_best / (1.0 + cfg.choice_margin);
        let mut acc = CvAcc::default();
        let mut dropped = false;
        for (j, (f, specs, m, tr, va, p_mlr)) in kept.iter().enumerate().rev() {
            let fit = &folds[*f].0;
            let (inner, block) = split_blocks(plan, fit, cfg.es_frac);
            let inner_s = cache.samples_capped(&plan.runs, &inner, idx, ch, cfg.net.max_rows)?;
            let block_s = cache.samples_capped(&plan.runs, &block, idx, ch, cfg.net.max_rows)?;
            let full_s = tr.strided(cfg.net.max_rows);
            let p: Vec<f64> = if name == "ga-bpn" {
                let (members, _) = train_ensemble(
                    specs,
                    ch,
                    &inner_s,
                    &block_s,
                    &full_s,
                    &cfg.net,
                    &ProgressBar::hidden(),
                );
                let ens = NetEnsemble {
                    members: members.iter().collect(),
                };
                va.x.iter().map(|r| ens.predict_raw(r)).collect()
            } else {
                let members = train_hybrid(
                    m,
                    specs,
                    &inner_s,
                    &block_s,
                    &full_s,
                    &cfg.net,
                    &ProgressBar::hidden(),
                );
                let ens = NetEnsemble {
                    members: members.iter().collect(),
                };
                va.x.iter()
                    .zip(p_mlr)
                    .map(|(r, pm)| {
                        if members.is_empty() {
                            *pm
                        } else {
                            pm + ens.predict_raw(r)
                        }
                    })
                    .collect()
            };
            acc.add_fold(&va.y, &p);
            if name == "ga-bpn" {
                net_preds[j] = Some(p);
            }
            if may_drop && n_total > 0 && (acc.sq / n_total as f64).sqrt() >= bar {
                dropped = acc.n < n_total;
                break;
            }
        }
        // Fold figures in time order.
        acc.folds.reverse();
        if let Some(mut sc) = acc.score() {
            sc.dropped = dropped;
            out.insert(name.to_string(), sc);
        }
    }
    if with_blend && kept.len() >= 2 && net_preds.iter().all(Option::is_some) {
        let rows = |skip: Option<usize>| {
            kept.iter()
                .zip(&net_preds)
                .enumerate()
                .filter(move |(j, _)| Some(*j) != skip)
                .flat_map(|(_, (k, pn))| {
                    let (va, pm) = (&k.4, &k.5);
                    va.y.iter()
                        .zip(pm.iter())
                        .zip(pn.iter().flatten())
                        .map(|((y, a), b)| (y, a, b))
                })
        };
        let mut acc = CvAcc::default();
        for (j, (k, pn)) in kept.iter().zip(&net_preds).enumerate() {
            let w = blend_weight(rows(Some(j)));
            let p: Vec<f64> =
                k.5.iter()
                    .zip(pn.iter().flatten())
                    .map(|(a, b)| w * a + (1.0 - w) * b)
                    .collect();
            acc.add_fold(&k.4.y, &p);
        }
        if let Some(mut sc) = acc.score() {
            sc.weight = Some(blend_weight(rows(None)));
            out.insert("blend".to_string(), sc);
        }
    }
    Ok(out)
}

/// The simplest model whose cross-validated RMS is within `margin` of the
/// best (a network must earn its place by more than fold noise).
pub fn choose_model(cv: &BTreeMap<String, CvScore>, margin: f64) -> Option<String> {
    let best = cv.values().map(|s| s.rms_um).fold(f64::INFINITY, f64::min);
    MODEL_NAMES
        .iter()
        .find(|n| {
            cv.get(**n)
                .is_some_and(|s| s.rms_um <= best * (1.0 + margin))
        })
        .map(|n| n.to_string())
}

/// Models that carry networks (the others are linear tables).
pub const NET_MODELS: [&str; 3] = ["blend", "hybrid", "ga-bpn"];

/// The latest-block rule: a candidate with networks stays admissible only
/// if, on the latest time block (the one fold whose fit rows all precede
/// it, as the board's future follows its training), its RMS is within
/// `margin` of the linear model the choice would otherwise take. The pooled
/// CV lets earlier blocks, fitted with later data on both sides,
/// outvote the one block that forecasts forward; a network that cannot
/// extrapolate past its training envelope shows only there. Removes them
/// from `cv` and returns `(name, its latest-block RMS, the linear one's)`.
pub fn latest_block_rule(
    cv: &mut BTreeMap<String, CvScore>,
    margin: f64,
) -> Vec<(String, f64, f64)> {
    let mut linear = cv.clone();
    linear.retain(|n, _| !NET_MODELS.contains(&n.as_str()));
    let Some(lin) = choose_model(&linear, margin) else {
        return vec![];
    };
    let Some(bar) = linear[&lin].fold_rms_um.last().copied() else {
        return vec![];
    };
    let mut out = Vec::new();
    for name in NET_MODELS {
        let latest = cv.get(name).and_then(|s| s.fold_rms_um.last().copied());
        if let Some(r) = latest {
            if r > bar * (1.0 + margin) {
                cv.remove(name);
                out.push((name.to_string(), r, bar));
            }
        }
    }
    out
}

/// Time span of the longest training segment, seconds.
fn training_span_s(plan: &Plan) -> f64 {
    plan.train
        .iter()
        .filter(|s| s.end > s.start)
        .map(|s| {
            let t = plan.runs[s.run].time_s();
            t[s.end - 1] - t[s.start]
        })
        .fold(0.0, f64::max)
}

/// Fit on a planned split.
pub fn fit_plan(plan: &Plan, cfg: &FitConfig) -> Result<FitReport> {
    use thermocomp_core::limits::{
        MAX_DIRECTIONS, MAX_INPUTS, MAX_NETS, MAX_NET_INPUTS, MAX_SENSORS,
    };
    let first = &plan.runs[plan.train[0].run];
    let channels: Vec<String> = match &cfg.channels {
        Some(c) => c.clone(),
        None => first
            .error_columns()
            .iter()
            .map(|s| s.to_string())
            .collect(),
    };
    if channels.is_empty() {
        bail!("fit: the training run has no error columns (d<name>_um)");
    }
    if channels.len() > MAX_DIRECTIONS {
        bail!(
            "fit: {} error channels, the board serves at most {MAX_DIRECTIONS} directions: choose them with --channels",
            channels.len()
        );
    }
    if cfg.max_inputs == 0 || cfg.max_inputs > MAX_NET_INPUTS {
        bail!(
            "fit: the board takes 1..={MAX_NET_INPUTS} inputs per model, asked for {}",
            cfg.max_inputs
        );
    }
    if cfg.net.hidden == 0 || cfg.net.hidden > 16 {
        bail!("fit: --hidden must be 1..=16, got {}", cfg.net.hidden);
    }
    let ens = cfg.net.ensemble.max(1);
    if ens > MAX_NETS {
        bail!("fit: --ensemble {ens} exceeds the board's {MAX_NETS} networks");
    }
    let folds = if cfg.select_folds <= 1 {
        let (inner, block) = plan.inner_block(cfg.es_frac);
        vec![(inner, block)]
    } else {
        blocked_folds(&plan.runs, &plan.train, cfg.select_folds)
    };
    // The board reads temperature channels 0..MAX_SENSORS in the run's
    // column order: sensors beyond are never candidates.
    let board_sensors = features::board_channels(first);
    let beyond = first
        .temperature_columns()
        .len()
        .saturating_sub(MAX_SENSORS);
    let mut notes = Vec::new();
    if beyond > 0 {
        notes.push(format!(
            "{beyond} temperature column(s) beyond the board's {MAX_SENSORS} channels are not candidates"
        ));
    }
    let span = training_span_s(plan);
    let lags: Vec<f64> = cfg.lags.iter().copied().filter(|&l| l <= span).collect();
    if lags.len() < cfg.lags.len() {
        notes.push(format!(
            "lags longer than the training span ({:.1} h) are not candidates",
            span / 3600.0
        ));
    }
    if lags.is_empty() {
        bail!("fit: every candidate lag is longer than the training span ({span:.0} s)");
    }
    // Sensor selection on training rows only, among the board's channels.
    let selection = if matches!(cfg.features, FeatureChoice::Auto) {
        let slices: Vec<Run> = plan
            .train
            .iter()
            .map(|s| {
                plan.runs[s.run]
                    .slice_rows(s.start, s.end)
                    .keep_temperatures(&board_sensors)
            })
            .collect();
        let groups = cfg.groups.min(board_sensors.len());
        Some(select::select(&slices, groups, 0)?)
    } else {
        None
    };
    let has_spindle = first.col("spindle_rpm").is_some();
    let mut reports: BTreeMap<&str, ModelReport> = MODEL_NAMES
        .iter()
        .map(|n| {
            (
                *n,
                ModelReport {
                    name: n.to_string(),
                    channels: BTreeMap::new(),
                    per_run: vec![],
                },
            )
        })
        .collect();
    let mut inputs = Vec::new();
    let mut file = ModelFile::default();

    // Candidate cache shared by all channels.
    let (cache, static_idx): (SeriesCache, Vec<usize>) = match (&cfg.features, &selection) {
        (FeatureChoice::Auto, Some(sel)) => {
            let sensors: Vec<String> = match cfg.candidates {
                Candidates::Selected => sel.chosen.clone(),
                Candidates::All => sel.sensors.clone(),
            };
            let kinds = candidates(&sensors, &lags, has_spindle);
            let static_idx = sel
                .chosen
                .iter()
                .filter_map(|s| {
                    kinds
                        .iter()
                        .position(|k| *k == (FeatureKind::SensorRise(s.clone()), None))
                })
                .take(MAX_NET_INPUTS)
                .collect();
            (SeriesCache::new(&plan.runs, kinds)?, static_idx)
        }
        (FeatureChoice::List(kinds), _) => {
            if kinds.is_empty() || kinds.len() > MAX_NET_INPUTS {
                bail!(
                    "fit: --features needs 1..={MAX_NET_INPUTS} inputs, got {}",
                    kinds.len()
                );
            }
            for (k, _) in kinds {
                for c in k.columns() {
                    if c != "spindle_rpm" && !board_sensors.iter().any(|s| s == c) {
                        bail!("fit: feature column {c} is not one of the board's {MAX_SENSORS} temperature channels");
                    }
                }
            }
            (SeriesCache::new(&plan.runs, kinds.clone())?, vec![])
        }
        (FeatureChoice::Auto, None) => bail!("internal: no selection"),
    };

    // Board resources shared by the channels: inputs and networks.
    let mut in_use: Vec<usize> = Vec::new();
    let mut nets_left = MAX_NETS;
    for ch in &channels {
        if first.col(ch).is_none() {
            bail!("fit: training run has no column `{ch}`");
        }
        let budget = MAX_INPUTS.saturating_sub(in_use.len());
        let (idx, cv_mse) = match cfg.features {
            FeatureChoice::Auto => {
                let (i, e) = greedy_select(
                    &cache,
                    &plan.runs,
                    &folds,
                    ch,
                    cfg.max_inputs,
                    &in_use,
                    budget,
                )?;
                (i, Some(e))
            }
            FeatureChoice::List(_) => ((0..cache.kinds.len()).collect(), None),
        };
        let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
        let full = cache.samples(&plan.runs, &plan.train, &idx, ch)?;
        let val = cache.samples(&plan.runs, &plan.val, &idx, ch)?;
        if full.y.is_empty() || val.y.is_empty() {
            // name the cause: an input column that never reads there, else
            // the channel itself
            for (part, segs) in [("training", &plan.train), ("validation", &plan.val)] {
                for c in kinds.iter().flat_map(|k| k.0.columns()) {
                    let reads = segs.iter().any(|s| {
                        plan.runs[s.run]
                            .col(c)
                            .is_some_and(|v| v[s.start..s.end].iter().any(Option::is_some))
                    });
                    if !reads {
                        bail!("fit: input {c} has no values in the {part} rows");
                    }
                }
            }
            bail!("fit: channel {ch} has no values in the training or validation rows");
        }
        // Static inputs the board can still take.
        let static_ok: Vec<usize> = static_idx
            .iter()
            .copied()
            .filter(|i| in_use.contains(i) || idx.contains(i))
            .chain(
                static_idx
                    .iter()
                    .copied()
                    .filter(|i| !in_use.contains(i) && !idx.contains(i))
                    .take(
                        budget.saturating_sub(idx.iter().filter(|i| !in_use.contains(i)).count()),
                    ),
            )
            .collect();
        let with = NetCandidates {
            net: !cfg.skip_net,
            hybrid: !cfg.skip_net && cfg.hybrid,
            blend: !cfg.skip_net && cfg.blend,
        };
        let pb = progress_bar(cfg.progress, 1, format!("cross-validating {ch}"));
        let cv = if folds.len() > 1 {
            cross_validate(&cache, plan, &folds, &idx, &static_ok, ch, cfg, with)?
        } else {
            BTreeMap::new()
        };
        pb.finish_and_clear();

        let specs = ranged_specs(&kinds, &full);
        let mlr = fit_mlr(specs.clone(), &full, ch)?;
        if let Some(r) = reports.get_mut("mlr") {
            r.channels
                .insert(ch.clone(), validate(&mlr, &val, plan, &mut r.per_run));
        }
        if !static_ok.is_empty() {
            let fs = cache.samples(&plan.runs, &plan.train, &static_ok, ch)?;
            let vs = cache.samples(&plan.runs, &plan.val, &static_ok, ch)?;
            let sk: Vec<_> = static_ok.iter().map(|&i| cache.kinds[i].clone()).collect();
            let m = fit_mlr(ranged_specs(&sk, &fs), &fs, ch)?;
            if let Some(r) = reports.get_mut("mlr-static") {
                r.channels
                    .insert(ch.clone(), validate(&m, &vs, plan, &mut r.per_run));
            }
            file.mlr_static.push(m);
        }

        let mut info = ChannelInfo {
            channel: ch.clone(),
            features: specs.iter().map(FeatureSpec::name).collect(),
            train_rows: full.y.len(),
            val_rows: val.y.len(),
            cv_rms_um: cv_mse.map(f64::sqrt),
            cv: cv.clone(),
            net: None,
        };
        let mut hybrid_empty = false;
        if with.net || with.hybrid {
            let (inner, block) = plan.inner_block(cfg.es_frac);
            let inner_s = cache.samples_capped(&plan.runs, &inner, &idx, ch, cfg.net.max_rows)?;
            let block_s = cache.samples_capped(&plan.runs, &block, &idx, ch, cfg.net.max_rows)?;
            let full_s = full.strided(cfg.net.max_rows);
            if with.net {
                let pb = progress_bar(cfg.progress, 1, format!("GA-BPN {ch}"));
                let (members, infos) =
                    train_ensemble(&specs, ch, &inner_s, &block_s, &full_s, &cfg.net, &pb);
                pb.finish_and_clear();
                let ens = NetEnsemble {
                    members: members.iter().collect(),
                };
                if let Some(r) = reports.get_mut("ga-bpn") {
                    r.channels
                        .insert(ch.clone(), validate(&ens, &val, plan, &mut r.per_run));
                }
                info.net = infos.into_iter().next();
                if let Some(w) = cv.get("blend").and_then(|s| s.weight) {
                    let b = Blend {
                        mlr: &mlr,
                        nets: NetEnsemble {
                            members: members.iter().collect(),
                        },
                        w,
                    };
                    if let Some(r) = reports.get_mut("blend") {
                        r.channels
                            .insert(ch.clone(), validate(&b, &val, plan, &mut r.per_run));
                    }
                    file.blend.insert(ch.clone(), w);
                }
                file.nets.extend(members);
            }
            if with.hybrid {
                let pb = progress_bar(cfg.progress, 1, format!("hybrid {ch}"));
                let members =
                    train_hybrid(&mlr, &specs, &inner_s, &block_s, &full_s, &cfg.net, &pb);
                pb.finish_and_clear();
                if members.is_empty() {
                    notes.push(format!(
                        "{ch}: the hybrid's residual networks did not lower the residual on the early-stopping block: the hybrid is the MLR alone"
                    ));
                    if let Some(r) = reports.get_mut("hybrid") {
                        r.channels
                            .insert(ch.clone(), validate(&mlr, &val, plan, &mut r.per_run));
                    }
                } else {
                    let hyb = Hybrid {
                        mlr: &mlr,
                        residual: NetEnsemble {
                            members: members.iter().collect(),
                        },
                    };
                    if let Some(r) = reports.get_mut("hybrid") {
                        r.channels
                            .insert(ch.clone(), validate(&hyb, &val, plan, &mut r.per_run));
                    }
                }
                hybrid_empty = members.is_empty();
                file.hybrid_nets.extend(members);
            }
        }
        // The choice: cross-validated on training rows, within the board's networks.
        let mut admissible = cv.clone();
        admissible.retain(|_, s| !s.dropped);
        for (name, r, bar) in latest_block_rule(&mut admissible, cfg.choice_margin) {
            notes.push(format!(
                "{ch}: {name} is not admissible: RMS {r:.2} µm on the latest training block (the one fold that forecasts forward) against the linear model's {bar:.2} µm"
            ));
        }
        for name in NET_MODELS {
            if admissible.contains_key(name) && nets_left < ens {
                admissible.remove(name);
                notes.push(format!(
                    "{ch}: {name} is not admissible (the board holds {MAX_NETS} networks, {} in use)",
                    MAX_NETS - nets_left
                ));
            }
        }
        let mut chosen =
            choose_model(&admissible, cfg.choice_margin).unwrap_or_else(|| "mlr".into());
        if chosen == "hybrid" && hybrid_empty {
            // The final hybrid kept no networks: it is the lagged MLR.
            chosen = "mlr".into();
        }
        if chosen == "blend" {
            // All weight on one part: the blend is that part.
            match file.blend.get(ch) {
                Some(w) if *w >= 1.0 => chosen = "mlr".into(),
                Some(w) if *w <= 0.0 => chosen = "ga-bpn".into(),
                _ => {}
            }
        }
        if chosen == "ga-bpn" || chosen == "hybrid" || chosen == "blend" {
            nets_left -= ens;
        }
        if chosen == "none" {
            notes.push(format!(
                "{ch}: no model beats no compensation by more than {:.0} % in the training CV (RMS {:.2} µm without compensation): the board serves 0 for it (`export --use {ch}=mlr` ships the lagged MLR anyway)",
                100.0 * cfg.choice_margin,
                admissible.get("none").map_or(f64::NAN, |s| s.rms_um)
            ));
        }
        let used_idx: &[usize] = match chosen.as_str() {
            "mlr-static" => &static_ok,
            "none" => &[],
            _ => &idx,
        };
        for &i in used_idx {
            if !in_use.contains(&i) {
                in_use.push(i);
            }
        }
        file.chosen.insert(ch.clone(), chosen);
        inputs.push(info);
        file.mlr.push(mlr);
    }
    // Sensor gaps: the board skips a step when any of the image's sensors is
    // empty; say where that differs from what each channel trained on.
    let image_kinds = features::chosen_kinds(&file);
    if let Some(n) = features::image_gap_rows(&plan.runs, &plan.train, &image_kinds)? {
        if n > 0 {
            notes.push(format!(
                "{n} training rows have a sensor gap in another channel's inputs: there the board's features for the exported model differ from the ones trained on (the board skips a step when any of its sensors is empty)"
            ));
        }
    }
    let mut fallbacks = Vec::new();
    if cfg.fallbacks {
        let ctx = super::fallback::Context {
            cache: &cache,
            plan,
            folds: &folds,
            static_idx: &static_idx,
            cfg,
        };
        let pb = progress_bar(cfg.progress, 1, "fallback models".into());
        let (params, reps) =
            super::fallback::fit_fallbacks(&ctx, &file, &channels, &mut in_use, &mut notes)?;
        pb.finish_and_clear();
        file.fallbacks = params;
        fallbacks = reps;
    }
    let models = reports
        .into_values()
        .filter(|r| !r.channels.is_empty())
        .collect();
    Ok(FitReport {
        fallbacks,
        models,
        inputs,
        chosen: file.chosen.clone(),
        notes,
        selection,
        train_segments: plan.train.clone(),
        val_segments: plan.val.clone(),
        model_file: file,
    })
}

/// Plain-text report.
pub fn print_report(r: &FitReport) {
    for n in &r.notes {
        println!("note: {n}");
    }
    if let Some(s) = &r.selection {
        println!("selected sensors (training rows): {}", s.chosen.join(","));
    }
    for i in &r.inputs {
        print!(
            "{}: inputs {} ({} train rows, {} validation rows)",
            i.channel,
            i.features.join(", "),
            i.train_rows,
            i.val_rows
        );
        if let Some(cv) = i.cv_rms_um {
            print!("; training CV RMS {cv:.2} µm");
        }
        if let Some(n) = &i.net {
            print!(
                "; GA {:.1} s, LM {} steps (best {}) {:.1} s",
                n.ga_s, n.lm_iters, n.best_iter, n.lm_s
            );
        }
        println!();
    }
    println!();
    println!(
        "{:<11} {:<10} {:>9} {:>9} {:>9} {:>9} {:>10}",
        "model", "channel", "MAE µm", "RMS µm", "peak µm", "raw RMS", "reduction"
    );
    for m in &r.models {
        for (ch, x) in &m.channels {
            println!(
                "{:<11} {:<10} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.1}%",
                m.name, ch, x.mae_um, x.rms_um, x.peak_um, x.raw_rms_um, x.reduction_pct
            );
        }
    }
    if !r.fallbacks.is_empty() {
        println!("\nfallback models (degraded mode; validation rows):");
        for f in &r.fallbacks {
            let cv = f.cv.get(&f.model).map_or(f64::NAN, |c| c.rms_um);
            println!(
                "{:<10} without {:<16} {:<10} CV RMS {:>6.2} µm, RMS {:>6.2} µm, reduction {:>5.1}%  ({})",
                f.channel,
                f.excluded.join("+"),
                f.model,
                cv,
                f.validation.rms_um,
                f.validation.reduction_pct,
                f.features.join(", ")
            );
        }
    }
    let runs: std::collections::BTreeSet<&str> = r
        .models
        .iter()
        .flat_map(|m| m.per_run.iter().map(|p| p.run.as_str()))
        .collect();
    if runs.len() > 1 {
        println!("\nper held-out run:");
        for m in &r.models {
            for p in &m.per_run {
                println!(
                    "{:<11} {:<10} {:>9.2} {:>9.2} {:>9.2} {:>9.1}%  {}",
                    m.name,
                    p.channel,
                    p.metrics.mae_um,
                    p.metrics.rms_um,
                    p.metrics.peak_um,
                    p.metrics.reduction_pct,
                    p.run
                );
            }
        }
    }
}

/// `{"models": [{"name", "channels": {...}}], ...}` (validation figures only).
pub fn report_json(r: &FitReport) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

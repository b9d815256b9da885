//! Network training, the blocked time cross-validation of every candidate
//! model of a channel on its training rows, and the choice among them.
//! Below `pipeline` (which runs it per channel) and `fallback` (which runs it
//! per channel without each sensor).

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use super::net::{self, Net, NetOpts};
use super::plan::{FitConfig, Plan};
use super::progress::{Progress, Silent};
use anyhow::Result;

use super::greedy::SELECT_ROWS;
use super::mlr::fit_mlr;
use super::model::{
    blend_weight, FeatureSpec, MlrParams, Model, NetEnsemble, NetParams, MODEL_NAMES,
};
use super::ridge::{choose_penalty, fit_ridge, standardised_coefs};
use super::samples::{normalize_rows, ranged_specs, Samples, SeriesCache};
use super::split::{time_block_split, Segment};

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
    progress: &dyn Progress,
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
    let (ga_net, hist) = net::ga_search(&xi, &yi, opts, progress);
    info.ga_best_mse_norm = hist.last().copied().unwrap_or(f64::NAN);
    info.ga_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let val = if yb.is_empty() {
        None
    } else {
        Some((xb.as_slice(), yb.as_slice()))
    };
    let es = net::train_lm(&ga_net, &xi, &yi, val, opts.lm_iters, opts, progress);
    info.best_iter = es.best_iter;
    info.es_val_mse_norm = es.val_mse;
    let final_net: Net = if opts.refit_full && val.is_some() {
        let r = net::train_lm(&ga_net, &xf, &yf, None, es.best_iter.max(1), opts, progress);
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
    progress: &dyn Progress,
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
            train_gabpn_once(specs, channel, &inner, &block, &full, &o, progress)
        })
        .unzip()
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
    /// `ridge` only: the penalty the fit ships, chosen by forward-chaining
    /// CV on all the training blocks. The figures above are nested: each
    /// fold is scored with the penalty chosen on its own fit blocks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub penalty: Option<f64>,
    /// Linear candidates: the coefficients of each fold's model in
    /// standardised units (µm per standard deviation of each input on the
    /// fold's fit rows), what the stability rule compares.
    #[serde(skip)]
    pub fold_coefs: Vec<Vec<f64>>,
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
            penalty: None,
            fold_coefs: vec![],
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
pub(crate) fn train_hybrid(
    mlr: &MlrParams,
    specs: &[FeatureSpec],
    inner: &Samples,
    block: &Samples,
    full: &Samples,
    opts: &NetOpts,
    progress: &dyn Progress,
) -> Vec<NetParams> {
    let rb = residual_samples(mlr, block);
    let (members, _) = train_ensemble(
        specs,
        &mlr.channel,
        &residual_samples(mlr, inner),
        &rb,
        &residual_samples(mlr, full),
        opts,
        progress,
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
    /// Ridge on the lagged MLR's inputs, its penalty chosen by
    /// forward-chaining CV on each fold's fit blocks (`ridge`; not a network:
    /// linear, cheap, scored on every fold beside the MLR).
    pub ridge: bool,
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
    let cv = CvChannel {
        cache,
        plan,
        folds,
        idx,
        ch,
        cfg,
    };
    let (kept, mut out, n_total) = cv.score_linear(static_idx, with.ridge)?;
    let linear_best = out.values().map(|s| s.rms_um).fold(f64::INFINITY, f64::min);
    // Out-of-fold network predictions per kept fold (for the blend).
    let mut net_preds: Vec<Option<Vec<f64>>> = vec![None; kept.len()];
    let with_blend = with.blend && with.net;
    for (name, on) in [("hybrid", with.hybrid), ("ga-bpn", with.net)] {
        if !on {
            continue;
        }
        let may_drop = cfg.cv_drop && !(with_blend && name == "ga-bpn");
        let drop_at = may_drop.then_some((n_total, linear_best / (1.0 + cfg.choice_margin)));
        let net_preds = (name == "ga-bpn").then_some(&mut net_preds);
        if let Some(sc) = cv.score_net(name, &kept, drop_at, net_preds)? {
            out.insert(name.to_string(), sc);
        }
    }
    if with_blend && kept.len() >= 2 && net_preds.iter().all(Option::is_some) {
        if let Some(sc) = score_blend(&kept, &net_preds) {
            out.insert("blend".to_string(), sc);
        }
    }
    Ok(out)
}

/// What the cross-validation of one channel works on.
struct CvChannel<'a> {
    cache: &'a SeriesCache,
    plan: &'a Plan,
    folds: &'a [(Vec<Segment>, Vec<Segment>)],
    /// The channel's (lagged) inputs, indices into `cache.kinds`.
    idx: &'a [usize],
    ch: &'a str,
    cfg: &'a FitConfig,
}

/// One usable fold, as the linear scoring left it for the network candidates.
struct KeptFold {
    /// Index into the folds.
    fold: usize,
    specs: Vec<FeatureSpec>,
    mlr: MlrParams,
    /// Fit rows and held-out rows.
    fit: Samples,
    held_out: Samples,
    /// The lagged MLR's predictions on the held-out rows.
    mlr_pred: Vec<f64>,
}

impl CvChannel<'_> {
    /// Scores `none`, `mlr-static` (on `static_idx`), `mlr` and (with
    /// `ridge`) the ridge on every usable fold, each linear one with its
    /// fold coefficients; returns those folds, the scores and the held-out
    /// rows.
    fn score_linear(
        &self,
        static_idx: &[usize],
        ridge: bool,
    ) -> Result<(Vec<KeptFold>, BTreeMap<String, CvScore>, usize)> {
        let (cache, plan, idx, ch) = (self.cache, self.plan, self.idx, self.ch);
        let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
        let skinds: Vec<_> = static_idx.iter().map(|&i| cache.kinds[i].clone()).collect();
        let (mut acc_static, mut acc_mlr) = (CvAcc::default(), CvAcc::default());
        let mut acc_ridge = CvAcc::default();
        let mut coefs: BTreeMap<&str, Vec<Vec<f64>>> = BTreeMap::new();
        // No compensation: the target is the error about the run's start, so 0.
        let mut acc_none = CvAcc::default();
        let mut kept = Vec::new();
        for (f, (fit, val)) in self.folds.iter().enumerate() {
            let tr = cache.samples_capped(&plan.runs, fit, idx, ch, SELECT_ROWS)?;
            let va = cache.samples_capped(&plan.runs, val, idx, ch, SELECT_ROWS)?;
            if tr.y.len() < 2 * idx.len() + 2 || va.y.is_empty() {
                continue;
            }
            let specs = ranged_specs(&kinds, &tr);
            let m = fit_mlr(specs.clone(), &tr, ch)?;
            let p_mlr: Vec<f64> = va.x.iter().map(|r| m.predict_raw(r)).collect();
            acc_mlr.add_fold(&va.y, &p_mlr);
            coefs
                .entry("mlr")
                .or_default()
                .push(standardised_coefs(&m, &tr));
            acc_none.add_fold(&va.y, &vec![0.0; va.y.len()]);
            // The ridge's penalty from this fold's fit blocks alone (nested).
            let lambda = match ridge {
                true => choose_penalty(cache, &plan.runs, fit, idx, ch)?,
                false => None,
            };
            if let Some(lambda) = lambda {
                let r = fit_ridge(specs.clone(), &tr, lambda, ch)?;
                let p: Vec<f64> = va.x.iter().map(|x| r.predict_raw(x)).collect();
                acc_ridge.add_fold(&va.y, &p);
                coefs
                    .entry("ridge")
                    .or_default()
                    .push(standardised_coefs(&r, &tr));
            }
            if !static_idx.is_empty() {
                let trs = cache.samples_capped(&plan.runs, fit, static_idx, ch, SELECT_ROWS)?;
                let vas = cache.samples_capped(&plan.runs, val, static_idx, ch, SELECT_ROWS)?;
                let ms = fit_mlr(ranged_specs(&skinds, &trs), &trs, ch)?;
                let p: Vec<f64> = vas.x.iter().map(|r| ms.predict_raw(r)).collect();
                acc_static.add_fold(&vas.y, &p);
                let c = standardised_coefs(&ms, &trs);
                coefs.entry("mlr-static").or_default().push(c);
            }
            kept.push(KeptFold {
                fold: f,
                specs,
                mlr: m,
                fit: tr,
                held_out: va,
                mlr_pred: p_mlr,
            });
        }
        let mut out = BTreeMap::new();
        for (name, acc) in [
            ("none", &acc_none),
            ("mlr-static", &acc_static),
            ("mlr", &acc_mlr),
            ("ridge", &acc_ridge),
        ] {
            if let Some(mut sc) = acc.score() {
                sc.fold_coefs = coefs.remove(name).unwrap_or_default();
                out.insert(name.to_string(), sc);
            }
        }
        Ok((kept, out, acc_mlr.n))
    }

    /// Scores the network candidate `name` (`ga-bpn` or `hybrid`) fold by
    /// fold, the latest first. With `drop_at = Some((all held-out rows,
    /// bar))` it stops once its pooled error over all rows reaches `bar`.
    /// `net_preds` collects the out-of-fold predictions per kept fold.
    fn score_net(
        &self,
        name: &str,
        kept: &[KeptFold],
        drop_at: Option<(usize, f64)>,
        mut net_preds: Option<&mut Vec<Option<Vec<f64>>>>,
    ) -> Result<Option<CvScore>> {
        let mut acc = CvAcc::default();
        let mut dropped = false;
        for (j, k) in kept.iter().enumerate().rev() {
            let p = self.net_fold_predictions(name, k)?;
            acc.add_fold(&k.held_out.y, &p);
            if let Some(preds) = net_preds.as_deref_mut() {
                preds[j] = Some(p);
            }
            if let Some((n_total, bar)) = drop_at {
                if n_total > 0 && (acc.sq / n_total as f64).sqrt() >= bar {
                    dropped = acc.n < n_total;
                    break;
                }
            }
        }
        // Fold figures in time order.
        acc.folds.reverse();
        Ok(acc.score().map(|mut sc| {
            sc.dropped = dropped;
            sc
        }))
    }

    /// Trains the network candidate `name` on a fold's fit rows and predicts
    /// its held-out rows.
    fn net_fold_predictions(&self, name: &str, k: &KeptFold) -> Result<Vec<f64>> {
        let (cache, plan, cfg) = (self.cache, self.plan, self.cfg);
        let fit = &self.folds[k.fold].0;
        let (inner, block) = split_blocks(plan, fit, cfg.es_frac);
        let inner_s =
            cache.samples_capped(&plan.runs, &inner, self.idx, self.ch, cfg.net.max_rows)?;
        let block_s =
            cache.samples_capped(&plan.runs, &block, self.idx, self.ch, cfg.net.max_rows)?;
        let full_s = k.fit.strided(cfg.net.max_rows);
        let va = &k.held_out;
        Ok(if name == "ga-bpn" {
            let (members, _) = train_ensemble(
                &k.specs, self.ch, &inner_s, &block_s, &full_s, &cfg.net, &Silent,
            );
            let ens = NetEnsemble {
                members: members.iter().collect(),
            };
            va.x.iter().map(|r| ens.predict_raw(r)).collect()
        } else {
            let members = train_hybrid(
                &k.mlr, &k.specs, &inner_s, &block_s, &full_s, &cfg.net, &Silent,
            );
            let ens = NetEnsemble {
                members: members.iter().collect(),
            };
            va.x.iter()
                .zip(&k.mlr_pred)
                .map(|(r, pm)| {
                    if members.is_empty() {
                        *pm
                    } else {
                        pm + ens.predict_raw(r)
                    }
                })
                .collect()
        })
    }
}

/// The blend `w·mlr + (1−w)·ga-bpn` from the out-of-fold predictions: each
/// fold scored with the weight chosen on the other folds; `weight` is the
/// one chosen on all folds.
fn score_blend(kept: &[KeptFold], net_preds: &[Option<Vec<f64>>]) -> Option<CvScore> {
    let rows = |skip: Option<usize>| {
        kept.iter()
            .zip(net_preds)
            .enumerate()
            .filter(move |(j, _)| Some(*j) != skip)
            .flat_map(|(_, (k, pn))| {
                let (va, pm) = (&k.held_out, &k.mlr_pred);
                va.y.iter()
                    .zip(pm.iter())
                    .zip(pn.iter().flatten())
                    .map(|((y, a), b)| (y, a, b))
            })
    };
    let mut acc = CvAcc::default();
    for (j, (k, pn)) in kept.iter().zip(net_preds).enumerate() {
        let w = blend_weight(rows(Some(j)));
        let p: Vec<f64> = k
            .mlr_pred
            .iter()
            .zip(pn.iter().flatten())
            .map(|(a, b)| w * a + (1.0 - w) * b)
            .collect();
        acc.add_fold(&k.held_out.y, &p);
    }
    acc.score().map(|mut sc| {
        sc.weight = Some(blend_weight(rows(None)));
        sc
    })
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
pub(crate) fn training_span_s(plan: &Plan) -> f64 {
    plan.train
        .iter()
        .filter(|s| s.end > s.start)
        .map(|s| {
            let t = plan.runs[s.run].time_s();
            t[s.end - 1] - t[s.start]
        })
        .fold(0.0, f64::max)
}

//! Fallback models for degraded-mode compensation (issue 15): per channel,
//! a model without each sensor the chosen model reads (and, with
//! `--fallback-pairs`, without each pair of them), chosen and validated the
//! way the main model is: greedy inputs by blocked time cross-validation on
//! the training rows among the candidates that do not read the excluded
//! sensors, then the simplest of static / lagged MLR within the choice
//! margin of the best CV RMS, then figures on the validation rows.
//!
//! Fallbacks are linear (MLR): the board stores each as one static table
//! (image format v2, section kind 1), a few dozen bytes, so every channel
//! can carry one per sensor within the 8 KiB image. A network fallback would
//! be a new section kind.

use std::collections::BTreeMap;

use anyhow::Result;
use serde::Serialize;

use super::choice::{choose_model, cross_validate, CvScore, NetCandidates};
use super::greedy::greedy_select;
use super::lags::choose_lags;
use super::mlr::{fit_mlr, metrics, Metrics};
use super::model::{FallbackParams, FeatureSpec, Model, ModelFile};
use super::plan::{FeatureChoice, FitConfig, Plan};
use super::samples::{ranged_specs, SeriesCache};
use super::split::Segment;

/// What `fit --json` reports per fallback.
#[derive(Clone, Debug, Serialize)]
pub struct FallbackReport {
    pub channel: String,
    pub excluded: Vec<String>,
    pub model: String,
    pub features: Vec<String>,
    /// Blocked CV on the training rows, per candidate.
    pub cv: BTreeMap<String, CvScore>,
    /// On the validation rows (never used to choose).
    pub validation: Metrics,
}

/// The fit's state the fallbacks share with the main models.
pub struct Context<'a> {
    pub cache: &'a SeriesCache,
    pub plan: &'a Plan,
    pub folds: &'a [(Vec<Segment>, Vec<Segment>)],
    /// Candidates of the static MLR (unlagged rises of the selected sensors).
    pub static_idx: &'a [usize],
    pub cfg: &'a FitConfig,
    /// The greedy selection's candidates are the cache's first `greedy`;
    /// the others are the lag grid's (`lags.rs`).
    pub greedy: usize,
}

/// Sensor columns a fitted channel's chosen model reads.
pub fn model_sensors(file: &ModelFile, channel: &str) -> Vec<String> {
    let feats: Vec<&FeatureSpec> = match file.chosen.get(channel).map(String::as_str) {
        Some("none") => vec![],
        Some("ga-bpn") => file
            .nets
            .iter()
            .filter(|n| n.channel == channel)
            .flat_map(|n| n.features.iter())
            .collect(),
        Some("ridge") => file
            .ridge
            .iter()
            .filter(|m| m.channel == channel)
            .flat_map(|m| m.features.iter())
            .collect(),
        Some("mlr-static") => file
            .mlr_static
            .iter()
            .filter(|m| m.channel == channel)
            .flat_map(|m| m.features.iter())
            .collect(),
        _ => file
            .mlr
            .iter()
            .filter(|m| m.channel == channel)
            .flat_map(|m| m.features.iter())
            .collect(),
    };
    let mut out: Vec<String> = Vec::new();
    for f in feats {
        for c in f.kind.columns() {
            if c != "spindle_rpm" && !out.iter().any(|o| o == c) {
                out.push(c.to_string());
            }
        }
    }
    out
}

/// The sets of sensors to do without: each model sensor, then (with pairs) each pair.
pub fn exclusion_sets(sensors: &[String], pairs: bool) -> Vec<Vec<String>> {
    let mut sets: Vec<Vec<String>> = sensors.iter().map(|s| vec![s.clone()]).collect();
    if pairs {
        for i in 0..sensors.len() {
            for j in i + 1..sensors.len() {
                sets.push(vec![sensors[i].clone(), sensors[j].clone()]);
            }
        }
    }
    sets
}

/// Fit every fallback of every channel. `in_use` (candidate indices the
/// board already computes) grows with what the fallbacks add, within the
/// board's [`thermocomp_core::limits::MAX_INPUTS`].
pub fn fit_fallbacks(
    ctx: &Context,
    file: &ModelFile,
    channels: &[String],
    in_use: &mut Vec<usize>,
    notes: &mut Vec<String>,
) -> Result<(Vec<FallbackParams>, Vec<FallbackReport>)> {
    use thermocomp_core::limits::MAX_INPUTS;
    let (mut params, mut reports) = (Vec::new(), Vec::new());
    for ch in channels {
        let sensors = model_sensors(file, ch);
        for excluded in exclusion_sets(&sensors, ctx.cfg.fallback_pairs) {
            let reads_excluded = |i: usize| {
                ctx.cache.kinds[i]
                    .0
                    .columns()
                    .iter()
                    .any(|c| excluded.iter().any(|e| e == c))
            };
            // The candidates it may use, as a cache of their own (index map back).
            let allowed: Vec<usize> = (0..ctx.cache.kinds.len())
                .filter(|&i| !reads_excluded(i))
                .collect();
            if allowed.is_empty() {
                notes.push(format!(
                    "{ch}: no fallback without {}: every candidate input reads it",
                    excluded.join("+")
                ));
                continue;
            }
            let sub = SeriesCache {
                kinds: allowed
                    .iter()
                    .map(|&i| ctx.cache.kinds[i].clone())
                    .collect(),
                series: allowed
                    .iter()
                    .map(|&i| ctx.cache.series[i].clone())
                    .collect(),
            };
            let to_sub = |i: &usize| allowed.iter().position(|a| a == i);
            let sub_in_use: Vec<usize> = in_use.iter().filter_map(to_sub).collect();
            let budget = MAX_INPUTS.saturating_sub(in_use.len());
            let idx = match &ctx.cfg.features {
                FeatureChoice::Auto => {
                    let n_greedy = allowed.iter().filter(|&&i| i < ctx.greedy).count();
                    match fallback_inputs(ctx, &sub, ch, &sub_in_use, budget, n_greedy) {
                        Ok(i) => i,
                        Err(e) => {
                            notes.push(format!(
                                "{ch}: no fallback without {}: {e:#}",
                                excluded.join("+")
                            ));
                            continue;
                        }
                    }
                }
                FeatureChoice::List(_) => (0..sub.kinds.len()).collect(),
            };
            let new_in = |i: &&usize| !sub_in_use.contains(i);
            let left = budget.saturating_sub(idx.iter().filter(new_in).count());
            let static_all: Vec<usize> = ctx.static_idx.iter().filter_map(to_sub).collect();
            let static_ok: Vec<usize> = static_all
                .iter()
                .copied()
                .filter(|i| sub_in_use.contains(i) || idx.contains(i))
                .chain(
                    static_all
                        .iter()
                        .copied()
                        .filter(|i| !sub_in_use.contains(i) && !idx.contains(i))
                        .take(left),
                )
                .collect();
            let cv = if ctx.folds.len() > 1 {
                cross_validate(
                    &sub,
                    ctx.plan,
                    ctx.folds,
                    &idx,
                    &static_ok,
                    ch,
                    ctx.cfg,
                    NetCandidates {
                        net: false,
                        hybrid: false,
                        blend: false,
                        ridge: false,
                    },
                )?
            } else {
                BTreeMap::new()
            };
            let model = choose_model(&cv, ctx.cfg.choice_margin).unwrap_or_else(|| "mlr".into());
            let used: &[usize] = if model == "mlr-static" && !static_ok.is_empty() {
                &static_ok
            } else {
                &idx
            };
            let full = sub.samples(&ctx.plan.runs, &ctx.plan.train, used, ch)?;
            let val = sub.samples(&ctx.plan.runs, &ctx.plan.val, used, ch)?;
            if full.y.is_empty() || val.y.is_empty() {
                continue;
            }
            let kinds: Vec<_> = used.iter().map(|&i| sub.kinds[i].clone()).collect();
            let mlr = fit_mlr(ranged_specs(&kinds, &full), &full, ch)?;
            let pred: Vec<f64> = val.x.iter().map(|r| mlr.predict_raw(r)).collect();
            for &i in used {
                let orig = allowed[i];
                if !in_use.contains(&orig) {
                    in_use.push(orig);
                }
            }
            reports.push(FallbackReport {
                channel: ch.clone(),
                excluded: excluded.clone(),
                model: model.clone(),
                features: mlr.features.iter().map(FeatureSpec::name).collect(),
                cv,
                validation: metrics(&val.y, &pred),
            });
            let cv_rms_um = reports
                .last()
                .and_then(|r: &FallbackReport| r.cv.get(&r.model))
                .map(|c| c.rms_um);
            params.push(FallbackParams {
                channel: ch.clone(),
                excluded,
                model,
                params: mlr,
                cv_rms_um,
            });
        }
    }
    Ok((params, reports))
}

/// A fallback's inputs among the candidates `sub`: the greedy selection
/// among its first `n_greedy`, then (with a lag grid) each input's lag by
/// forward-chaining CV, as the main model's.
fn fallback_inputs(
    ctx: &Context,
    sub: &SeriesCache,
    ch: &str,
    in_use: &[usize],
    budget: usize,
    n_greedy: usize,
) -> Result<Vec<usize>> {
    let (runs, folds, cfg) = (&ctx.plan.runs, ctx.folds, ctx.cfg);
    let (i, _) = greedy_select(
        sub,
        runs,
        folds,
        ch,
        cfg.max_inputs,
        in_use,
        budget,
        n_greedy,
    )?;
    if cfg.lag_grid.is_empty() {
        return Ok(i);
    }
    Ok(choose_lags(sub, runs, folds, ch, &i, in_use, budget)?.0)
}

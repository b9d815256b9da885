//! The `fit` pipeline: plan the chronological / held-out split, gather the
//! candidate inputs ([`super::candidates`]), then per channel choose the
//! inputs, fit MLR and GA-BPN, cross-validate the choice and validate on
//! held-out rows only; the report ([`super::report`]) says what was fitted
//! and what `export` ships ([`super::shipped`]).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Result};

use super::candidates::candidate_set;
pub use super::candidates::candidates;
pub use super::choice::{
    choose_model, latest_block_rule, train_ensemble, CvScore, NetCandidates, NetInfo, NET_MODELS,
};
use super::choice::{cross_validate, train_hybrid};
use super::envelope;
use super::fallback;
use super::features;
use super::greedy::{blocked_folds, blocked_mse, greedy_select};
use super::lags::{choose_lags, lag_note};
use super::mlr::{fit_mlr, metrics, Metrics};
use super::model::{
    feature_name, Blend, FeatureKind, FeatureSpec, Hybrid, MlrParams, Model, ModelFile,
    NetEnsemble, MODEL_NAMES,
};
use super::output_lag;
pub use super::plan::{Candidates, FeatureChoice, FitConfig, Plan};
pub use super::progress::{Progress, Silent};
pub use super::report::{
    print_report, report_json, ChannelInfo, FitReport, ModelReport, RunMetrics,
};
use super::ridge::{all_blocks, choose_penalty, fit_ridge};
use super::samples::{ranged_specs, Samples, SeriesCache};
use super::shipped::shipped;
pub use super::shipped::{LeftOut, Shipped};
use super::split::Segment;
use super::stability::{assess, collinearity, stability_rule, Stability};
use tcomp_data::runcsv::Run;
use thermocomp_core::limits::{MAX_DIRECTIONS, MAX_INPUTS, MAX_NETS, MAX_NET_INPUTS};

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

/// Read runs and fit, telling `progress` how far the fit is.
pub fn run_fit(
    train: &[PathBuf],
    validate_runs: &[PathBuf],
    cfg: &FitConfig,
    progress: &dyn Progress,
) -> Result<FitReport> {
    let mut runs = Vec::new();
    for p in train.iter().chain(validate_runs) {
        runs.push((p.display().to_string(), Run::read(p)?));
    }
    fit_runs(runs, train.len(), cfg, progress)
}

/// Fit runs already read (`(label, run)`, the first `n_train` train),
/// telling `progress` how far the fit is.
pub fn fit_runs(
    runs: Vec<(String, Run)>,
    n_train: usize,
    cfg: &FitConfig,
    progress: &dyn Progress,
) -> Result<FitReport> {
    let mut notes = Vec::new();
    let (labels, runs): (Vec<String>, Vec<Run>) = runs
        .into_iter()
        .map(|(label, mut run)| {
            // The model predicts rises from the run's start (what the board serves).
            notes.extend(run.errors_as_rises(&label));
            (label, run)
        })
        .unzip();
    let plan = Plan::new(runs, labels, n_train, cfg.split_chrono)?;
    let mut report = fit_plan_with(&plan, cfg, progress)?;
    notes.append(&mut report.notes);
    report.notes = notes;
    Ok(report)
}

/// Fit on a planned split, silently.
pub fn fit_plan(plan: &Plan, cfg: &FitConfig) -> Result<FitReport> {
    fit_plan_with(plan, cfg, &Silent)
}

/// Fit on a planned split, telling `progress` each stage and step.
pub fn fit_plan_with(plan: &Plan, cfg: &FitConfig, progress: &dyn Progress) -> Result<FitReport> {
    let first = &plan.runs[plan.train[0].run];
    let (channels, ens) = checked_request(first, cfg)?;
    let folds = if cfg.select_folds <= 1 {
        let (inner, block) = plan.inner_block(cfg.es_frac);
        vec![(inner, block)]
    } else {
        blocked_folds(&plan.runs, &plan.train, cfg.select_folds)
    };
    let mut notes = Vec::new();
    let candidates = candidate_set(plan, cfg, &mut notes)?;
    let fit = ChannelFit {
        plan,
        cfg,
        cache: &candidates.cache,
        folds: &folds,
        static_idx: &candidates.static_idx,
        greedy: candidates.greedy,
        ens,
        progress,
    };
    let mut acc = Fitted::new(notes);
    for ch in &channels {
        fit.fit_channel(ch, &mut acc)?;
    }
    note_image_gaps(plan, &acc.file, &mut acc.notes)?;
    let fallbacks = if cfg.fallbacks {
        fit.fit_fallbacks(&channels, &mut acc)?
    } else {
        Vec::new()
    };
    let models = acc
        .reports
        .into_values()
        .filter(|r| !r.channels.is_empty())
        .collect();
    // The envelope policy's evidence (issue 50 item 3), on the training
    // rows' forward folds: what `export` writes in the image.
    let chosen: BTreeMap<String, envelope::ChosenInfo> = acc
        .inputs
        .iter()
        .filter_map(|i| {
            let name = acc.file.chosen.get(&i.channel)?;
            let info = envelope::ChosenInfo {
                stable: i.stability.get(name).is_some_and(|s| s.stable),
                ridge_penalty: (name == "ridge")
                    .then(|| i.cv.get("ridge").and_then(|c| c.penalty))
                    .flatten(),
            };
            Some((i.channel.clone(), info))
        })
        .collect();
    acc.file.envelope = envelope::evidence(
        &plan.runs,
        &plan.train,
        &acc.file,
        envelope::DEFAULT_MARGIN_RAW,
        &chosen,
    )?;
    // The output low-pass (issue 51 item 1), on the same forward folds.
    for (ch, lag) in output_lag::choose(&plan.runs, &plan.train, &acc.file, &chosen)? {
        acc.notes.push(format!(
            "{ch}: output low-pass {}: forward-CV RMS {:.2} -> {:.2} µm, about each hour's anchor {:.2} -> {:.2} µm",
            if lag.tau_s > 0.0 { format!("{:.0} s", lag.tau_s) } else { "none".into() },
            lag.before.0, lag.after.0, lag.before.1, lag.after.1
        ));
        if lag.tau_s > 0.0 {
            acc.file.output_lag_s.insert(ch, lag.tau_s);
        }
    }
    let selection = candidates.selection;
    let shipped = shipped(first, cfg, selection.as_ref(), &acc.file);
    Ok(FitReport {
        shipped,
        fallbacks,
        models,
        inputs: acc.inputs,
        chosen: acc.file.chosen.clone(),
        notes: acc.notes,
        selection,
        train_segments: plan.train.clone(),
        val_segments: plan.val.clone(),
        model_file: acc.file,
    })
}

/// The channels to fit, and the ensemble size, checked against the board's
/// limits.
fn checked_request(first: &Run, cfg: &FitConfig) -> Result<(Vec<String>, usize)> {
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
    Ok((channels, ens))
}

/// Sensor gaps: the board skips a step when any of the image's sensors is
/// empty; say where that differs from what each channel trained on.
fn note_image_gaps(plan: &Plan, file: &ModelFile, notes: &mut Vec<String>) -> Result<()> {
    let image_kinds = features::chosen_kinds(file);
    if let Some(n) = features::image_gap_rows(&plan.runs, &plan.train, &image_kinds)? {
        if n > 0 {
            notes.push(format!(
                "{n} training rows have a sensor gap in another channel's inputs: there the board's features for the exported model differ from the ones trained on (the board skips a step when any of its sensors is empty)"
            ));
        }
    }
    Ok(())
}

/// What the channels share while they are fitted one after another.
struct ChannelFit<'a> {
    plan: &'a Plan,
    cfg: &'a FitConfig,
    cache: &'a SeriesCache,
    folds: &'a [(Vec<Segment>, Vec<Segment>)],
    /// Candidates of the static MLR (unlagged rises of the selected sensors).
    static_idx: &'a [usize],
    /// The greedy selection's candidates: the cache's first (`lags.rs`
    /// moves a chosen input's lag to the others).
    greedy: usize,
    /// Networks per ensemble.
    ens: usize,
    /// Where the stages and training steps are reported.
    progress: &'a dyn Progress,
}

/// What the fit has gathered so far, and the board resources the fitted
/// channels hold (inputs and networks).
struct Fitted {
    reports: BTreeMap<&'static str, ModelReport>,
    inputs: Vec<ChannelInfo>,
    file: ModelFile,
    notes: Vec<String>,
    /// Candidate indices the chosen models read.
    in_use: Vec<usize>,
    nets_left: usize,
}

impl Fitted {
    fn new(notes: Vec<String>) -> Fitted {
        let reports = MODEL_NAMES
            .iter()
            .map(|n| {
                let report = ModelReport {
                    name: n.to_string(),
                    channels: BTreeMap::new(),
                    per_run: vec![],
                };
                (*n, report)
            })
            .collect();
        Fitted {
            reports,
            inputs: Vec::new(),
            file: ModelFile::default(),
            notes,
            in_use: Vec::new(),
            nets_left: MAX_NETS,
        }
    }

    /// Validation figures of model `name` on channel `ch`.
    fn record<M: Model>(&mut self, name: &str, ch: &str, m: &M, val: &Samples, plan: &Plan) {
        if let Some(r) = self.reports.get_mut(name) {
            r.channels
                .insert(ch.to_string(), validate(m, val, plan, &mut r.per_run));
        }
    }
}

/// One channel's inputs, rows and lagged MLR: what its networks build on.
struct ChannelRows<'c> {
    ch: &'c str,
    idx: &'c [usize],
    specs: &'c [FeatureSpec],
    full: &'c Samples,
    val: &'c Samples,
    mlr: &'c MlrParams,
}

impl ChannelFit<'_> {
    /// Fits every candidate model of channel `ch`, validates them and
    /// records the one cross-validation chose.
    fn fit_channel(&self, ch: &str, acc: &mut Fitted) -> Result<()> {
        let (plan, cfg, cache) = (self.plan, self.cfg, self.cache);
        if plan.runs[plan.train[0].run].col(ch).is_none() {
            bail!("fit: training run has no column `{ch}`");
        }
        let budget = MAX_INPUTS.saturating_sub(acc.in_use.len());
        let (idx, cv_mse) = self.channel_inputs(ch, &acc.in_use, budget, &mut acc.notes)?;
        let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
        let full = cache.samples(&plan.runs, &plan.train, &idx, ch)?;
        let val = cache.samples(&plan.runs, &plan.val, &idx, ch)?;
        if full.y.is_empty() || val.y.is_empty() {
            return Err(self.no_rows_error(ch, &kinds));
        }
        let static_ok = static_inputs(self.static_idx, &acc.in_use, &idx, budget);
        let with = NetCandidates {
            net: !cfg.skip_net,
            hybrid: !cfg.skip_net && cfg.hybrid,
            blend: !cfg.skip_net && cfg.blend,
            ridge: cfg.ridge,
        };
        self.progress.begin(&format!("cross-validating {ch}"));
        let mut cv = if self.folds.len() > 1 {
            cross_validate(cache, plan, self.folds, &idx, &static_ok, ch, cfg, with)?
        } else {
            BTreeMap::new()
        };
        self.progress.end();

        let specs = ranged_specs(&kinds, &full);
        let mlr = fit_mlr(specs.clone(), &full, ch)?;
        acc.record("mlr", ch, &mlr, &val, plan);
        if cfg.ridge {
            self.fit_ridge(ch, &idx, &specs, (&full, &val), &mut cv, acc)?;
        }
        if !static_ok.is_empty() {
            self.fit_static(ch, &static_ok, acc)?;
        }
        let stability = self.stabilities(&cv, &specs, &static_ok, &full);
        let mut info = ChannelInfo {
            channel: ch.to_string(),
            features: specs.iter().map(FeatureSpec::name).collect(),
            train_rows: full.y.len(),
            val_rows: val.y.len(),
            cv_rms_um: cv_mse.map(f64::sqrt),
            cv: cv.clone(),
            net: None,
            stability,
            collinearity: None,
        };
        let rows = ChannelRows {
            ch,
            idx: &idx,
            specs: &specs,
            full: &full,
            val: &val,
            mlr: &mlr,
        };
        let mut hybrid_empty = false;
        if with.net || with.hybrid {
            hybrid_empty = self.fit_networks(&rows, with, &cv, &mut info, acc)?;
        }
        let chosen = self.choose(ch, &cv, &info.stability, hybrid_empty, acc);
        let used_idx: &[usize] = match chosen.as_str() {
            "mlr-static" => &static_ok,
            "none" => &[],
            _ => &idx,
        };
        info.collinearity = match chosen.as_str() {
            "none" => None,
            "mlr-static" => acc.file.mlr_static.last().and_then(|m| {
                let rows = cache
                    .samples(&plan.runs, &plan.train, &static_ok, ch)
                    .ok()?;
                collinearity(&m.features, &rows)
            }),
            _ => collinearity(&specs, &full),
        };
        for &i in used_idx {
            if !acc.in_use.contains(&i) {
                acc.in_use.push(i);
            }
        }
        acc.file.chosen.insert(ch.to_string(), chosen);
        acc.inputs.push(info);
        acc.file.mlr.push(mlr);
        Ok(())
    }

    /// The channel's inputs (indices into the cache) and, for `auto`, the
    /// cross-validated MSE that chose them (the greedy selection's blocked
    /// CV; after the lag choice moved a lag, that CV of the final inputs).
    fn channel_inputs(
        &self,
        ch: &str,
        in_use: &[usize],
        budget: usize,
        notes: &mut Vec<String>,
    ) -> Result<(Vec<usize>, Option<f64>)> {
        let cfg = self.cfg;
        Ok(match cfg.features {
            FeatureChoice::Auto => {
                let (runs, folds) = (&self.plan.runs, self.folds);
                let (i, e) = greedy_select(
                    self.cache,
                    runs,
                    folds,
                    ch,
                    cfg.max_inputs,
                    in_use,
                    budget,
                    self.greedy,
                )?;
                let (i, moves) = match cfg.lag_grid.is_empty() {
                    true => (i, vec![]),
                    false => choose_lags(self.cache, runs, folds, ch, &i, in_use, budget)?,
                };
                if moves.is_empty() {
                    (i, Some(e))
                } else {
                    notes.push(lag_note(ch, self.cache, &moves));
                    let e = blocked_mse(self.cache, runs, folds, ch, &i)?;
                    (i, Some(e))
                }
            }
            FeatureChoice::List(_) => ((0..self.cache.kinds.len()).collect(), None),
        })
    }

    /// Fallback models per channel and excluded sensor(s), into the model file.
    fn fit_fallbacks(
        &self,
        channels: &[String],
        acc: &mut Fitted,
    ) -> Result<Vec<fallback::FallbackReport>> {
        let ctx = fallback::Context {
            cache: self.cache,
            plan: self.plan,
            folds: self.folds,
            static_idx: self.static_idx,
            cfg: self.cfg,
            greedy: self.greedy,
        };
        self.progress.begin("fallback models");
        let (params, reps) =
            fallback::fit_fallbacks(&ctx, &acc.file, channels, &mut acc.in_use, &mut acc.notes)?;
        self.progress.end();
        acc.file.fallbacks = params;
        Ok(reps)
    }

    /// Why channel `ch` has no rows: an input column that never reads
    /// there, else the channel itself.
    fn no_rows_error(&self, ch: &str, kinds: &[(FeatureKind, Option<f64>)]) -> anyhow::Error {
        let plan = self.plan;
        for (part, segs) in [("training", &plan.train), ("validation", &plan.val)] {
            for c in kinds.iter().flat_map(|k| k.0.columns()) {
                let reads = segs.iter().any(|s| {
                    plan.runs[s.run]
                        .col(c)
                        .is_some_and(|v| v[s.start..s.end].iter().any(Option::is_some))
                });
                if !reads {
                    return anyhow::anyhow!("fit: input {c} has no values in the {part} rows");
                }
            }
        }
        anyhow::anyhow!("fit: channel {ch} has no values in the training or validation rows")
    }

    /// The ridge on the channel's inputs, its penalty chosen by
    /// forward-chaining CV over all the training blocks (recorded as the
    /// `ridge` CV score's `penalty`); none when no fold has rows enough.
    fn fit_ridge(
        &self,
        ch: &str,
        idx: &[usize],
        specs: &[FeatureSpec],
        (full, val): (&Samples, &Samples),
        cv: &mut BTreeMap<String, CvScore>,
        acc: &mut Fitted,
    ) -> Result<()> {
        let blocks = all_blocks(self.folds);
        let Some(lambda) = choose_penalty(self.cache, &self.plan.runs, &blocks, idx, ch)? else {
            cv.remove("ridge");
            acc.notes.push(format!(
                "{ch}: no ridge: too few training rows to choose its penalty by forward-chaining CV"
            ));
            return Ok(());
        };
        let r = fit_ridge(specs.to_vec(), full, lambda, ch)?;
        acc.record("ridge", ch, &r, val, self.plan);
        acc.file.ridge.push(r);
        if let Some(sc) = cv.get_mut("ridge") {
            sc.penalty = Some(lambda);
        }
        Ok(())
    }

    /// How the coefficients of each linear candidate moved across the CV
    /// folds (`stability`), in the standard deviations of the target.
    fn stabilities(
        &self,
        cv: &BTreeMap<String, CvScore>,
        specs: &[FeatureSpec],
        static_ok: &[usize],
        full: &Samples,
    ) -> BTreeMap<String, Stability> {
        let n = full.y.len().max(1) as f64;
        let mean = full.y.iter().sum::<f64>() / n;
        let y_sd = (full.y.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / n).sqrt();
        let names: Vec<String> = specs.iter().map(FeatureSpec::name).collect();
        let static_names: Vec<String> = static_ok
            .iter()
            .map(|&i| feature_name(&self.cache.kinds[i].0, self.cache.kinds[i].1))
            .collect();
        cv.iter()
            .filter(|(_, sc)| !sc.fold_coefs.is_empty())
            .map(|(name, sc)| {
                let n = if name == "mlr-static" {
                    &static_names
                } else {
                    &names
                };
                (name.clone(), assess(n, &sc.fold_coefs, y_sd))
            })
            .collect()
    }

    /// The static MLR on the inputs `static_ok`.
    fn fit_static(&self, ch: &str, static_ok: &[usize], acc: &mut Fitted) -> Result<()> {
        let (plan, cache) = (self.plan, self.cache);
        let fs = cache.samples(&plan.runs, &plan.train, static_ok, ch)?;
        let vs = cache.samples(&plan.runs, &plan.val, static_ok, ch)?;
        let sk: Vec<_> = static_ok.iter().map(|&i| cache.kinds[i].clone()).collect();
        let m = fit_mlr(ranged_specs(&sk, &fs), &fs, ch)?;
        acc.record("mlr-static", ch, &m, &vs, plan);
        acc.file.mlr_static.push(m);
        Ok(())
    }

    /// The GA-BPN ensemble (and the blend) and the hybrid, as `with` asks;
    /// returns whether the hybrid kept no networks.
    fn fit_networks(
        &self,
        c: &ChannelRows,
        with: NetCandidates,
        cv: &BTreeMap<String, CvScore>,
        info: &mut ChannelInfo,
        acc: &mut Fitted,
    ) -> Result<bool> {
        let (plan, cfg, cache, ch) = (self.plan, self.cfg, self.cache, c.ch);
        let (inner, block) = plan.inner_block(cfg.es_frac);
        let inner_s = cache.samples_capped(&plan.runs, &inner, c.idx, ch, cfg.net.max_rows)?;
        let block_s = cache.samples_capped(&plan.runs, &block, c.idx, ch, cfg.net.max_rows)?;
        let full_s = c.full.strided(cfg.net.max_rows);
        if with.net {
            self.progress.begin(&format!("GA-BPN {ch}"));
            let (members, infos) = train_ensemble(
                c.specs,
                ch,
                &inner_s,
                &block_s,
                &full_s,
                &cfg.net,
                self.progress,
            );
            self.progress.end();
            let ens = NetEnsemble {
                members: members.iter().collect(),
            };
            acc.record("ga-bpn", ch, &ens, c.val, plan);
            info.net = infos.into_iter().next();
            if let Some(w) = cv.get("blend").and_then(|s| s.weight) {
                let b = Blend {
                    mlr: c.mlr,
                    nets: NetEnsemble {
                        members: members.iter().collect(),
                    },
                    w,
                };
                acc.record("blend", ch, &b, c.val, plan);
                acc.file.blend.insert(ch.to_string(), w);
            }
            acc.file.nets.extend(members);
        }
        let mut hybrid_empty = false;
        if with.hybrid {
            self.progress.begin(&format!("hybrid {ch}"));
            let members = train_hybrid(
                c.mlr,
                c.specs,
                &inner_s,
                &block_s,
                &full_s,
                &cfg.net,
                self.progress,
            );
            self.progress.end();
            if members.is_empty() {
                acc.notes.push(format!(
                    "{ch}: the hybrid's residual networks did not lower the residual on the early-stopping block: the hybrid is the MLR alone"
                ));
                acc.record("hybrid", ch, c.mlr, c.val, plan);
            } else {
                let hyb = Hybrid {
                    mlr: c.mlr,
                    residual: NetEnsemble {
                        members: members.iter().collect(),
                    },
                };
                acc.record("hybrid", ch, &hyb, c.val, plan);
            }
            hybrid_empty = members.is_empty();
            acc.file.hybrid_nets.extend(members);
        }
        Ok(hybrid_empty)
    }

    /// The choice: cross-validated on training rows, within the board's
    /// networks; takes the chosen model's networks from what is left.
    fn choose(
        &self,
        ch: &str,
        cv: &BTreeMap<String, CvScore>,
        stab: &BTreeMap<String, Stability>,
        hybrid_empty: bool,
        acc: &mut Fitted,
    ) -> String {
        let (margin, ens) = (self.cfg.choice_margin, self.ens);
        let mut admissible = cv.clone();
        admissible.retain(|_, s| !s.dropped);
        for (name, r, bar) in latest_block_rule(&mut admissible, margin) {
            acc.notes.push(format!(
                "{ch}: {name} is not admissible: RMS {r:.2} µm on the latest training block (the one fold that forecasts forward) against the linear model's {bar:.2} µm"
            ));
        }
        for (u, s) in stability_rule(&mut admissible, stab, margin) {
            acc.notes.push(stability_note(ch, &u, &s, cv, stab));
        }
        for name in NET_MODELS {
            if admissible.contains_key(name) && acc.nets_left < ens {
                admissible.remove(name);
                acc.notes.push(format!(
                    "{ch}: {name} is not admissible (the board holds {MAX_NETS} networks, {} in use)",
                    MAX_NETS - acc.nets_left
                ));
            }
        }
        let mut chosen = choose_model(&admissible, margin).unwrap_or_else(|| "mlr".into());
        if chosen == "hybrid" && hybrid_empty {
            // The final hybrid kept no networks: it is the lagged MLR.
            chosen = "mlr".into();
        }
        if chosen == "blend" {
            // All weight on one part: the blend is that part.
            match acc.file.blend.get(ch) {
                Some(w) if *w >= 1.0 => chosen = "mlr".into(),
                Some(w) if *w <= 0.0 => chosen = "ga-bpn".into(),
                _ => {}
            }
        }
        if chosen == "ga-bpn" || chosen == "hybrid" || chosen == "blend" {
            acc.nets_left -= ens;
        }
        if chosen == "none" {
            acc.notes.push(format!(
                "{ch}: no model beats no compensation by more than {:.0} % in the training CV (RMS {:.2} µm without compensation): the board serves 0 for it (`export --use {ch}=mlr` ships the lagged MLR anyway)",
                100.0 * margin,
                admissible.get("none").map_or(f64::NAN, |s| s.rms_um)
            ));
        }
        chosen
    }
}

/// Static inputs the board can still take: those already in use or among
/// the channel's inputs `idx`, then new ones up to the input budget.
fn static_inputs(
    static_idx: &[usize],
    in_use: &[usize],
    idx: &[usize],
    budget: usize,
) -> Vec<usize> {
    let new_inputs = idx.iter().filter(|i| !in_use.contains(i)).count();
    static_idx
        .iter()
        .copied()
        .filter(|i| in_use.contains(i) || idx.contains(i))
        .chain(
            static_idx
                .iter()
                .copied()
                .filter(|i| !in_use.contains(i) && !idx.contains(i))
                .take(budget.saturating_sub(new_inputs)),
        )
        .collect()
}

/// Why the stability rule set `u` aside in favour of `s` on channel `ch`.
fn stability_note(
    ch: &str,
    u: &str,
    s: &str,
    cv: &BTreeMap<String, CvScore>,
    stab: &BTreeMap<String, Stability>,
) -> String {
    let rms = |n: &str| cv.get(n).map_or(f64::NAN, |c| c.rms_um);
    let why = match stab.get(u) {
        Some(st) => {
            let (lo, hi) = st.coef_range_um.unwrap_or((f64::NAN, f64::NAN));
            let input = st.worst_input.as_deref().unwrap_or("?");
            match st.worst_factor {
                _ if st.sign_flip => format!(
                    "the coefficient of {input} flips sign across the {} CV folds ({lo:+.2} to {hi:+.2} µm per standard deviation)",
                    st.folds
                ),
                Some(f) => format!(
                    "the coefficient of {input} changes by a factor {f:.1} across the {} CV folds ({lo:+.2} to {hi:+.2} µm per standard deviation)",
                    st.folds
                ),
                None => "its coefficients are unstable across the CV folds".to_string(),
            }
        }
        None => "its coefficients are unstable across the CV folds".to_string(),
    };
    format!(
        "{ch}: {u} is not chosen: {why}; {s} is stabler and within noise of it (CV RMS {:.2} against {:.2} µm)",
        rms(s),
        rms(u)
    )
}

//! The `fit` pipeline: plan the chronological / held-out split, choose the
//! inputs, fit MLR and GA-BPN per channel, validate on held-out rows only.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Result};
use serde::Serialize;

pub use super::choice::{
    choose_model, latest_block_rule, train_ensemble, CvScore, NetCandidates, NetInfo, NET_MODELS,
};
use super::choice::{cross_validate, progress_bar, train_hybrid, training_span_s};
use super::fallback;
use super::features;
pub use super::plan::{Candidates, FeatureChoice, FitConfig, Plan};
use super::*;
use crate::select::{self, Selection};
use tcomp_data::runcsv::Run;
use thermocomp_core::limits::{MAX_DIRECTIONS, MAX_INPUTS, MAX_NETS, MAX_NET_INPUTS, MAX_SENSORS};

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
    pub fallbacks: Vec<fallback::FallbackReport>,
    /// Per channel, what `export` ships: the model, the sensors it reads,
    /// and every temperature column it does not read, with why.
    pub shipped: Vec<Shipped>,
    #[serde(skip)]
    pub model_file: ModelFile,
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

/// One channel of what `export` ships.
#[derive(Clone, Debug, Serialize)]
pub struct Shipped {
    pub channel: String,
    /// The chosen model (`mlr`, `ga-bpn`, `none`, …).
    pub model: String,
    /// The temperature columns its inputs read.
    pub sensors: Vec<String>,
    /// Every other temperature column of the training run, with why.
    pub left_out: Vec<LeftOut>,
}

/// A temperature column a channel's shipped model does not read.
#[derive(Clone, Debug, Serialize)]
pub struct LeftOut {
    pub sensor: String,
    pub why: String,
}

/// Read runs and fit.
pub fn run_fit(train: &[PathBuf], validate_runs: &[PathBuf], cfg: &FitConfig) -> Result<FitReport> {
    let mut runs = Vec::new();
    for p in train.iter().chain(validate_runs) {
        runs.push((p.display().to_string(), Run::read(p)?));
    }
    fit_runs(runs, train.len(), cfg)
}

/// Fit runs already read (`(label, run)`, the first `n_train` train).
pub fn fit_runs(runs: Vec<(String, Run)>, n_train: usize, cfg: &FitConfig) -> Result<FitReport> {
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
    let mut report = fit_plan(&plan, cfg)?;
    notes.append(&mut report.notes);
    report.notes = notes;
    Ok(report)
}

/// Fit on a planned split.
pub fn fit_plan(plan: &Plan, cfg: &FitConfig) -> Result<FitReport> {
    let first = &plan.runs[plan.train[0].run];
    let (channels, ens) = checked_request(first, cfg)?;
    let folds = if cfg.select_folds <= 1 {
        let (inner, block) = plan.inner_block(cfg.es_frac);
        vec![(inner, block)]
    } else {
        blocked_folds(&plan.runs, &plan.train, cfg.select_folds)
    };
    // The board reads temperature channels 0..MAX_SENSORS in the run's
    // column order: sensors beyond are never candidates.
    let board_sensors = features::board_channels(first);
    let picked = picked_sensors(first, cfg, &board_sensors)?;
    let mut notes = Vec::new();
    let lags = candidate_lags(plan, cfg, &mut notes)?;
    let selection = match &picked {
        // The user's picks (`select`'s) are the candidates: no new grouping.
        Some(_) => None,
        None => select_sensors(plan, cfg, &board_sensors)?,
    };
    let has_spindle = first.col("spindle_rpm").is_some();
    let auto_sensors = match (&picked, &selection) {
        (Some(p), _) => Some((p.clone(), p.clone())),
        (None, Some(sel)) => Some((
            match cfg.candidates {
                Candidates::Selected => sel.chosen.clone(),
                Candidates::All => sel.sensors.clone(),
            },
            sel.chosen.clone(),
        )),
        (None, None) => None,
    };
    let (cache, static_idx) = candidate_cache(
        plan,
        cfg,
        auto_sensors.as_ref(),
        &lags,
        has_spindle,
        &board_sensors,
    )?;
    let fit = ChannelFit {
        plan,
        cfg,
        cache: &cache,
        folds: &folds,
        static_idx: &static_idx,
        ens,
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

/// The candidate lags no longer than the training span; notes what the
/// board's channels and the span rule out.
fn candidate_lags(plan: &Plan, cfg: &FitConfig, notes: &mut Vec<String>) -> Result<Vec<f64>> {
    let first = &plan.runs[plan.train[0].run];
    let beyond = first
        .temperature_columns()
        .len()
        .saturating_sub(MAX_SENSORS);
    if beyond > 0 {
        notes.push(format!(
            "{beyond} temperature column(s) beyond the board's {MAX_SENSORS} channels are not candidates: {} (the board reads the run's first {MAX_SENSORS} T_ columns; put a sensor you need among them)",
            first.temperature_columns()[MAX_SENSORS..].join(", ")
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
    Ok(lags)
}

/// Sensor selection for `auto`, on training rows only, among the board's channels.
fn select_sensors(
    plan: &Plan,
    cfg: &FitConfig,
    board_sensors: &[String],
) -> Result<Option<Selection>> {
    if !matches!(cfg.features, FeatureChoice::Auto) {
        return Ok(None);
    }
    let slices: Vec<Run> = plan
        .train
        .iter()
        .map(|s| {
            plan.runs[s.run]
                .slice_rows(s.start, s.end)
                .keep_temperatures(board_sensors)
        })
        .collect();
    let groups = cfg.groups.min(board_sensors.len());
    Ok(Some(select::select(&slices, groups, 0)?))
}

/// `--sensors`: the user's picks, checked against the training run's
/// temperature columns and the board's channels; `None` when not given.
fn picked_sensors(
    first: &Run,
    cfg: &FitConfig,
    board_sensors: &[String],
) -> Result<Option<Vec<String>>> {
    let Some(want) = &cfg.sensors else {
        return Ok(None);
    };
    if want.is_empty() {
        bail!("fit: --sensors names no sensor");
    }
    let all = first.temperature_columns();
    for s in want {
        if !all.contains(&s.as_str()) {
            bail!(
                "fit: --sensors: {s} is not a temperature column of the training run (its T_ columns: {})",
                all.join(", ")
            );
        }
        if !board_sensors.contains(s) {
            bail!(
                "fit: --sensors: {s} is beyond the board's {MAX_SENSORS} channels (the board reads the run's first {MAX_SENSORS} T_ columns)"
            );
        }
    }
    if matches!(cfg.features, FeatureChoice::List(_)) {
        bail!("fit: --sensors chooses the candidates of `--features auto`; with a --features list, name the inputs there");
    }
    Ok(Some(want.clone()))
}

/// Per channel, the shipped model, its sensors and why every other
/// temperature column of the training run is not among them.
fn shipped(
    first: &Run,
    cfg: &FitConfig,
    selection: Option<&Selection>,
    file: &ModelFile,
) -> Vec<Shipped> {
    let mut out = Vec::new();
    for (ch, model) in &file.chosen {
        let params = match model.as_str() {
            "none" => None,
            "mlr-static" => file.mlr_static.iter().find(|m| m.channel == *ch),
            _ => file.mlr.iter().find(|m| m.channel == *ch),
        };
        let mut sensors: Vec<String> = Vec::new();
        for f in params.map_or(&[][..], |m| &m.features[..]) {
            for c in f.kind.columns() {
                if c != "spindle_rpm" && !sensors.iter().any(|s| s == c) {
                    sensors.push(c.to_string());
                }
            }
        }
        let left_out = first
            .temperature_columns()
            .iter()
            .enumerate()
            .filter(|(_, s)| !sensors.iter().any(|u| u == *s))
            .map(|(i, s)| LeftOut {
                sensor: s.to_string(),
                why: left_out_why(i, s, model, cfg, selection),
            })
            .collect();
        out.push(Shipped {
            channel: ch.clone(),
            model: model.clone(),
            sensors,
            left_out,
        });
    }
    out
}

/// Why the temperature column `s` (the run's `i`-th) is not read by a
/// channel whose shipped model is `model`.
fn left_out_why(
    i: usize,
    s: &str,
    model: &str,
    cfg: &FitConfig,
    selection: Option<&Selection>,
) -> String {
    if i >= MAX_SENSORS {
        return format!(
            "beyond the board's {MAX_SENSORS} channels (the board reads the run's first {MAX_SENSORS} T_ columns)"
        );
    }
    if cfg
        .sensors
        .as_ref()
        .is_some_and(|p| !p.iter().any(|x| x == s))
    {
        return "not among the picked sensors (--sensors, --sensors-from)".into();
    }
    if let FeatureChoice::List(kinds) = &cfg.features {
        if !kinds.iter().any(|(k, _)| k.columns().contains(&s)) {
            return "not in --features".into();
        }
    }
    if let Some(sel) = selection {
        if let Some(why) = sel.left_out.get(s) {
            return format!("select left it out: {why}");
        }
        if cfg.candidates == Candidates::Selected && !sel.chosen.iter().any(|c| c == s) {
            if let Some((g, best)) = sel
                .clusters
                .iter()
                .zip(&sel.chosen)
                .enumerate()
                .find(|(_, (members, _))| members.iter().any(|m| m == s))
                .map(|(g, (_, best))| (g, best))
            {
                let score = |n: &str| sel.scores.get(n).copied().unwrap_or(f64::NAN);
                return format!(
                    "not its group's best in select (group {}: {best}, score {:.3} against its {:.3})",
                    g + 1,
                    score(best),
                    score(s)
                );
            }
        }
    }
    match model {
        "none" => "the channel ships no compensation (no model beat 0 by the choice margin)".into(),
        "mlr-static" => "not an input of the chosen static MLR (unlagged rises of the selected sensors)".into(),
        _ if matches!(cfg.features, FeatureChoice::Auto) => format!(
            "a candidate the cross-validated forward selection did not pick for this channel (at most {} inputs: --max-inputs)",
            cfg.max_inputs
        ),
        _ => "not an input of the chosen model".into(),
    }
}

/// The candidate cache shared by all channels, and the candidates of the
/// static MLR (unlagged rises of the selected sensors). `auto_sensors`:
/// for `auto`, the candidate sensors and the static MLR's sensors.
fn candidate_cache(
    plan: &Plan,
    cfg: &FitConfig,
    auto_sensors: Option<&(Vec<String>, Vec<String>)>,
    lags: &[f64],
    has_spindle: bool,
    board_sensors: &[String],
) -> Result<(SeriesCache, Vec<usize>)> {
    match (&cfg.features, auto_sensors) {
        (FeatureChoice::Auto, Some((sensors, static_sensors))) => {
            let kinds = candidates(sensors, lags, has_spindle);
            let static_idx = static_sensors
                .iter()
                .filter_map(|s| {
                    kinds
                        .iter()
                        .position(|k| *k == (FeatureKind::SensorRise(s.clone()), None))
                })
                .take(MAX_NET_INPUTS)
                .collect();
            Ok((SeriesCache::new(&plan.runs, kinds)?, static_idx))
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
            Ok((SeriesCache::new(&plan.runs, kinds.clone())?, vec![]))
        }
        (FeatureChoice::Auto, None) => bail!("internal: no selection"),
    }
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
    /// Networks per ensemble.
    ens: usize,
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
        let (idx, cv_mse) = self.channel_inputs(ch, &acc.in_use, budget)?;
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
        };
        let pb = progress_bar(cfg.progress, 1, format!("cross-validating {ch}"));
        let cv = if self.folds.len() > 1 {
            cross_validate(cache, plan, self.folds, &idx, &static_ok, ch, cfg, with)?
        } else {
            BTreeMap::new()
        };
        pb.finish_and_clear();

        let specs = ranged_specs(&kinds, &full);
        let mlr = fit_mlr(specs.clone(), &full, ch)?;
        acc.record("mlr", ch, &mlr, &val, plan);
        if !static_ok.is_empty() {
            self.fit_static(ch, &static_ok, acc)?;
        }
        let mut info = ChannelInfo {
            channel: ch.to_string(),
            features: specs.iter().map(FeatureSpec::name).collect(),
            train_rows: full.y.len(),
            val_rows: val.y.len(),
            cv_rms_um: cv_mse.map(f64::sqrt),
            cv: cv.clone(),
            net: None,
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
        let chosen = self.choose(ch, &cv, hybrid_empty, acc);
        let used_idx: &[usize] = match chosen.as_str() {
            "mlr-static" => &static_ok,
            "none" => &[],
            _ => &idx,
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
    /// cross-validated MSE that chose them.
    fn channel_inputs(
        &self,
        ch: &str,
        in_use: &[usize],
        budget: usize,
    ) -> Result<(Vec<usize>, Option<f64>)> {
        let cfg = self.cfg;
        Ok(match cfg.features {
            FeatureChoice::Auto => {
                let (i, e) = greedy_select(
                    self.cache,
                    &self.plan.runs,
                    self.folds,
                    ch,
                    cfg.max_inputs,
                    in_use,
                    budget,
                )?;
                (i, Some(e))
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
        };
        let pb = progress_bar(self.cfg.progress, 1, "fallback models".into());
        let (params, reps) =
            fallback::fit_fallbacks(&ctx, &acc.file, channels, &mut acc.in_use, &mut acc.notes)?;
        pb.finish_and_clear();
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
            let pb = progress_bar(cfg.progress, 1, format!("GA-BPN {ch}"));
            let (members, infos) =
                train_ensemble(c.specs, ch, &inner_s, &block_s, &full_s, &cfg.net, &pb);
            pb.finish_and_clear();
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
            let pb = progress_bar(cfg.progress, 1, format!("hybrid {ch}"));
            let members = train_hybrid(c.mlr, c.specs, &inner_s, &block_s, &full_s, &cfg.net, &pb);
            pb.finish_and_clear();
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

/// Plain-text report.
pub fn print_report(r: &FitReport) {
    for n in &r.notes {
        println!("note: {n}");
    }
    if let Some(s) = &r.selection {
        println!("selected sensors (training rows): {}", s.chosen.join(","));
    }
    print_shipped(&r.shipped);
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

/// What `export` will ship per channel, and every sensor left out with why.
fn print_shipped(shipped: &[Shipped]) {
    if shipped.is_empty() {
        return;
    }
    println!("what `export` ships (the cross-validated choice; `export --use` overrides it):");
    for c in shipped {
        let what = match c.model.as_str() {
            "none" => "no compensation (serves 0)",
            "mlr" => "lagged MLR",
            "mlr-static" => "static MLR",
            "ga-bpn" => "GA-BPN network ensemble",
            "hybrid" => "lagged MLR + residual networks",
            "blend" => "blend of the MLR and the networks",
            other => other,
        };
        let reads = if c.sensors.is_empty() {
            "no sensor".to_string()
        } else {
            c.sensors.join(", ")
        };
        println!("  {}: {} ({what}), reads {reads}", c.channel, c.model);
        for l in &c.left_out {
            println!("    left out {}: {}", l.sensor, l.why);
        }
    }
    println!();
}

/// `{"models": [{"name", "channels": {...}}], ...}` (validation figures only).
pub fn report_json(r: &FitReport) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

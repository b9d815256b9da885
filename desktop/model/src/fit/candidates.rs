//! The candidate inputs every channel of a fit chooses among: the sensors
//! (the user's picks from `--sensors`, else `select`'s on the training rows,
//! always within the board's channels), the lags no longer than the
//! training span, and the cache of their series over the runs.

use anyhow::{bail, Result};

use super::choice::training_span_s;
use super::features;
use super::model::FeatureKind;
use super::plan::{Candidates, FeatureChoice, FitConfig, Plan};
use super::samples::SeriesCache;
use crate::select::{self, Selection};
use tcomp_data::runcsv::Run;
use thermocomp_core::limits::{MAX_NET_INPUTS, MAX_SENSORS};

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

/// The candidates a fit's channels share.
pub(super) struct CandidateSet {
    /// Every candidate's series over the runs.
    pub cache: SeriesCache,
    /// Candidates of the static MLR (unlagged rises of the selected sensors).
    pub static_idx: Vec<usize>,
    /// `select`'s grouping on the training rows (`auto` without `--sensors`).
    pub selection: Option<Selection>,
    /// The greedy selection's candidates are `cache.kinds[..greedy]` (the
    /// lags of `FitConfig::lags`); after them, the other lags of
    /// `FitConfig::lag_grid` a chosen input's lag may move to (`lags.rs`).
    pub greedy: usize,
}

/// The candidates of the fit on `plan`; notes what the board's channels and
/// the training span rule out.
pub(super) fn candidate_set(
    plan: &Plan,
    cfg: &FitConfig,
    notes: &mut Vec<String>,
) -> Result<CandidateSet> {
    let first = &plan.runs[plan.train[0].run];
    // The board reads temperature channels 0..MAX_SENSORS in the run's
    // column order: sensors beyond are never candidates.
    let board_sensors = features::board_channels(first);
    let picked = picked_sensors(first, cfg, &board_sensors)?;
    let (lags, grid) = candidate_lags(plan, cfg, notes)?;
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
    let (cache, static_idx, greedy) = candidate_cache(
        plan,
        cfg,
        auto_sensors.as_ref(),
        (&lags, &grid),
        has_spindle,
        &board_sensors,
    )?;
    Ok(CandidateSet {
        cache,
        static_idx,
        selection,
        greedy,
    })
}

/// The greedy selection's candidate lags and the lag grid's other lags,
/// each no longer than the training span; notes what the board's channels
/// and the span rule out.
fn candidate_lags(
    plan: &Plan,
    cfg: &FitConfig,
    notes: &mut Vec<String>,
) -> Result<(Vec<f64>, Vec<f64>)> {
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
    let mut grid: Vec<f64> = Vec::new();
    for &l in &cfg.lag_grid {
        if l <= span && !lags.contains(&l) && !grid.contains(&l) {
            grid.push(l);
        }
    }
    Ok((lags, grid))
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

/// The candidate cache shared by all channels, the candidates of the
/// static MLR (unlagged rises of the selected sensors) and how many of the
/// first candidates the greedy selection chooses among. `auto_sensors`:
/// for `auto`, the candidate sensors and the static MLR's sensors; `lags`:
/// the greedy selection's lags and the lag grid's others.
fn candidate_cache(
    plan: &Plan,
    cfg: &FitConfig,
    auto_sensors: Option<&(Vec<String>, Vec<String>)>,
    (lags, grid): (&[f64], &[f64]),
    has_spindle: bool,
    board_sensors: &[String],
) -> Result<(SeriesCache, Vec<usize>, usize)> {
    match (&cfg.features, auto_sensors) {
        (FeatureChoice::Auto, Some((sensors, static_sensors))) => {
            let mut kinds = candidates(sensors, lags, has_spindle);
            let greedy = kinds.len();
            kinds.extend(candidates(sensors, grid, has_spindle));
            let static_idx = static_sensors
                .iter()
                .filter_map(|s| {
                    kinds
                        .iter()
                        .position(|k| *k == (FeatureKind::SensorRise(s.clone()), None))
                })
                .take(MAX_NET_INPUTS)
                .collect();
            Ok((SeriesCache::new(&plan.runs, kinds)?, static_idx, greedy))
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
            Ok((
                SeriesCache::new(&plan.runs, kinds.clone())?,
                vec![],
                kinds.len(),
            ))
        }
        (FeatureChoice::Auto, None) => bail!("internal: no selection"),
    }
}

//! What a fit works on: the runs and their split into fit, time-block and
//! validation rows (`Plan`), and the fit's settings (`FitConfig`).

use super::net::NetOpts;
use anyhow::{bail, Context, Result};

use super::model::FeatureKind;
use super::split::{chrono_split, time_block_split, Segment};
use tcomp_data::runcsv::Run;

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
    /// Candidate lags of `auto`'s greedy input selection, seconds (0 = no lag).
    pub lags: Vec<f64>,
    /// The lags each chosen input's lag may then move to, chosen per input
    /// by forward-chaining CV on the training rows (`lags.rs`; empty, the
    /// default: the greedy selection's lags stay; `lags::LAG_GRID` is the
    /// geometric grid `--lag-grid geometric` asks for).
    pub lag_grid: Vec<f64>,
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
    /// The candidate sensors of `auto`, given (`select`'s picks) instead
    /// of chosen by a new selection on the training rows.
    pub sensors: Option<Vec<String>>,
    /// Fit and offer the ridge candidate (`ridge`, issue 50).
    pub ridge: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            split_chrono: None,
            features: FeatureChoice::Auto,
            lags: vec![0.0, 1800.0, 3600.0, 7200.0, 10800.0, 21600.0],
            lag_grid: vec![],
            max_inputs: 5,
            candidates: Candidates::Selected,
            groups: 5,
            channels: None,
            net: NetOpts::default(),
            es_frac: 0.15,
            select_folds: 5,
            skip_net: false,
            choice_margin: 0.02,
            hybrid: false,
            cv_drop: true,
            blend: false,
            fallbacks: true,
            fallback_pairs: false,
            sensors: None,
            ridge: true,
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

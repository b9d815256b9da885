//! The diagnosis's own types: its settings, a finding, the whole result
//! and the report's held-out gaps. A leaf: the modules of `diagnose` take
//! them from here, `diagnose` re-exports them for its callers.

use serde_json::{json, Value};

use crate::sim::Effect;

/// Settings of a diagnosis.
#[derive(Clone, Debug)]
pub struct Options {
    /// Fraction of each run's time used to fit (of the run when there is one
    /// run, of every hold-out block when there are several).
    pub fit_fraction: f64,
    /// With several runs: every run is cut into blocks of this length [s];
    /// the first `fit_fraction` of each block is fitted, the rest held out.
    pub holdout_block_s: f64,
    /// Decimate runs above this many rows.
    pub max_rows: usize,
    /// BIC improvement required to claim an effect.
    pub min_dbic: f64,
    /// Relative held-out reduction required (0..1).
    pub min_rel: f64,
    /// Absolute held-out reduction required (noise-variance units).
    pub min_abs: f64,
    /// Nelder–Mead evaluations per single candidate.
    pub budget: usize,
    /// Try at most 2× this many pairs (best single + another candidate).
    pub pair_top: usize,
    /// Threads for fitting candidates in parallel.
    pub threads: usize,
    /// Restrict the candidates (empty = all applicable).
    pub only: Vec<String>,
    /// Take the machine file as exact (no calibration within its
    /// tolerances): the behaviour before issue 27.
    pub exact: bool,
    /// Accepted for compatibility, no effect: the default calibrates the
    /// file within its tolerances (`calibrate.rs`); `exact` turns that off.
    pub calibrate: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            fit_fraction: 0.6,
            holdout_block_s: 3600.0,
            max_rows: 3000,
            min_dbic: 10.0,
            min_rel: 0.15,
            min_abs: 0.5,
            budget: 45,
            pair_top: 8,
            threads: std::thread::available_parallelism()
                .map_or(1, |n| n.get())
                .min(8),
            only: Vec::new(),
            exact: false,
            calibrate: false,
        }
    }
}

/// One supported effect (or combination) of the diagnosis.
#[derive(Clone, Debug)]
pub struct Finding {
    pub name: String,
    pub effects: Vec<Effect>,
    pub dbic: f64,
    pub m_before: f64,
    pub m_after: f64,
    pub gap_um: Option<((f64, f64), (f64, f64))>,
    pub gap_c: Option<((f64, f64), (f64, f64))>,
    pub evidence: Value,
    /// Parameters of an effect that is not a simulator effect (`diagnose fit`).
    pub params: Option<Value>,
}

impl Finding {
    pub fn params_json(&self) -> Value {
        if let Some(p) = &self.params {
            p.clone()
        } else if self.effects.len() == 1 {
            self.effects[0].params_json()
        } else {
            let mut o = serde_json::Map::new();
            for e in &self.effects {
                o.insert(e.name().to_string(), e.params_json());
            }
            Value::Object(o)
        }
    }

    pub fn to_json(&self) -> Value {
        json!({
            "name": self.name,
            "params": self.params_json(),
            "gap_before_um": self.gap_um.map(|g| g.0 .0),
            "gap_after_um": self.gap_um.map(|g| g.1 .0),
            "gap_before_c": self.gap_c.map(|g| g.0 .0),
            "gap_after_c": self.gap_c.map(|g| g.1 .0),
            "evidence": self.evidence,
        })
    }
}

/// A finding with its role in the ranking (`evidence.role`).
pub(super) fn with_role(f: &Finding, role: &str) -> Finding {
    let mut g = f.clone();
    if let Some(o) = g.evidence.as_object_mut() {
        o.insert("role".into(), json!(role));
    }
    g
}

/// Everything a diagnosis found.
#[derive(Clone, Debug)]
pub struct Diagnosis {
    pub machine: String,
    pub findings: Vec<Finding>,
    /// All single candidates tried (for the report), supported or not.
    pub tried: Vec<Finding>,
    pub where_: Value,
    pub nominal_m_held: f64,
    pub nominal_gap_um: Option<(f64, f64)>,
    pub nominal_gap_c: Option<(f64, f64)>,
    pub notes: Vec<String>,
    pub seconds: f64,
    pub sims: usize,
    /// Effects the data cannot test, with the reason.
    pub untestable: Vec<(String, String)>,
    /// `diagnose fit`: per sensor, the shortest lag [s] the body-map test
    /// would see on it (`None`: none up to the grid's longest). Empty in
    /// machine-file mode and without a displacement.
    pub lag_reach: Vec<(String, Option<f64>)>,
    /// One line per missing input: what is missing and what that costs.
    pub missing: Vec<String>,
    /// The nominal model and its own held-out fit.
    pub nominal: Value,
    /// Evidence for "no effect": residual against noise, whiteness.
    pub no_effect: Value,
    /// How findings are ranked and when one is claimed.
    pub ranking_rule: String,
    /// Held-out RMS by channel and by phase, before and after the selected
    /// effect (for the report's plots).
    pub selected_gaps: Option<SelectedGaps>,
    /// The explanations of different classes the held-out data cannot
    /// separate, ranked (at most 3; empty when one is named): then
    /// `findings` is empty, nothing is named as the cause.
    pub ambiguous: Vec<String>,
    /// Per pair (the first of `ambiguous` and each other), the measurement
    /// that would separate them.
    pub separate_by: Vec<String>,
}

impl Diagnosis {
    pub fn to_json(&self) -> Value {
        json!({
            "effects": self.findings.iter().map(Finding::to_json).collect::<Vec<_>>(),
            "ambiguous": self.ambiguous,
            "separate_by": self.separate_by,
            "where": self.where_,
            "gap_before_um": self.nominal_gap_um.map(|g| g.0),
            "gap_before_c": self.nominal_gap_c.map(|g| g.0),
            "untestable": self.untestable.iter().map(|(n, r)| json!({"name": n, "reason": r})).collect::<Vec<_>>(),
            "sensor_lag_reach_s": self.lag_reach.iter().map(|(n, t)| (n.clone(), json!(t))).collect::<serde_json::Map<_, _>>(),
            "missing": self.missing,
            "nominal": self.nominal,
            "no_effect": self.no_effect,
            "ranking_rule": self.ranking_rule,
        })
    }
}

/// Held-out RMS before and after the selected effect.
#[derive(Clone, Debug, Default)]
pub struct SelectedGaps {
    pub effect: String,
    /// (channel, is displacement, before, after)
    pub channels: Vec<(String, bool, f64, f64)>,
    /// (phase, °C before, °C after)
    pub phases: Vec<(String, f64, f64)>,
}

//! Scoring shared by the benches: tallies of `diagnose fit` cases, how far
//! an effect moves its data, means and the `--verbose` case lines.

use anyhow::Result;
use serde_json::{json, Value};

use tcomp_thermal::diagnose::stats::r4;
use tcomp_thermal::diagnose::Options;

/// Tallies the two `diagnose fit` benches (open world, cross model) share:
/// top-1 per effect kind, false alarms on clean cases, time per case,
/// redraws, lag cases by reach.
#[derive(Default)]
pub(super) struct FitTally {
    /// kind → (cases, top-1 correct)
    pub(super) per: std::collections::BTreeMap<String, (usize, usize)>,
    pub(super) false_alarms: usize,
    pub(super) times: Vec<f64>,
    pub(super) redraws: usize,
    pub(super) lag_reach: LagReachTally,
}

impl FitTally {
    /// `diagnose fit` on one case's runs, timed.
    pub(super) fn diagnose(
        &mut self,
        runs: &[(String, tcomp_data::runcsv::Run)],
        opt: &Options,
        redrawn: usize,
    ) -> Result<tcomp_thermal::diagnose::Diagnosis> {
        self.redraws += redrawn;
        let t = std::time::Instant::now();
        let d = tcomp_thermal::diagnose::fitmode::diagnose_fit(runs, opt)?;
        self.times.push(t.elapsed().as_secs_f64());
        Ok(d)
    }

    /// Count one case: an effect case of `kind` (named right or not), or a
    /// clean case (a false alarm when anything is named).
    pub(super) fn score(
        &mut self,
        kind: Option<&str>,
        correct: bool,
        d: &tcomp_thermal::diagnose::Diagnosis,
    ) {
        match kind {
            Some(k) => {
                let e = self.per.entry(k.to_string()).or_default();
                e.0 += 1;
                e.1 += correct as usize;
            }
            None => self.false_alarms += (!d.findings.is_empty()) as usize,
        }
    }

    /// `fields` with the tallied figures added.
    pub(super) fn with_figures(&self, mut fields: Value) -> Value {
        let (n_eff, ok) = self
            .per
            .values()
            .fold((0usize, 0usize), |a, (n, k)| (a.0 + n, a.1 + k));
        if let Some(o) = fields.as_object_mut() {
            for (k, v) in [
                ("effect_cases", json!(n_eff)),
                ("top1_rate", json!(ok as f64 / n_eff.max(1) as f64)),
                (
                    "per_effect",
                    json!(self
                        .per
                        .iter()
                        .map(|(k, (n, ok))| (k.clone(), json!({"cases": n, "top1": ok})))
                        .collect::<serde_json::Map<_, _>>()),
                ),
                ("false_alarms", json!(self.false_alarms)),
                ("mean_diagnosis_seconds", json!(mean(&self.times))),
                (
                    "max_diagnosis_seconds",
                    json!(self.times.iter().copied().fold(0.0, f64::max)),
                ),
                ("redrawn_effects", json!(self.redraws)),
                ("lag_by_reach", self.lag_reach.json()),
            ] {
                o.insert(k.into(), v);
            }
        }
        fields
    }
}

/// Lag cases by outcome: named; missed but listed under `untestable` (the
/// lag test's reach, `Diagnosis::lag_reach`, does not cover the drawn lag
/// on that sensor: the honest "cannot tell"); missed and not listed.
#[derive(Default)]
pub(super) struct LagReachTally {
    cases: usize,
    named: usize,
    missed_listed: usize,
    missed_unlisted: usize,
}

impl LagReachTally {
    pub(super) fn add(
        &mut self,
        d: &tcomp_thermal::diagnose::Diagnosis,
        sensor: &str,
        tau_s: f64,
        named: bool,
    ) {
        self.cases += 1;
        // a sensor the diagnosis does not know is not listed
        let reach = d.lag_reach.iter().find(|(n, _)| n == sensor).map(|e| e.1);
        if named {
            self.named += 1;
        } else if reach.is_some_and(|r| r.is_none_or(|r| r > tau_s)) {
            self.missed_listed += 1;
        } else {
            self.missed_unlisted += 1;
        }
    }

    fn json(&self) -> Value {
        json!({
            "rule": "a missed lag is listed when diagnose fit names its sensor under untestable for the drawn tau (sensor_lag_reach_s above it, or none)",
            "cases": self.cases,
            "named": self.named,
            "missed_listed_untestable": self.missed_listed,
            "missed_not_listed": self.missed_unlisted,
        })
    }
}

/// How far an effect moves a case's data: the largest RMS difference
/// (over channels and runs) between the run with the effect and the same
/// run (same duty, same noise) without it, in °C and in µm.
#[derive(Default)]
pub struct Visibility {
    pub max_c: f64,
    pub max_um: f64,
}

/// Smallest RMS change an effect case must make on some sensor [°C]
/// (≈ 4 × the truth model's sensor noise: 0.02 °C plus 1/16 °C steps) or
/// on some probe [µm] (2.5 × its 0.2 µm noise).
pub const VISIBLE_C: f64 = 0.1;
pub const VISIBLE_UM: f64 = 0.5;

impl Visibility {
    pub(super) fn visible(&self) -> bool {
        self.max_c >= VISIBLE_C || self.max_um >= VISIBLE_UM
    }

    pub(super) fn add(&mut self, with: &tcomp_data::runcsv::Run, clean: &tcomp_data::runcsv::Run) {
        for name in &with.columns {
            let is_t = tcomp_data::runcsv::is_temperature_column(name) && name != "T_ambient";
            let is_d = tcomp_data::runcsv::is_error_column(name);
            if !is_t && !is_d {
                continue;
            }
            let (Some(a), Some(b)) = (with.col(name), clean.col(name)) else {
                continue;
            };
            let (s, n) = a
                .iter()
                .zip(b)
                .filter_map(|(x, y)| Some((x.as_ref()? - y.as_ref()?).powi(2)))
                .fold((0.0, 0usize), |acc, d| (acc.0 + d, acc.1 + 1));
            let rms = if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
            if is_t {
                self.max_c = self.max_c.max(rms);
            } else {
                self.max_um = self.max_um.max(rms);
            }
        }
    }
}

/// Per effect kind: median effect RMS (°C, µm) of the cases found and missed.
pub(super) fn visibility_json(
    v: &std::collections::BTreeMap<String, Vec<(f64, f64, bool)>>,
) -> Value {
    let median = |mut x: Vec<f64>| -> Option<Value> {
        if x.is_empty() {
            return None;
        }
        x.sort_by(|a, b| a.total_cmp(b));
        Some(r4(x[x.len() / 2]))
    };
    v.iter()
        .map(|(k, cases)| {
            let pick = |found: bool, um: bool| {
                median(
                    cases
                        .iter()
                        .filter(|c| c.2 == found)
                        .map(|c| if um { c.1 } else { c.0 })
                        .collect(),
                )
            };
            (
                k.clone(),
                json!({
                    "rule": "largest RMS difference over channels and runs between the case's run and the same run without the effect",
                    "found_median_rms_c": pick(true, false),
                    "found_median_rms_um": pick(true, true),
                    "missed_median_rms_c": pick(false, false),
                    "missed_median_rms_um": pick(false, true),
                }),
            )
        })
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// Mean of a list of figures (NaN for none).
pub(super) fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// `--verbose` lines of one open-world case: every effect tried, then the
/// verdict (both open benches print the same form).
pub(super) fn eprint_case(
    head: &str,
    truth: Option<&crate::truth::TruthEffect>,
    d: &tcomp_thermal::diagnose::Diagnosis,
    correct: bool,
    has_effect: bool,
    seconds: f64,
) {
    for f in &d.tried {
        eprintln!(
            "      tried {:18} m {:.2} -> {:.2} dbic {:.1} um {:?} c {:?} {} {}{}",
            f.name,
            f.m_before,
            f.m_after,
            f.dbic,
            f.gap_um.map(|g| (g.0 .0, g.1 .0)),
            f.gap_c.map(|g| (g.0 .0, g.1 .0)),
            f.params_json(),
            f.evidence
                .get("fit_rel_gain")
                .map_or(String::new(), |g| format!("fit gain {g}")),
            // the speed law must also beat the nominal (its m, as a gap)
            f.evidence
                .get("held_out_norm_gap_nominal")
                .map_or(String::new(), |g| format!("nominal gap {g}"))
        );
    }
    eprintln!(
        "{head} truth {:50} got {:40} {} ({seconds:.2} s)",
        truth.map_or("clean".into(), crate::truth::TruthEffect::describe),
        d.findings
            .iter()
            .map(|f| format!("{} {}", f.name, f.params_json()))
            .collect::<Vec<_>>()
            .join(", "),
        if correct {
            "ok"
        } else if has_effect {
            "MISS"
        } else {
            "FALSE ALARM"
        },
    );
}

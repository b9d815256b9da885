//! The periodic-driver column (`bench-diagnose --periodic-only`): cases of
//! the open-world truth model with a chiller sawtooth or on/off cycle on
//! the coolant, a shop HVAC cycle on the air, a single sensor step (a step
//! must stay a step) and clean runs, each diagnosed in both modes
//! (`diagnose fit` and `tcomp diagnose` with the truth's machine file).
//! Drawn from their own random stream: the other columns' cases do not move.

use anyhow::Result;
use serde_json::{json, Value};

use tcomp_numerics::rng::Rng;
use tcomp_thermal::diagnose::stats::r4;
use tcomp_thermal::diagnose::{diagnose, fitmode::diagnose_fit, Diagnosis, Options};
use tcomp_thermal::sim::Machine;

use super::draw::BenchConfig;
use super::open::{draw_case, OpenCase};
use super::tally::mean;
use crate::truth::{TruthEffect, PERIODIC_EFFECTS};

/// Case kinds of the column besides the clean ones.
const KINDS: [&str; 4] = [
    PERIODIC_EFFECTS[0],
    PERIODIC_EFFECTS[1],
    PERIODIC_EFFECTS[2],
    "sensor_offset",
];

/// `cases` cases: a quarter clean (at least one), the rest cycling over
/// `KINDS`; two runs of half the hours each (light and heavy duty).
pub fn periodic_cases(cfg: &BenchConfig) -> Vec<OpenCase> {
    let mut g = Rng::paired(cfg.seed ^ 0x9e71_0d1c);
    let n = cfg.cases.max(5);
    let n_clean = (n / 4).max(1);
    let mut plan: Vec<Option<&'static str>> = (0..n - n_clean)
        .map(|i| Some(KINDS[i % KINDS.len()]))
        .collect();
    plan.extend(std::iter::repeat_n(None, n_clean));
    let mut cases = Vec::new();
    for (ci, kind) in plan.into_iter().enumerate() {
        cases.push(draw_case(&mut g, kind, ci, cfg, 9000, "periodic"));
    }
    cases
}

/// The truth's period and amplitude (None: not periodic).
fn truth_period(e: &TruthEffect) -> Option<(f64, f64)> {
    match e {
        TruthEffect::ChillerWave {
            period_s, amp_c, ..
        }
        | TruthEffect::HvacCycle {
            period_s, amp_c, ..
        } => Some((*period_s, *amp_c)),
        _ => None,
    }
}

/// Tally of one mode.
#[derive(Default)]
struct Tally {
    /// kind → (cases, named, wrong, period within 10 %)
    per: std::collections::BTreeMap<String, (usize, usize, usize, usize)>,
    clean: usize,
    false_alarms: usize,
    periodic_false_alarms: usize,
    times: Vec<f64>,
    period_err: Vec<f64>,
    misses: Vec<Value>,
}

impl Tally {
    fn add(&mut self, ci: usize, case: &OpenCase, d: &Diagnosis, secs: f64) {
        self.times.push(secs);
        let top = d.findings.first();
        let Some(kind) = case.kind else {
            self.clean += 1;
            self.false_alarms += top.is_some() as usize;
            self.periodic_false_alarms += d.findings.iter().any(|f| f.name == "periodic") as usize;
            if top.is_some() {
                self.misses.push(miss(ci, case, d));
            }
            return;
        };
        let truth = &case.effects[0];
        let (named, period_ok) = match (truth, top) {
            (_, None) => (false, false),
            (TruthEffect::SensorStep { sensor, .. }, Some(f)) => (
                f.name == "sensor_offset"
                    && f.params_json()["sensor"] == format!("T_T{sensor}").as_str(),
                false,
            ),
            (t, Some(f)) => {
                let (per, _) = truth_period(t).unwrap_or((f64::NAN, 0.0));
                let got = f.params_json()["period_s"].as_f64();
                if let Some(p) = got {
                    self.period_err.push((p / per - 1.0).abs());
                }
                (
                    matches!(f.name.as_str(), "periodic" | "coolant" | "chiller"),
                    got.is_some_and(|p| (p / per - 1.0).abs() <= 0.1),
                )
            }
        };
        let e = self.per.entry(kind.to_string()).or_default();
        e.0 += 1;
        e.1 += named as usize;
        e.2 += (top.is_some() && !named) as usize;
        e.3 += period_ok as usize;
        if !named {
            self.misses.push(miss(ci, case, d));
        }
    }

    fn json(&self) -> Value {
        let (n, named, wrong) = self
            .per
            .iter()
            .filter(|(k, _)| k.as_str() != "sensor_offset")
            .fold((0, 0, 0), |a, (_, v)| (a.0 + v.0, a.1 + v.1, a.2 + v.2));
        json!({
            "periodic_cases": n,
            "periodic_named": named,
            "periodic_wrong": wrong,
            "periodic_honest": 0,
            "per_kind": self.per.iter().map(|(k, v)| (k.clone(), json!({"cases": v.0, "named": v.1, "wrong": v.2, "period_within_10pct": v.3}))).collect::<serde_json::Map<_, _>>(),
            "median_period_error": median(&self.period_err).map(r4),
            "clean_cases": self.clean,
            "false_alarms": self.false_alarms,
            "periodic_false_alarms": self.periodic_false_alarms,
            "mean_seconds_per_case": r4(mean(&self.times)),
            "max_seconds_per_case": r4(self.times.iter().copied().fold(0.0, f64::max)),
            "misses": self.misses,
        })
    }
}

fn median(v: &[f64]) -> Option<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied()
}

fn miss(ci: usize, case: &OpenCase, d: &Diagnosis) -> Value {
    json!({
        "case": ci,
        "truth": case.effects.iter().map(TruthEffect::describe).collect::<Vec<_>>(),
        "got": d.findings.iter().map(|f| json!({"name": f.name, "params": f.params_json()})).collect::<Vec<_>>(),
    })
}

/// Both modes on the periodic cases: named / wrong per kind, period within
/// 10 %, false alarms on the clean cases, seconds per case.
pub fn run_periodic_bench(m: &Machine, cfg: &BenchConfig) -> Result<Value> {
    let opt = Options {
        threads: cfg.threads,
        calibrate: cfg.calibrate,
        ..Options::default()
    };
    let cases = periodic_cases(cfg);
    let (mut fit, mut mach) = (Tally::default(), Tally::default());
    for (ci, case) in cases.iter().enumerate() {
        let t = std::time::Instant::now();
        let d = diagnose_fit(&case.runs, &opt)?;
        fit.add(ci, case, &d, t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        let e = diagnose(m, &case.runs, &opt)?;
        mach.add(ci, case, &e, t.elapsed().as_secs_f64());
        if cfg.verbose {
            let names = |d: &Diagnosis| {
                let scan = d.tried.iter().find(|f| f.name == "periodic").map(|f| {
                    format!(
                        "[scan: {} s on {}, p×tests {:.1e}, amp/noise {}, m {:.2}→{:.2}]",
                        f.evidence["period_s"],
                        f.evidence["channel"],
                        f.evidence["p_value_corrected"].as_f64().unwrap_or(f64::NAN),
                        f.evidence["amplitude_over_noise"],
                        f.m_before,
                        f.m_after
                    )
                });
                d.findings
                    .iter()
                    .map(|f| format!("{} {}", f.name, f.params_json()["period_s"]))
                    .chain(scan)
                    .collect::<Vec<_>>()
                    .join(" | ")
            };
            eprintln!(
                "periodic {ci:3} truth {:?}\n    fit:     {}\n    machine: {}",
                case.effects.first(),
                names(&d),
                names(&e)
            );
        }
    }
    Ok(json!({
        "mode": "open-world truth model (desktop/bench/src/truth.rs), two runs per case (light and heavy duty), periodic kinds chiller_sawtooth / chiller_onoff (the coolant tank, 10–60 min) and hvac (the air at the machine, 30 min – 2 h, unseen by T_ambient), sensor steps as a control, clean cases",
        "named_rule": "periodic cases: named when the top finding is periodic (or coolant / chiller); sensor steps: when it is sensor_offset on the right sensor; wrong: something else named",
        "cases": cases.len(),
        "hours_per_case": cfg.hours,
        "sample_period_s": cfg.sample_period_s,
        "diagnose_fit": fit.json(),
        "machine_file": mach.json(),
    }))
}

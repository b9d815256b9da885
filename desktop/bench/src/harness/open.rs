//! The open-world columns: cases of the separate truth model (`truth.rs`),
//! diagnosed by `diagnose fit` (no machine file) and by `tcomp diagnose`
//! with a machine file.

use anyhow::Result;
use serde_json::{json, Value};

use tcomp_numerics::rng::Rng;
use tcomp_thermal::diagnose::stats::r4;
use tcomp_thermal::diagnose::{diagnose, Options};
use tcomp_thermal::sim::Machine;

use super::draw::BenchConfig;
use super::tally::{
    eprint_case, mean, visibility_json, FitTally, Visibility, VISIBLE_C, VISIBLE_UM,
};

/// Open-world blind check of `diagnose fit` (no machine file) on runs of
/// the separate truth model (`truth.rs`): each testable effect kind at
/// random strengths, plus clean cases, one 8 h run (or `hours`) per case.
pub fn run_open_bench(cfg: &BenchConfig) -> Result<Value> {
    use crate::truth::TruthEffect;
    let cases = open_cases(cfg);
    let n_clean = cases.iter().filter(|c| c.kind.is_none()).count();
    let opt = Options {
        threads: cfg.threads,
        ..Options::default()
    };
    let mut tally = FitTally::default();
    let (mut shrink_c, mut shrink_um) = (Vec::new(), Vec::new());
    let mut misses = Vec::new();
    let mut visibility: std::collections::BTreeMap<String, Vec<(f64, f64, bool)>> =
        Default::default();
    let n_cases = cases.len();
    for (ci, case) in cases.into_iter().enumerate() {
        let OpenCase {
            kind,
            effects,
            runs,
            visibility: vis,
            redrawn,
        } = case;
        let d = tally.diagnose(&runs, &opt, redrawn)?;
        let got = d.findings.first().map(|f| f.name.clone());
        // sensor effects must also name the right sensor
        let sensor_ok = match effects.first() {
            Some(TruthEffect::SensorStep { sensor, .. })
            | Some(TruthEffect::SensorLag { sensor, .. }) => d
                .findings
                .first()
                .is_some_and(|f| f.params_json()["sensor"] == format!("T_T{sensor}").as_str()),
            _ => true,
        };
        let correct = match kind {
            Some(_) => {
                got.as_deref() == effects.first().map(TruthEffect::diagnosis_name) && sensor_ok
            }
            None => got.is_none(),
        };
        if let Some(TruthEffect::SensorLag { sensor, tau_s }) = effects.first() {
            tally
                .lag_reach
                .add(&d, &format!("T_T{sensor}"), *tau_s, correct);
        }
        tally.score(kind, correct, &d);
        if let Some(k) = kind {
            visibility
                .entry(k.to_string())
                .or_default()
                .push((vis.max_c, vis.max_um, correct));
            if let Some(f) = d.findings.first() {
                if let Some(((b, _), (a, _))) = f.gap_c {
                    if b > 0.0 {
                        shrink_c.push(1.0 - a / b);
                    }
                }
                if let Some(((b, _), (a, _))) = f.gap_um {
                    if b > 0.0 {
                        shrink_um.push(1.0 - a / b);
                    }
                }
            } else {
                shrink_c.push(0.0);
                shrink_um.push(0.0);
            }
        }
        if !correct {
            misses.push(json!({
                "case": ci,
                "effect_rms_c": r4(vis.max_c),
                "effect_rms_um": r4(vis.max_um),
                "truth": effects.iter().map(TruthEffect::describe).collect::<Vec<_>>(),
                "got": d.findings.iter().map(|f| json!({"name": f.name, "params": f.params_json()})).collect::<Vec<_>>(),
            }));
        }
        if cfg.verbose {
            eprint_case(
                &format!(
                    "open {ci:3} effect rms {:.3} °C {:.3} µm",
                    vis.max_c, vis.max_um
                ),
                effects.first(),
                &d,
                correct,
                kind.is_some(),
                tally.times.last().copied().unwrap_or(0.0),
            );
        }
    }
    // the kinds a nominal identified from the data cannot absorb (the
    // issue's target set): step, lag, periodic chiller, speed law
    let (n_t, ok_t) = [
        "sensor_offset",
        "sensor_lag",
        "coolant",
        "bearing_nonlinear",
    ]
    .iter()
    .filter_map(|k| tally.per.get(*k))
    .fold((0usize, 0usize), |a, (n, k)| (a.0 + n, a.1 + k));
    let testable = ok_t as f64 / n_t.max(1) as f64;
    Ok(tally.with_figures(json!({
        "mode": "diagnose fit (no machine file), truth model diagnose/truth.rs, two runs per case (light and heavy duty)",
        "cases": n_cases,
        "clean_cases": n_clean,
        "top1_rate_fit_testable": testable,
        "mean_heldout_gap_shrink_c": mean(&shrink_c),
        "mean_heldout_gap_shrink_um": mean(&shrink_um),
        "hours_per_case": cfg.hours,
        "sample_period_s": cfg.sample_period_s,
        "misses": misses,
        "effect_visibility": visibility_json(&visibility),
        "visibility_rule": format!("an effect case is drawn again (at most 20 times) until its data differ from the same runs without it by ≥ {VISIBLE_C} °C RMS on a sensor or ≥ {VISIBLE_UM} µm RMS on a probe"),
    })))
}

/// One open-world case: the truth effect kind (None = clean), the effects
/// and the two runs (light and heavy duty), as `run_open_bench` draws them.
pub struct OpenCase {
    pub kind: Option<&'static str>,
    pub effects: Vec<crate::truth::TruthEffect>,
    pub runs: Vec<(String, tcomp_data::runcsv::Run)>,
    /// How far the effect moves the data (against the same runs without it).
    pub visibility: Visibility,
    /// Draws rejected as invisible before this one.
    pub redrawn: usize,
}

/// The open-world cases both open benches diagnose (same seed, same cases).
pub fn open_cases(cfg: &BenchConfig) -> Vec<OpenCase> {
    use crate::truth::TRUTH_EFFECTS;
    let mut g = Rng::paired(cfg.seed ^ 0x5eed);
    let n = cfg.cases.max(6);
    let n_clean = (n / 6).max(1);
    let mut plan: Vec<Option<&'static str>> = (0..n - n_clean)
        .map(|i| Some(TRUTH_EFFECTS[i % TRUTH_EFFECTS.len()]))
        .collect();
    plan.extend(std::iter::repeat_n(None, n_clean));
    let mut cases = Vec::with_capacity(plan.len());
    for (ci, kind) in plan.into_iter().enumerate() {
        cases.push(draw_case(&mut g, kind, ci, cfg, 5000, "open"));
    }
    cases
}

/// One case of `kind` (None: clean): two runs of half the case's hours, a
/// light and a heavy duty, named `<prefix><ci>-<run>`, noise seeded from
/// `seed_base`. An effect case must move its data by a visible amount
/// somewhere (see `VISIBLE_C`): drawn again when it does not (a lag on a
/// sensor whose body changes slowly reads like the body itself), 20 times
/// at most.
pub(super) fn draw_case(
    g: &mut Rng,
    kind: Option<&'static str>,
    ci: usize,
    cfg: &BenchConfig,
    seed_base: u64,
    prefix: &str,
) -> OpenCase {
    use crate::truth::{random_duty, simulate, TruthEffect};
    let half = cfg.hours / 2.0;
    let mut redrawn = 0usize;
    loop {
        let effects: Vec<TruthEffect> = kind
            .iter()
            .map(|k| TruthEffect::random(k, g, half))
            .collect();
        let mut visibility = Visibility::default();
        let runs: Vec<(String, tcomp_data::runcsv::Run)> = [(0.15, 0.55), (0.5, 1.0)]
            .iter()
            .enumerate()
            .map(|(ri, &(lo, hi))| {
                let duty = random_duty(g, half, lo, hi);
                let seed = seed_base + 2 * ci as u64 + ri as u64;
                // a sensor fault happens once: in the second run only
                let eff: Vec<TruthEffect> = effects
                    .iter()
                    .filter(|e| ri == 1 || !matches!(e, TruthEffect::SensorStep { .. }))
                    .cloned()
                    .collect();
                let run = simulate(&duty, &eff, half, cfg.sample_period_s, seed).run;
                if !eff.is_empty() {
                    // the same run without the effect (same duty, same noise)
                    let clean = simulate(&duty, &[], half, cfg.sample_period_s, seed).run;
                    visibility.add(&run, &clean);
                }
                (format!("{prefix}{ci}-{ri}"), run)
            })
            .collect();
        if effects.is_empty() || visibility.visible() || redrawn >= 20 {
            return OpenCase {
                kind,
                effects,
                runs,
                visibility,
                redrawn,
            };
        }
        redrawn += 1;
    }
}

/// Whether a diagnosis' selected effect names the truth effect (and, for
/// sensor effects, its sensor): the machine-file mode's rule.
pub fn names_truth(
    d: &tcomp_thermal::diagnose::Diagnosis,
    truth: Option<&crate::truth::TruthEffect>,
) -> bool {
    use crate::truth::TruthEffect;
    let top = d.findings.first();
    let Some(t) = truth else {
        return top.is_none();
    };
    let Some(f) = top else {
        return false;
    };
    let sensor_is = |i: usize| f.params_json()["sensor"] == format!("T_T{i}").as_str();
    match t {
        TruthEffect::SensorStep { sensor, .. } => f.name == "sensor_offset" && sensor_is(*sensor),
        TruthEffect::SensorLag { sensor, .. } => f.name == "sensor_lag" && sensor_is(*sensor),
        TruthEffect::ChillerCycling { .. } => f.name == "chiller" || f.name == "coolant",
        other => f.name == other.diagnosis_name(),
    }
}

/// Open-world blind check of `tcomp diagnose` WITH an effect-free machine
/// file written from the truth machine's design
/// (`examples/machines/vertical-mc-truth.toml`): the same cases as
/// `run_open_bench` (two runs per case, no `coolant_on` column).
pub fn run_open_machine_bench(m: &Machine, cfg: &BenchConfig) -> Result<Value> {
    use crate::truth::TruthEffect;
    let opt = Options {
        threads: cfg.threads,
        calibrate: cfg.calibrate,
        ..Options::default()
    };
    let cases = open_cases(cfg);
    let mut per: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    let (mut ok, mut n_eff, mut false_alarms, mut n_clean) = (0usize, 0usize, 0usize, 0usize);
    let (mut shrink_c, mut shrink_um, mut times) = (Vec::new(), Vec::new(), Vec::new());
    let mut misses = Vec::new();
    for (ci, case) in cases.iter().enumerate() {
        let t = std::time::Instant::now();
        let d = diagnose(m, &case.runs, &opt)?;
        times.push(t.elapsed().as_secs_f64());
        let truth = case.effects.first();
        let correct = names_truth(&d, truth);
        match case.kind {
            Some(k) => {
                n_eff += 1;
                ok += correct as usize;
                let e = per.entry(k.to_string()).or_default();
                e.0 += 1;
                e.1 += correct as usize;
                let top = d.findings.first();
                // held-out shrink in each unit (0 when nothing is named)
                if let Some((b, _)) = d.nominal_gap_c {
                    let a = top.and_then(|f| f.gap_c).map_or(b, |g| g.1 .0);
                    if b > 0.0 {
                        shrink_c.push(1.0 - a / b);
                    }
                }
                if let Some((b, _)) = d.nominal_gap_um {
                    let a = top.and_then(|f| f.gap_um).map_or(b, |g| g.1 .0);
                    if b > 0.0 {
                        shrink_um.push(1.0 - a / b);
                    }
                }
            }
            None => {
                n_clean += 1;
                false_alarms += (!d.findings.is_empty()) as usize;
            }
        }
        if !correct {
            misses.push(json!({
                "case": ci,
                "truth": case.effects.iter().map(TruthEffect::describe).collect::<Vec<_>>(),
                "got": d.findings.iter().map(|f| json!({"name": f.name, "params": f.params_json()})).collect::<Vec<_>>(),
            }));
        }
        if cfg.verbose {
            eprint_case(
                &format!("machine {ci:3}"),
                truth,
                &d,
                correct,
                case.kind.is_some(),
                times.last().copied().unwrap_or(0.0),
            );
        }
    }
    Ok(json!({
        "mode": format!("tcomp diagnose {} (effect-free, from the design{}), truth model diagnose/truth.rs, two runs per case, no coolant_on; held out: the last 40 % of every hour of every run", m.spec.name, if cfg.calibrate { ", calibrated on the fit rows first" } else { ", taken as exact" }),
        "calibrate": cfg.calibrate,
        "cases": cases.len(),
        "effect_cases": n_eff,
        "clean_cases": n_clean,
        "top1_rate": ok as f64 / n_eff.max(1) as f64,
        "per_effect": per.iter().map(|(k, (n, ok))| (k.clone(), json!({"cases": n, "top1": ok}))).collect::<serde_json::Map<_, _>>(),
        "mean_heldout_gap_shrink_c": mean(&shrink_c),
        "mean_heldout_gap_shrink_um": mean(&shrink_um),
        "false_alarms": false_alarms,
        "mean_diagnosis_seconds": mean(&times),
        "max_diagnosis_seconds": times.iter().copied().fold(0.0, f64::max),
        "hours_per_case": cfg.hours,
        "sample_period_s": cfg.sample_period_s,
        "misses": misses,
    }))
}

//! The closed-world column: `tcomp diagnose` with the simulator's own
//! machine file on cases of the first simulator.

use anyhow::Result;
use serde_json::{json, Value};

use tcomp_numerics::rng::Rng;
use tcomp_thermal::diagnose::{diagnose, Options};
use tcomp_thermal::sim::{sim_run, Effect, Machine, SimOptions, EFFECT_NAMES};

use super::draw::{random_duty, random_effect, BenchConfig};
use super::score::{effects_of, finding_physics, findings_of, KIND_RULES};
use super::tally::mean;

/// A single-effect case whose diagnosis names no effect and whose first
/// parameter finding (a design value that had to leave its tolerance)
/// names the effect's physics (`score::KIND_RULES`, the rule of the
/// open and cross worlds and of issue 52: "a parameter finding counts
/// only where it names the effect's physics"): a steep bearing heat read
/// as the bearing's viscous term f0 beyond its tolerance.
fn names_physics(d: &Value, kind: &str) -> bool {
    let Some(r) = KIND_RULES.iter().find(|r| r.kind == kind) else {
        return false;
    };
    effects_of(d).is_empty()
        && findings_of(d)
            .first()
            .and_then(finding_physics)
            .is_some_and(|p| r.physics.contains(&p))
}

/// Run the blind check; returns the summary JSON.
pub fn run_bench(machines: &[Machine], cfg: &BenchConfig) -> Result<Value> {
    let mut g = Rng::paired(cfg.seed);
    let n = cfg.cases.max(3);
    let n_clean = (n / 6).max(1);
    let n_pair = (n / 6).max(1);
    let n_single = n - n_clean - n_pair;
    let mut plan: Vec<Vec<&str>> = Vec::new();
    for i in 0..n_single {
        plan.push(vec![EFFECT_NAMES[i % EFFECT_NAMES.len()]]);
    }
    for _ in 0..n_pair {
        let a = (g.uniform() * 8.0) as usize % 8;
        let mut b = (g.uniform() * 8.0) as usize % 8;
        if b == a {
            b = (a + 1 + (g.uniform() * 7.0) as usize % 7) % 8;
        }
        plan.push(vec![EFFECT_NAMES[a], EFFECT_NAMES[b]]);
    }
    for _ in 0..n_clean {
        plan.push(vec![]);
    }
    let opt = Options {
        threads: cfg.threads,
        ..Options::default()
    };
    let (mut ok_single, mut ok_pair, mut n_s, mut n_p) = (0, 0, 0, 0);
    let (mut false_alarms, mut physics_single) = (0, 0);
    let (mut shrinks, mut shrinks_um) = (Vec::new(), Vec::new());
    let mut per: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    let mut misses = Vec::new();
    let t_all = std::time::Instant::now();
    let mut diag_times = Vec::new();
    for (ci, kinds) in plan.iter().enumerate() {
        let m = &machines[ci % machines.len()];
        let duty = random_duty(&mut g, m.spec.n_max_rpm, cfg.hours);
        let effects: Vec<Effect> = kinds.iter().map(|k| random_effect(&mut g, m, k)).collect();
        let seed = 1000 + ci as u64;
        let run = sim_run(
            m,
            &duty,
            &SimOptions {
                effects: effects.clone(),
                seed,
                hours: Some(cfg.hours),
                sample_period_s: Some(cfg.sample_period_s),
                noise: true,
            },
        )?;
        let d = diagnose(m, &[(format!("case{ci}"), run)], &opt)?;
        diag_times.push(d.seconds);
        let top = d.findings.first();
        let mut truth: Vec<&str> = kinds.clone();
        truth.sort();
        let got: Vec<String> = top
            .map(|f| {
                let mut v: Vec<String> = f.name.split('+').map(String::from).collect();
                v.sort();
                v
            })
            .unwrap_or_default();
        let correct = got.iter().map(String::as_str).eq(truth.iter().copied());
        let label = if kinds.is_empty() {
            "clean".to_string()
        } else {
            kinds.join("+")
        };
        match kinds.len() {
            0 => {
                if !d.findings.is_empty() {
                    false_alarms += 1;
                }
            }
            1 => {
                n_s += 1;
                ok_single += correct as usize;
                physics_single += (!correct && names_physics(&d.to_json(), kinds[0])) as usize;
                let e = per.entry(kinds[0].to_string()).or_default();
                e.0 += 1;
                e.1 += correct as usize;
            }
            _ => {
                n_p += 1;
                ok_pair += correct as usize;
            }
        }
        if !kinds.is_empty() {
            let s = top.map_or(0.0, |f| 1.0 - (f.m_after / f.m_before).sqrt());
            shrinks.push(s);
            if let (Some(f), Some((b, _))) = (top, d.nominal_gap_um) {
                if let Some((_, (a, _))) = f.gap_um {
                    if b > 1.0 {
                        shrinks_um.push(1.0 - a / b);
                    }
                }
            }
        }
        if !correct && !kinds.is_empty() || kinds.is_empty() && !d.findings.is_empty() {
            misses.push(json!({
                "case": ci, "machine": m.spec.name, "truth": effects.iter().map(|e| e.to_spec()).collect::<Vec<_>>(),
                "got": d.findings.iter().map(|f| f.name.clone()).collect::<Vec<_>>(),
            }));
        }
        if cfg.verbose {
            eprintln!(
                "case {ci:3} {:18} truth {:36} got {:36} {} ({:.2} s)",
                m.spec.name,
                label,
                d.findings
                    .iter()
                    .map(|f| f.name.as_str())
                    .collect::<Vec<_>>()
                    .join(","),
                if kinds.is_empty() {
                    if d.findings.is_empty() {
                        "ok"
                    } else {
                        "FALSE ALARM"
                    }
                } else if correct {
                    "ok"
                } else {
                    "MISS"
                },
                d.seconds
            );
        }
    }
    let identified = ok_single + ok_pair;
    Ok(json!({
        "cases": plan.len(),
        "effect_cases": n_s + n_p,
        "single_cases": n_s,
        "pair_cases": n_p,
        "clean_cases": n_clean,
        "top1_rate": identified as f64 / (n_s + n_p).max(1) as f64,
        "top1_single_rate": ok_single as f64 / n_s.max(1) as f64,
        "top1_pair_rate": ok_pair as f64 / n_p.max(1) as f64,
        "single_named_as_physics": physics_single,
        "top1_or_physics_rate": (identified + physics_single) as f64 / (n_s + n_p).max(1) as f64,
        "mean_heldout_gap_shrink": mean(&shrinks),
        "mean_heldout_gap_shrink_um": mean(&shrinks_um),
        "false_alarms": false_alarms,
        "per_effect": per.iter().map(|(k, (n, ok))| (k.clone(), json!({"cases": n, "top1": ok}))).collect::<serde_json::Map<_, _>>(),
        "misses": misses,
        "hours_per_case": cfg.hours,
        "sample_period_s": cfg.sample_period_s,
        "mean_diagnosis_seconds": mean(&diag_times),
        "total_seconds": t_all.elapsed().as_secs_f64(),
    }))
}

//! Issue 27's side-by-side columns: the same cases diagnosed with the exact
//! design file, with a design file drawn off by σ = 15 % per case (default
//! flags), and without a file (`diagnose fit`), on the open-world truth
//! model and on the cross model (the first simulator's machines), scored
//! named / honest / wrong / silent (`score.rs`), on a development seed or
//! on the held-out seeds.

use anyhow::{bail, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;

use tcomp_thermal::diagnose::{diagnose, fitmode::diagnose_fit, Diagnosis, Options};
use tcomp_thermal::sim::Machine;

use super::cpu;
use super::cross::cross_cases;
use super::draw::BenchConfig;
use super::file_truth::{is_parameter_finding, judge_finding, FileVerdict};
use super::open::open_cases;
use super::perturb::{design_seed, perturb_machine};
use super::score::{
    ambiguous_of, count_findings, effects_of, score_clean, score_effect, truth_of_open,
    truth_of_sim, DrawnFile, Outcome, Truth,
};
use super::tally::mean;

/// Seeds never tuned on: report them apart (`bench-diagnose --columns …
/// --heldout`) and never use them while changing the diagnosis.
pub const HELDOUT_SEEDS: [u64; 3] = [101, 103, 107];

/// One column: which machine file the diagnosis is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Column {
    /// The design file with its exact numbers.
    Exact,
    /// The design file with every number off by a lognormal factor.
    Design,
    /// No file: `diagnose fit`.
    Fit,
}

impl Column {
    pub fn key(self) -> &'static str {
        match self {
            Column::Exact => "exact_file",
            Column::Design => "design_error_file",
            Column::Fit => "fit",
        }
    }

    /// `exact`, `design` or `fit`.
    pub fn parse(s: &str) -> Result<Column> {
        Ok(match s {
            "exact" => Column::Exact,
            "design" => Column::Design,
            "fit" => Column::Fit,
            o => bail!("unknown column `{o}` (exact, design, fit)"),
        })
    }
}

/// Which cases: the truth model's (open), the first simulator's (cross),
/// or the blind third world's (`worlds/third/`, run by its own generator
/// and scorer: `third.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum World {
    Open,
    Cross,
    Third,
}

impl World {
    pub fn key(self) -> &'static str {
        match self {
            World::Open => "open_world",
            World::Cross => "cross_model",
            World::Third => "third_world",
        }
    }

    /// `open`, `cross` or `third`.
    pub fn parse(s: &str) -> Result<World> {
        Ok(match s {
            "open" => World::Open,
            "cross" => World::Cross,
            "third" => World::Third,
            o => bail!("unknown world `{o}` (open, cross, third, or all)"),
        })
    }

    fn tag(self) -> u64 {
        match self {
            World::Open => 0,
            World::Cross => 1,
            World::Third => 2,
        }
    }
}

/// What to run besides the `BenchConfig`.
pub struct ApproxConfig {
    pub columns: Vec<Column>,
    pub worlds: Vec<World>,
    /// σ of the log design factor.
    pub sigma: f64,
    pub seeds: Vec<u64>,
    /// Cases before this index are drawn but not diagnosed (to look at
    /// one case without running those before it).
    pub first_case: usize,
}

/// One world × column: outcome counts, clean cases, times.
#[derive(Default)]
struct Tally {
    /// kind → [named, honest, wrong, silent]
    per: BTreeMap<String, [usize; 4]>,
    /// Effect cases answered "ambiguous": the true effect among them
    /// (counted honest above), not (counted wrong).
    ambiguous: [usize; 2],
    clean: usize,
    /// Clean cases with an effect named or a finding not true of the file.
    false_alarms: usize,
    /// Clean cases with an effect named.
    clean_effects: usize,
    /// Clean cases with a finding not true of the file.
    clean_false_findings: usize,
    /// Parameter findings on clean cases: true of the drawn file, not.
    clean_true_findings: usize,
    clean_findings_not_true: usize,
    /// Parameter findings on effect cases: naming the effect's physics,
    /// true of the file, neither.
    effect_findings: [usize; 3],
    times: Vec<f64>,
    /// CPU seconds (user + system, every thread) per case.
    cpu: Vec<f64>,
    misses: Vec<Value>,
}

impl Tally {
    fn add_effect(&mut self, kind: &str, o: Outcome) {
        let i = match o {
            Outcome::Named => 0,
            Outcome::Honest => 1,
            Outcome::Wrong => 2,
            Outcome::Silent => 3,
        };
        self.per.entry(kind.to_string()).or_default()[i] += 1;
    }

    fn json(&self) -> Value {
        let mut tot = [0usize; 4];
        for v in self.per.values() {
            for i in 0..4 {
                tot[i] += v[i];
            }
        }
        let n: usize = tot.iter().sum();
        let rate = |k: usize| k as f64 / n.max(1) as f64;
        json!({
            "effect_cases": n,
            "named": tot[0],
            "honest": tot[1],
            "wrong": tot[2],
            "silent": tot[3],
            "named_rate": rate(tot[0]),
            "named_or_honest_rate": rate(tot[0] + tot[1]),
            "wrong_rate": rate(tot[2]),
            "ambiguous": self.ambiguous[0] + self.ambiguous[1],
            "ambiguous_with_truth": self.ambiguous[0],
            "ambiguous_without_truth": self.ambiguous[1],
            "clean_cases": self.clean,
            "false_alarms": self.false_alarms,
            "clean_with_effect_named": self.clean_effects,
            "clean_with_false_findings": self.clean_false_findings,
            "clean_true_file_findings": self.clean_true_findings,
            "clean_false_findings": self.clean_findings_not_true,
            "effect_case_findings": {
                "naming_the_effect": self.effect_findings[0],
                "true_of_file": self.effect_findings[1],
                "neither": self.effect_findings[2],
            },
            "mean_seconds_per_case": mean(&self.times),
            "max_seconds_per_case": self.times.iter().copied().fold(0.0, f64::max),
            "mean_cpu_seconds_per_case": mean(&self.cpu),
            "max_cpu_seconds_per_case": self.cpu.iter().copied().fold(0.0, f64::max),
            "cpu_seconds_total": self.cpu.iter().sum::<f64>(),
            "per_effect": self.per.iter().map(|(k, v)| (k.clone(), json!({"cases": v.iter().sum::<usize>(), "named": v[0], "honest": v[1], "wrong": v[2], "silent": v[3]}))).collect::<serde_json::Map<_, _>>(),
            "misses": self.misses,
        })
    }
}

/// A case of either world, as the columns need it.
struct Case<'a> {
    kind: Option<&'static str>,
    truth: Option<Truth>,
    describe: String,
    runs: Vec<(String, tcomp_data::runcsv::Run)>,
    exact: &'a Machine,
}

fn world_cases<'a>(
    w: World,
    truth_machine: &'a Machine,
    machines: &'a [Machine],
    cfg: &BenchConfig,
) -> Result<Vec<Case<'a>>> {
    Ok(match w {
        World::Open => open_cases(cfg)
            .into_iter()
            .map(|c| Case {
                kind: c.kind,
                truth: c.effects.first().map(truth_of_open),
                describe: c.effects.first().map_or("clean".into(), |e| e.describe()),
                runs: c.runs,
                exact: truth_machine,
            })
            .collect(),
        World::Cross => cross_cases(machines, cfg)?
            .into_iter()
            .map(|c| Case {
                kind: c.kind,
                truth: c.effects.first().map(truth_of_sim),
                describe: c
                    .effects
                    .first()
                    .map_or("clean".into(), |e| format!("{e:?}")),
                runs: c.runs,
                exact: &machines[c.machine],
            })
            .collect(),
        World::Third => bail!(
            "the third world runs through its own generator and scorer (third.rs), not these cases"
        ),
    })
}

/// What one column's diagnosis of a case gave: the diagnosis, wall and CPU
/// seconds, and the factors drawn on the design file (design column).
struct ColumnRun {
    d: Diagnosis,
    secs: f64,
    cpu: f64,
    factors: Option<Vec<(String, f64)>>,
}

/// The diagnosis of one case in one column (default flags), timed.
fn diagnose_column(
    col: Column,
    case: &Case,
    opt: &Options,
    sigma: f64,
    dseed: u64,
) -> Result<ColumnRun> {
    let c0 = cpu::own_s();
    let t = std::time::Instant::now();
    let (d, factors) = match col {
        Column::Exact => (diagnose(case.exact, &case.runs, opt)?, None),
        Column::Design => {
            let (m, f) = perturb_machine(case.exact, sigma, dseed)?;
            (diagnose(&m, &case.runs, opt)?, Some(f))
        }
        Column::Fit => (diagnose_fit(&case.runs, opt)?, None),
    };
    Ok(ColumnRun {
        d,
        secs: t.elapsed().as_secs_f64(),
        cpu: cpu::own_s() - c0,
        factors,
    })
}

/// Run every selected world and column on one seed's cases, into `tallies`
/// (keyed world, column); one line per case and column on stderr.
fn run_seed(
    truth_machine: &Machine,
    machines: &[Machine],
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
    tallies: &mut BTreeMap<(&'static str, &'static str), Tally>,
) -> Result<()> {
    let opt = Options {
        threads: cfg.threads,
        ..Options::default()
    };
    for &w in &acfg.worlds {
        let cases = world_cases(w, truth_machine, machines, cfg)?;
        for (ci, case) in cases.iter().enumerate().skip(acfg.first_case) {
            let dseed = design_seed(cfg.seed, w.tag(), ci);
            for &col in &acfg.columns {
                let run = diagnose_column(col, case, &opt, acfg.sigma, dseed)?;
                let (secs, cpu) = (run.secs, run.cpu);
                let d = &run.d;
                if cfg.verbose {
                    // every candidate with the figures its gates judged
                    for f in &d.tried {
                        eprintln!(
                            "      tried {:18} m {:.2} -> {:.2} dbic {:.1} z {} {}",
                            f.name,
                            f.m_before,
                            f.m_after,
                            f.dbic,
                            f.evidence["held_out_z"],
                            f.params_json()
                        );
                    }
                    // the drawn file: heat numbers and every number off by
                    // more than the default tolerance
                    let tol = tcomp_thermal::sim::machine::tolerance::DEFAULT_TOLERANCE;
                    for (k, f) in run.factors.iter().flatten() {
                        if f.ln().abs() > tol.ln_1p()
                            || k.starts_with("bearing")
                            || k.starts_with("source")
                        {
                            eprintln!("      drawn {k} ×{f:.3}");
                        }
                    }
                    for (n, why) in &d.untestable {
                        eprintln!("      untestable {n}: {why}");
                    }
                }
                let dj = d.to_json();
                // a debugging aid: the whole diagnosis per case
                if let Ok(dir) = std::env::var("TCOMP_BENCH_DUMP") {
                    let f = format!("{dir}/{}_{}_{}_{ci}.json", w.key(), col.key(), cfg.seed);
                    let tried: Vec<Value> = d.tried.iter().map(|f| f.to_json()).collect();
                    std::fs::write(&f, json!({"d": dj, "tried": tried}).to_string())?;
                }
                let file = run.factors.as_deref().map(|factors| DrawnFile {
                    spec: &case.exact.spec,
                    factors,
                });
                let t = tallies.entry((w.key(), col.key())).or_default();
                t.times.push(secs);
                t.cpu.push(cpu);
                let verdict = match (&case.truth, case.kind) {
                    (Some(truth), Some(kind)) => {
                        let o = score_effect(&dj, truth);
                        t.add_effect(kind, o);
                        if !ambiguous_of(&dj).is_empty() && effects_of(&dj).is_empty() {
                            t.ambiguous[(o != Outcome::Honest) as usize] += 1;
                        }
                        let fc = count_findings(&dj, Some(truth), file);
                        t.effect_findings[0] += fc.names_effect;
                        t.effect_findings[1] += fc.true_of_file;
                        t.effect_findings[2] += fc.neither;
                        o.label()
                    }
                    _ => {
                        let c = score_clean(&dj, file);
                        t.clean += 1;
                        t.false_alarms += c.false_alarm as usize;
                        t.clean_effects += c.effect as usize;
                        t.clean_false_findings += (c.false_findings > 0) as usize;
                        t.clean_true_findings += c.true_findings;
                        t.clean_findings_not_true += c.false_findings;
                        if c.false_alarm {
                            "FALSE ALARM"
                        } else {
                            "clean ok"
                        }
                    }
                };
                let got: Vec<Value> = ["effects", "findings"]
                    .iter()
                    .flat_map(|k| dj[*k].as_array().cloned().unwrap_or_default())
                    .map(|e| {
                        let mut g = json!({"name": e["name"], "params": e["params"]});
                        if is_parameter_finding(&e) {
                            let v = file.map_or(FileVerdict::Unknown, |f| {
                                judge_finding(&e, f.spec, f.factors)
                            });
                            g["file"] = json!(format!("{v:?}"));
                            g["z"] = e["evidence"]["held_out_z"].clone();
                        }
                        g
                    })
                    .collect();
                let amb = ambiguous_of(&dj);
                if verdict != "named" && verdict != "clean ok" {
                    t.misses.push(json!({
                        "seed": cfg.seed, "case": ci, "verdict": verdict,
                        "truth": case.describe, "got": got, "ambiguous": amb,
                    }));
                }
                eprintln!(
                    "{} seed {} case {ci:3} {:17} {:10} {:.2} s (cpu {:.2} s)  truth {}  got {}{}",
                    w.key(),
                    cfg.seed,
                    col.key(),
                    verdict,
                    secs,
                    cpu,
                    case.describe,
                    Value::from(got),
                    if amb.is_empty() {
                        String::new()
                    } else {
                        format!("  ambiguous {amb:?}")
                    }
                );
            }
        }
    }
    Ok(())
}

/// Issue 27's bench: every selected world and column over `acfg.seeds`
/// (pooled; per seed too when there are several).
pub fn run_approx_bench(
    truth_machine: &Machine,
    machines: &[Machine],
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
) -> Result<Value> {
    if !(0.0..2.0).contains(&acfg.sigma) {
        bail!("--sigma {}: 0 ≤ σ < 2 (σ of the log factor)", acfg.sigma);
    }
    let mut pooled: BTreeMap<(&'static str, &'static str), Tally> = BTreeMap::new();
    let mut per_seed = serde_json::Map::new();
    for &seed in &acfg.seeds {
        let c = BenchConfig { seed, ..*cfg };
        let mut tallies = BTreeMap::new();
        run_seed(truth_machine, machines, &c, acfg, &mut tallies)?;
        per_seed.insert(seed.to_string(), table_json(&tallies));
        for (k, t) in tallies {
            let p = pooled.entry(k).or_default();
            for (kind, v) in t.per {
                let e = p.per.entry(kind).or_default();
                for i in 0..4 {
                    e[i] += v[i];
                }
            }
            p.ambiguous[0] += t.ambiguous[0];
            p.ambiguous[1] += t.ambiguous[1];
            p.clean += t.clean;
            p.false_alarms += t.false_alarms;
            p.clean_effects += t.clean_effects;
            p.clean_false_findings += t.clean_false_findings;
            p.clean_true_findings += t.clean_true_findings;
            p.clean_findings_not_true += t.clean_findings_not_true;
            for i in 0..3 {
                p.effect_findings[i] += t.effect_findings[i];
            }
            p.times.extend(t.times);
            p.cpu.extend(t.cpu);
            p.misses.extend(t.misses);
        }
    }
    Ok(json!({
        "mode": "issue 27 columns: the same cases diagnosed with the exact design file, with a design file whose every design number is multiplied by exp(σ·z) (z standard normal, seeded per case), both with default flags, and by diagnose fit (no file)",
        "sigma_log": acfg.sigma,
        "seeds": acfg.seeds,
        "heldout_seeds": HELDOUT_SEEDS,
        "heldout": acfg.seeds == HELDOUT_SEEDS,
        "cases_per_seed": cfg.cases,
        "scoring": "parameter findings (effects entries whose evidence kind is 'design value outside its tolerance') are told from effects. named: top effect right (sensor effects: right sensor), or no effect named and the first parameter finding's physics matches (harness/score.rs KIND_RULES); honest: nothing named and the truth listed under untestable, or an ambiguous answer (nothing named, `ambiguous` listing the explanations the data cannot separate) that contains the truth (ambiguous without it: wrong; on a clean case: a false alarm); wrong: something else named; silent: nothing named or listed. A parameter finding is true of the drawn design file (harness/file_truth.rs) when the correction the file needs on the design numbers it names (truth / design: 1/factor drawn, the geometric mean over a group or multi-number parameter) lies outside the tolerance the diagnosis used and its fitted/design factor is on the same side of 1; with the exact file no finding is true. Clean: false alarm = an effect named or a finding not true of the file; true file findings counted apart. Effect cases: findings counted as naming the effect's physics, true of the file, or neither",
        "columns": table_json(&pooled),
        "per_seed": per_seed,
    }))
}

fn table_json(t: &BTreeMap<(&'static str, &'static str), Tally>) -> Value {
    let mut out = serde_json::Map::new();
    for ((w, c), tally) in t {
        if let Some(o) = out
            .entry(w.to_string())
            .or_insert_with(|| json!({}))
            .as_object_mut()
        {
            o.insert(c.to_string(), tally.json());
        }
    }
    Value::Object(out)
}

/// The text table of `run_approx_bench`'s result.
pub fn approx_text(v: &Value) -> String {
    let mut s = format!(
        "issue 27 columns, seeds {}, σ(log) {}: effect cases named / honest / wrong / silent (ambig: answered ambiguous, in honest when the truth is among them, else in wrong); clean false alarms; s per case\n",
        v["seeds"], v["sigma_log"]
    );
    s += "world        column             effect  named  honest  wrong  silent  ambig  named%  n+h%  wrong%  clean  false-alarms  true-file-findings  false-findings  s/case(mean/max)\n";
    if let Some(ws) = v["columns"].as_object() {
        for (w, cols) in ws {
            for (c, t) in cols.as_object().into_iter().flatten() {
                let f = |k: &str| t[k].as_f64().unwrap_or(f64::NAN);
                s += &format!(
                    "{w:12} {c:18} {:6} {:6} {:7} {:6} {:7} {:6} {:6.1} {:5.1} {:7.1} {:6} {:13} {:19} {:15} {:.2}/{:.2}\n",
                    t["effect_cases"], t["named"], t["honest"], t["wrong"], t["silent"], t["ambiguous"],
                    100.0 * f("named_rate"), 100.0 * f("named_or_honest_rate"), 100.0 * f("wrong_rate"),
                    t["clean_cases"], t["false_alarms"], t["clean_true_file_findings"], t["clean_false_findings"],
                    f("mean_seconds_per_case"), f("max_seconds_per_case"),
                );
            }
        }
    }
    s
}

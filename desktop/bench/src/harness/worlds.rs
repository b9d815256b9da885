//! `bench-diagnose --worlds open,cross,third` (issue 52 item 4): the
//! project's three diagnosis worlds side by side per column (exact design
//! file, design file off by σ, `diagnose fit`), and per column the worst
//! world (`worst.rs`). The open and cross worlds run in this process
//! (`approx.rs`), the third through its own generator and scorer
//! (`third.rs`).

use anyhow::Result;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;

use tcomp_thermal::sim::Machine;

use super::approx::{run_approx_bench, ApproxConfig, Column, World};
use super::cpu;
use super::draw::BenchConfig;
use super::third::{run_third, ThirdConfig};
use super::worst::{worst_row, WorldTally};

/// The aim per world and column: effect cases and clean cases.
pub const TARGET_EFFECT_CASES: usize = 150;
pub const TARGET_CLEAN_CASES: usize = 30;

/// Clean cases among `n` drawn: the open world makes one in six clean, the
/// cross world one in four (`open.rs`, `cross.rs`), the third world draws
/// each case clean with probability 1/6 (`gen.py`: the expectation).
fn clean_of(w: World, n: usize) -> usize {
    match w {
        World::Open => (n.max(6) / 6).max(1),
        World::Cross => (n.max(4) / 4).max(1),
        World::Third => n / 6,
    }
}

/// The smallest case count that reaches the target in world `w`.
pub fn default_cases(w: World) -> usize {
    let reaches = |n: usize| {
        let c = clean_of(w, n);
        c >= TARGET_CLEAN_CASES && n.saturating_sub(c) >= TARGET_EFFECT_CASES
    };
    (1..=100_000).find(|&n| reaches(n)).unwrap_or(100_000)
}

/// What the worlds report needs besides the bench and column configs.
pub struct WorldsConfig<'a> {
    /// Cases per world (None: `default_cases` of each world).
    pub cases: Option<usize>,
    /// The `tcomp` binary the third world's scorer runs.
    pub tcomp: &'a Path,
    /// Third-world cases already written by its gen.py.
    pub third_dir: Option<&'a Path>,
}

/// One world's tallies per column, its detail and its CPU seconds.
struct WorldResult {
    tallies: Vec<(Column, WorldTally)>,
    detail: Value,
    cpu: Value,
    /// Cases drawn (the third world: scored, summed over seeds).
    cases: usize,
}

fn run_in_process(
    w: World,
    truth_machine: &Machine,
    machines: &[Machine],
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
) -> Result<WorldResult> {
    let a = ApproxConfig {
        columns: acfg.columns.clone(),
        worlds: vec![w],
        sigma: acfg.sigma,
        seeds: acfg.seeds.clone(),
        first_case: acfg.first_case,
    };
    let c0 = cpu::own_s();
    let v = run_approx_bench(truth_machine, machines, cfg, &a)?;
    let total = cpu::own_s() - c0;
    let table = &v["columns"][w.key()];
    let tallies = acfg
        .columns
        .iter()
        .map(|&c| (c, WorldTally::from_column_json(&table[c.key()])))
        .collect();
    let per_column: serde_json::Map<String, Value> = acfg
        .columns
        .iter()
        .map(|&c| {
            (
                c.key().to_string(),
                table[c.key()]["cpu_seconds_total"].clone(),
            )
        })
        .collect();
    Ok(WorldResult {
        tallies,
        detail: table.clone(),
        cpu: json!({"total": total, "diagnosis_per_column": per_column}),
        cases: cfg.cases,
    })
}

fn run_third_world(
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
    wcfg: &WorldsConfig,
) -> Result<WorldResult> {
    let mut pooled: BTreeMap<&'static str, (Column, WorldTally)> = BTreeMap::new();
    let (mut gen_cpu, mut col_cpu, mut col_wall) = (0.0, BTreeMap::new(), BTreeMap::new());
    let (mut per_seed, mut misses, mut cases) = (serde_json::Map::new(), Vec::new(), 0);
    for &seed in &acfg.seeds {
        let r = run_third(&ThirdConfig {
            cases: cfg.cases,
            first_case: acfg.first_case,
            seed,
            sigma: acfg.sigma,
            columns: &acfg.columns,
            tcomp: wcfg.tcomp,
            dir: wcfg.third_dir,
        })?;
        gen_cpu += r.cpu_generate_s;
        for (c, s) in &r.cpu_s {
            *col_cpu.entry(c.key()).or_insert(0.0) += s;
        }
        for (c, s) in &r.wall_s {
            *col_wall.entry(c.key()).or_insert(0.0) += s;
        }
        for (c, t) in &r.tallies {
            pooled
                .entry(c.key())
                .or_insert((*c, WorldTally::default()))
                .1
                .add(t);
        }
        per_seed.insert(
            seed.to_string(),
            json!({"cases": r.cases, "per_effect": r.per_effect}),
        );
        misses.extend(r.misses);
        cases += r.cases;
    }
    let total = gen_cpu + col_cpu.values().sum::<f64>();
    Ok(WorldResult {
        tallies: acfg
            .columns
            .iter()
            .filter_map(|c| pooled.get(c.key()).copied())
            .collect(),
        detail: json!({"per_seed": per_seed, "misses": misses}),
        cpu: json!({
            "total": total,
            "generation": gen_cpu,
            "scoring_per_column": col_cpu,
            "wall_scoring_per_column": col_wall,
            "note": "python3 and the tcomp processes it ran (children CPU time)",
        }),
        cases,
    })
}

/// One column's tallies, world by world.
type PerWorld = Vec<(String, WorldTally)>;

/// Every selected world and column over `acfg.seeds` (pooled), with the
/// worst world per column.
pub fn run_worlds(
    truth_machine: &Machine,
    machines: &[Machine],
    cfg: &BenchConfig,
    acfg: &ApproxConfig,
    wcfg: &WorldsConfig,
) -> Result<Value> {
    let mut per_col: BTreeMap<&'static str, (Column, PerWorld)> = BTreeMap::new();
    let (mut worlds, mut detail, mut cpu_s, mut cases) = (
        serde_json::Map::new(),
        serde_json::Map::new(),
        serde_json::Map::new(),
        serde_json::Map::new(),
    );
    for &w in &acfg.worlds {
        let n = wcfg.cases.unwrap_or_else(|| default_cases(w));
        let c = BenchConfig { cases: n, ..*cfg };
        let r = match w {
            World::Third => run_third_world(&c, acfg, wcfg)?,
            _ => run_in_process(w, truth_machine, machines, &c, acfg)?,
        };
        let mut cols = serde_json::Map::new();
        for (col, t) in &r.tallies {
            cols.insert(col.key().to_string(), t.json());
            per_col
                .entry(col.key())
                .or_insert((*col, Vec::new()))
                .1
                .push((w.key().to_string(), *t));
        }
        worlds.insert(w.key().to_string(), Value::Object(cols));
        detail.insert(w.key().to_string(), r.detail);
        cpu_s.insert(w.key().to_string(), r.cpu);
        cases.insert(w.key().to_string(), json!(r.cases));
    }
    let worst: serde_json::Map<String, Value> = acfg
        .columns
        .iter()
        .filter_map(|c| per_col.get(c.key()))
        .map(|(c, pw)| {
            let row: Vec<Value> = worst_row(*c, pw).iter().map(|w| w.json()).collect();
            (c.key().to_string(), Value::from(row))
        })
        .collect();
    Ok(json!({
        "mode": "issue 52 item 4: per world (open: the truth model; cross: the first simulator's machines under diagnose; third: the blind horizontal machining centre, worlds/third, by its own gen.py and score.py) and column (exact design file; design file off by sigma; diagnose fit), then the worst world per column",
        "seeds": acfg.seeds,
        "sigma": acfg.sigma,
        "cases_per_world": cases,
        "target_per_world_and_column": {"effect": TARGET_EFFECT_CASES, "clean": TARGET_CLEAN_CASES},
        "scoring": "named: the truth named first (a parameter finding stating its physics counts, named_as_parameter); honest: nothing named and the truth listed untestable, or an ambiguous answer containing the truth; wrong: something else named, or an ambiguous answer without the truth; silent: nothing named or listed; false alarm: a clean case with something named (an ambiguous answer included; open/cross with a design file: also a finding not true of the drawn file; third: any effects entry, its frozen scorer's rule). The design column's error is lognormal exp(sigma z) in open/cross and x(1 + N(0, sigma)) in third (its scorer's own perturbation). worst: per column and criterion the world(s) at the worst rate (file columns: lowest named; fit: lowest named+honest and highest wrong; every column: highest false-alarm rate)",
        "worlds": worlds,
        "worst": worst,
        "cpu_seconds": cpu_s,
        "detail": detail,
    }))
}

/// The text table of `run_worlds`' result.
pub fn worlds_text(v: &Value) -> String {
    let pc = |x: &Value| {
        x.as_f64()
            .map_or("  -  ".to_string(), |r| format!("{:5.1}", 100.0 * r))
    };
    let mut s = format!(
        "worlds report (issue 52 item 4), seeds {}, sigma {}, cases per world {}\n",
        v["seeds"], v["sigma"], v["cases_per_world"]
    );
    s += "world        column             effect named honest (amb+) wrong (amb-) silent err clean FA  named%  n+h% wrong%   FA%\n";
    for (w, cols) in v["worlds"].as_object().into_iter().flatten() {
        for (c, t) in cols.as_object().into_iter().flatten() {
            // serde_json's Display ignores widths: counts as integers
            let n = |k: &str| t[k].as_u64().unwrap_or(0);
            s += &format!(
                "{w:12} {c:18} {:6} {:5} {:6} {:6} {:5} {:6} {:6} {:3} {:5} {:2} {} {} {} {}\n",
                n("effect_cases"),
                n("named"),
                n("honest"),
                n("ambiguous_with_truth"),
                n("wrong"),
                n("ambiguous_without_truth"),
                n("silent"),
                n("errors"),
                n("clean_cases"),
                n("false_alarms"),
                pc(&t["named_rate"]),
                pc(&t["named_or_honest_rate"]),
                pc(&t["wrong_rate"]),
                pc(&t["false_alarm_rate"]),
            );
        }
    }
    for (c, row) in v["worst"].as_object().into_iter().flatten() {
        let parts: Vec<String> = row
            .as_array()
            .into_iter()
            .flatten()
            .map(|e| {
                let ws: Vec<String> = e["worlds"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|x| {
                        format!(
                            "{} {}/{}",
                            x["world"].as_str().unwrap_or("?"),
                            x["count"],
                            x["of"]
                        )
                    })
                    .collect();
                format!(
                    "{} {} % ({})",
                    e["criterion"].as_str().unwrap_or("?"),
                    pc(&e["rate"]).trim(),
                    ws.join(", ")
                )
            })
            .collect();
        s += &format!("worst {c:18} {}\n", parts.join("; "));
    }
    for (w, c) in v["cpu_seconds"].as_object().into_iter().flatten() {
        s += &format!(
            "cpu {w:12} {:.0} s  {}\n",
            c["total"].as_f64().unwrap_or(f64::NAN),
            c
        );
    }
    s
}

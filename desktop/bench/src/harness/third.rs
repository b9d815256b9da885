//! The blind third world (`worlds/third/`, frozen: nothing there is ever
//! edited or written) run for `bench-diagnose --worlds third`. Its own
//! generator (`gen.py`) writes the cases into a temporary folder and its
//! own scorer runs `tcomp diagnose` on them, through
//! `worlds/score_ambiguous.py`, which puts issue 52's ambiguous rule in
//! front of the frozen `score.py` without changing it. Both are Python 3
//! (standard library only), so they run as `python3` subprocesses: the
//! world is scored by its own code, never by a Rust copy of it.

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::approx::Column;
use super::cpu;
use super::worst::WorldTally;

/// What one seed's third-world run needs.
pub struct ThirdConfig<'a> {
    /// Cases drawn (`gen.py --cases`; about one in six is clean).
    pub cases: usize,
    /// First case index (`gen.py --first`).
    pub first_case: usize,
    /// `gen.py --seed` and the scorer's `--perturb-seed`.
    pub seed: u64,
    /// σ of the design file's error (`score.py --sigma`: × (1 + N(0, σ))).
    pub sigma: f64,
    pub columns: &'a [Column],
    /// The `tcomp` binary the scorer runs.
    pub tcomp: &'a Path,
    /// Cases gen.py already wrote: scored as they are, nothing generated.
    pub dir: Option<&'a Path>,
}

/// One seed's result: per column its tally, per effect kind its classes,
/// the cases not named, and the CPU seconds (generation, each column).
pub struct ThirdRun {
    pub tallies: Vec<(Column, WorldTally)>,
    pub per_effect: Value,
    pub misses: Vec<Value>,
    pub cpu_generate_s: f64,
    pub cpu_s: Vec<(Column, f64)>,
    pub wall_s: Vec<(Column, f64)>,
    pub cases: usize,
}

/// `desktop/bench/worlds/`.
fn worlds_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds")
}

/// score.py's name of a column.
fn score_column(c: Column) -> &'static str {
    match c {
        Column::Exact => "exact",
        Column::Design => "design",
        Column::Fit => "fit",
    }
}

/// The temporary case folder, removed when dropped.
struct TempCases(PathBuf);

impl Drop for TempCases {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Run `python3 args…`; its stdout, or one line naming what failed.
fn python(what: &str, args: &[&std::ffi::OsStr]) -> Result<String> {
    let out = Command::new("python3")
        .args(args)
        .output()
        .with_context(|| format!("third world: {what}: cannot run python3"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("");
        bail!("third world: {what} failed ({}): {last}", out.status);
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Count one scored case of a column into `t`: score.py's class and the
/// name it shows (`ambiguous: a/b` for an ambiguous answer, which
/// score_ambiguous.py has classed honest when it holds the truth, wrong
/// when not, a false alarm on a clean case).
pub fn count_case(effect: &str, class: &str, named: &str, t: &mut WorldTally) -> Result<()> {
    let ambiguous = named.starts_with("ambiguous:");
    match class {
        "right" => t.named += 1,
        "right_param" => {
            t.named += 1;
            t.named_as_parameter += 1;
        }
        "honest" if ambiguous => t.ambiguous_with_truth += 1,
        "honest" => t.honest_untestable += 1,
        "wrong" if ambiguous => t.ambiguous_without_truth += 1,
        "wrong" => t.wrong_named += 1,
        "missed" => t.silent += 1,
        "quiet" => t.clean += 1,
        "false_alarm" => {
            t.clean += 1;
            t.false_alarms += 1;
        }
        "error" if effect == "none" => t.clean_errors += 1,
        "error" => t.effect_errors += 1,
        o => bail!("third world: the scorer gave an unknown class `{o}`"),
    }
    Ok(())
}

/// Generate (unless `cfg.dir`) and score one seed's third-world cases.
pub fn run_third(cfg: &ThirdConfig) -> Result<ThirdRun> {
    if !cfg.tcomp.is_file() {
        bail!(
            "third world: no tcomp at {} (cargo build --release -p tcomp, or --tcomp FILE)",
            cfg.tcomp.display()
        );
    }
    let worlds = worlds_dir();
    let _temp;
    let c0 = cpu::children_s();
    let dir: PathBuf = match cfg.dir {
        Some(d) => d.to_path_buf(),
        None => {
            let d = std::env::temp_dir().join(format!(
                "tcomp-bench-third-{}-seed{}",
                std::process::id(),
                cfg.seed
            ));
            _temp = TempCases(d.clone());
            let n = cfg.cases.saturating_sub(cfg.first_case);
            eprintln!(
                "third_world seed {}: gen.py writes {n} cases into {}",
                cfg.seed,
                d.display()
            );
            let (seed, cases, first) = (
                cfg.seed.to_string(),
                n.to_string(),
                cfg.first_case.to_string(),
            );
            let gen = worlds.join("third").join("gen.py");
            python(
                "gen.py",
                &[
                    gen.as_os_str(),
                    "--out".as_ref(),
                    d.as_os_str(),
                    "--seed".as_ref(),
                    seed.as_ref(),
                    "--cases".as_ref(),
                    cases.as_ref(),
                    "--first".as_ref(),
                    first.as_ref(),
                ],
            )?;
            d
        }
    };
    let cpu_generate_s = cpu::children_s() - c0;
    let mut run = ThirdRun {
        tallies: Vec::new(),
        per_effect: json!({}),
        misses: Vec::new(),
        cpu_generate_s,
        cpu_s: Vec::new(),
        wall_s: Vec::new(),
        cases: 0,
    };
    for &col in cfg.columns {
        score_one_column(cfg, &worlds, &dir, col, &mut run)?;
    }
    Ok(run)
}

/// Run the scorer on one column and count its cases into `run`.
fn score_one_column(
    cfg: &ThirdConfig,
    worlds: &Path,
    dir: &Path,
    col: Column,
    run: &mut ThirdRun,
) -> Result<()> {
    let scorer = worlds.join("score_ambiguous.py");
    let (sigma, seed) = (cfg.sigma.to_string(), cfg.seed.to_string());
    let c0 = cpu::children_s();
    let t0 = std::time::Instant::now();
    let out = python(
        "score_ambiguous.py",
        &[
            scorer.as_os_str(),
            "--cases".as_ref(),
            dir.as_os_str(),
            "--tcomp".as_ref(),
            cfg.tcomp.as_os_str(),
            "--sigma".as_ref(),
            sigma.as_ref(),
            "--perturb-seed".as_ref(),
            seed.as_ref(),
            "--columns".as_ref(),
            score_column(col).as_ref(),
            "--json".as_ref(),
        ],
    )?;
    run.cpu_s.push((col, cpu::children_s() - c0));
    run.wall_s.push((col, t0.elapsed().as_secs_f64()));
    let v: Value = serde_json::from_str(&out)
        .map_err(|e| anyhow::anyhow!("third world: the scorer's JSON: {e}"))?;
    let rows = v["per_case"].as_array().cloned().unwrap_or_default();
    run.cases = rows.len();
    let mut t = WorldTally::default();
    let mut per_effect: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for row in &rows {
        let effect = row["effect"].as_str().unwrap_or("?");
        let r = &row[score_column(col)];
        let class = r["class"].as_str().unwrap_or("?");
        let named = r["named"].as_str().unwrap_or("");
        count_case(effect, class, named, &mut t)?;
        *per_effect
            .entry(effect.to_string())
            .or_default()
            .entry(class.to_string())
            .or_default() += 1;
        if !matches!(class, "right" | "right_param" | "quiet") {
            run.misses.push(json!({
                "seed": cfg.seed, "case": row["case"], "column": col.key(),
                "truth": effect, "sensor": row["sensor"], "class": class, "got": named,
            }));
        }
        eprintln!(
            "third_world seed {} {} {:17} {:12} {:.1} s  truth {}{}  got {}",
            cfg.seed,
            row["case"].as_str().unwrap_or("?"),
            col.key(),
            class,
            r["seconds"].as_f64().unwrap_or(f64::NAN),
            effect,
            row["sensor"]
                .as_str()
                .map(|s| format!("@{s}"))
                .unwrap_or_default(),
            named,
        );
    }
    run.tallies.push((col, t));
    run.per_effect[col.key()] = json!(per_effect);
    Ok(())
}

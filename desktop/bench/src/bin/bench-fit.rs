//! Benchmarks of `tcomp fit`:
//! (a) FL_THERMAL, chronological split 60 % / 20 %: published test MAE next to
//!     our MLR and GA-BPN (same rows, same metric);
//! (b) training time of GA + Levenberg–Marquardt on a 4-hour 1 Hz run (4 h of
//!     FL_THERMAL, 24–28 h, interpolated to 1 Hz) against scikit-learn's
//!     MLPRegressor(11, logistic) on the same inputs and split.
//!
//! (c) the default pipeline refitted with 5 ensemble base seeds: test MAE
//!     spread of the chosen model and of each network candidate;
//! (d) fit time of the default pipeline on 500,000 rows (FL_THERMAL
//!     interpolated), wall and CPU.
//!
//! Usage: bench-fit [--json] [--data run.csv] [--ensemble N] [--no-sklearn]
//!        [--seeds N] [--big-rows N] [--write-big FILE]

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use tcomp_data::runcsv::Run;
use tcomp_model::fit::net::NetOpts;
use tcomp_model::fit::pipeline::{
    fit_plan, fit_plan_with, train_ensemble, FitConfig, NetInfo, Plan, Progress, Silent,
};
use tcomp_model::fit::*;

const PUBLISHED: [(&str, f64); 2] = [("dch3_um", 3.70), ("dch5_um", 4.28)];

fn default_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/caiviac-fl-thermal/run.csv")
}

/// Rows with `t0 ≤ t ≤ t1` linearly interpolated every `dt` seconds (time
/// restarts at 0).
fn resample(run: &Run, t0: f64, t1: f64, dt: f64, what: &str) -> Result<Run> {
    let t = run.time_s();
    let mut out = Run {
        meta: run.meta.clone(),
        columns: run.columns.clone(),
        data: vec![Vec::new(); run.columns.len()],
    };
    out.set_meta("source", what);
    let mut k = 0usize;
    let mut i = 0u64;
    loop {
        let ts = t0 + i as f64 * dt;
        if ts > t1 + 1e-6 * dt || t.len() < 2 {
            break;
        }
        let ts = ts.min(t[t.len() - 1]);
        while k + 2 < t.len() && t[k + 1] < ts {
            k += 1;
        }
        let w = ((ts - t[k]) / (t[k + 1] - t[k])).clamp(0.0, 1.0);
        out.data[0].push(Some(ts - t0));
        for c in 1..run.columns.len() {
            let v = match (run.data[c][k], run.data[c][k + 1]) {
                (Some(a), Some(b)) => Some(a + w * (b - a)),
                (a, b) => a.or(b),
            };
            out.data[c].push(v);
        }
        i += 1;
    }
    if out.rows() < 100 {
        bail!("resampling gave only {} rows", out.rows());
    }
    Ok(out)
}

fn resample_1hz(run: &Run, t0: f64, t1: f64) -> Result<Run> {
    resample(
        run,
        t0,
        t1,
        1.0,
        "FL_THERMAL resampled to 1 Hz (linear interpolation) for bench-fit",
    )
}

/// FL_THERMAL's whole span linearly interpolated to `rows` rows (the
/// 500,000-row fit-time case).
pub fn resample_rows(run: &Run, rows: usize) -> Result<Run> {
    let t = run.time_s();
    let (t0, t1) = (t[0], t[t.len() - 1]);
    let dt = (t1 - t0) / (rows.max(2) - 1) as f64;
    let mut r = resample(
        run,
        t0,
        t1,
        dt,
        "FL_THERMAL interpolated for the bench-fit fit-time case",
    )?;
    r.set_meta("sample_period_s", &format!("{dt}"));
    Ok(r)
}

/// CPU time (user + system, all threads) of this process so far, seconds
/// (Linux `/proc/self/stat`, USER_HZ = 100); None elsewhere. Wall-clock time
/// on a machine shared with other jobs overstates the fit's own cost.
fn cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which ends with the last ')').
    let rest = s.get(s.rfind(')')? + 2..)?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(run)
}

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    name = "bench-fit",
    about = "Benchmarks of `tcomp fit` on FL_THERMAL: test MAE against the published figures, seed spread, the 500,000-row fit time, GA + LM against scikit-learn"
)]
struct Args {
    /// Print the figures as one JSON object.
    #[arg(long)]
    json: bool,
    /// Skip the scikit-learn comparison (scripts/bench-sklearn.py).
    #[arg(long = "no-sklearn")]
    no_sklearn: bool,
    /// The FL_THERMAL run CSV (default: shared/data/caiviac-fl-thermal/run.csv).
    #[arg(long, value_name = "CSV", default_value_os_t = default_data(), hide_default_value = true)]
    data: PathBuf,
    /// Networks per ensemble in the FL_THERMAL fit.
    #[arg(long, value_name = "N", default_value_t = NetOpts::default().ensemble)]
    ensemble: usize,
    /// Refits of the seed spread (ensemble base seeds 1, 5, 9, ...; 0 skips it).
    #[arg(long, value_name = "N", default_value_t = 5)]
    seeds: usize,
    /// Rows of the fit-time case (FL_THERMAL interpolated; 0 skips it).
    #[arg(long = "big-rows", value_name = "N", default_value_t = 500_000)]
    big_rows: usize,
    /// Write the fit-time case's run CSV to this file.
    #[arg(long = "write-big", value_name = "FILE")]
    write_big: Option<String>,
}

fn run() -> Result<()> {
    let args: Args = tcomp_bench::cli::parse()?;
    let json = args.json;
    let run = Run::read(&args.data).with_context(|| "FL_THERMAL data (give --data <run.csv>)")?;

    let fl = fit_fl_thermal(&run, args.ensemble, json)?;
    let seeds_out = seed_spread(&fl.plan, &fl.cfg, args.seeds, json)?;
    let big = big_fit(&run, &fl.cfg, args.big_rows, args.write_big, json)?;
    let t4 = timing_4h(&run, args.no_sklearn)?;
    let out = serde_json::json!({"fl_thermal": fl.table, "fl_thermal_fit_s": fl.secs, "fl_thermal_fit_cpu_s": fl.cpu,
        "seed_spread": seeds_out, "big_fit": big, "timing_4h_1hz": t4.json()});
    if json {
        println!("{out}");
        return Ok(());
    }
    print_fl_table(&fl.table);
    for s in &seeds_out {
        println!("seed spread {}: {}", s["channel"], s["test_mae"]);
    }
    if !big.is_null() {
        println!("big fit: {big}");
    }
    println!(
        "(published: seq2seq + attention, GPU; fit took {:.1} s for both channels)\n",
        fl.secs
    );
    t4.print();
    Ok(())
}

/// (a) FL_THERMAL chronological 60/20: the plan and configuration the
/// other groups refit, the table of test MAE per model, the fit's time.
struct FlThermal {
    plan: Plan,
    cfg: FitConfig,
    table: Vec<serde_json::Value>,
    secs: f64,
    cpu: Option<f64>,
}

fn fit_fl_thermal(run: &Run, ensemble: usize, json: bool) -> Result<FlThermal> {
    let t_a = Instant::now();
    let ca = cpu_s();
    let plan = Plan::new(
        vec![run.clone()],
        vec!["fl-thermal".into()],
        1,
        Some((0.6, 0.8)),
    )?;
    let cfg = FitConfig {
        split_chrono: Some((0.6, 0.8)),
        channels: Some(PUBLISHED.iter().map(|p| p.0.to_string()).collect()),
        net: NetOpts {
            ensemble,
            ..NetOpts::default()
        },
        ..FitConfig::default()
    };
    // The bar on the terminal, unless the output is JSON.
    let bar = tcomp_bench::progress::Bar::default();
    let progress: &dyn Progress = if json { &Silent } else { &bar };
    let rep = fit_plan_with(&plan, &cfg, progress)?;
    let secs = t_a.elapsed().as_secs_f64();
    let cpu = cpu_s().zip(ca).map(|(b, a)| b - a);
    let mae = |model: &str, ch: &str| {
        rep.models
            .iter()
            .find(|m| m.name == model)
            .and_then(|m| m.channels.get(ch))
            .map(|x| x.mae_um)
    };
    let mut table = Vec::new();
    for (ch, publ) in PUBLISHED {
        let info = rep.inputs.iter().find(|i| i.channel == ch);
        table.push(serde_json::json!({
            "channel": ch, "published_seq2seq_attention_mae_um": publ,
            "chosen": rep.chosen.get(ch),
            "chosen_mae_um": rep.chosen.get(ch).and_then(|m| mae(m, ch)),
            "mlr_static_mae_um": mae("mlr-static", ch), "mlr_mae_um": mae("mlr", ch),
            "hybrid_mae_um": mae("hybrid", ch), "ga_bpn_mae_um": mae("ga-bpn", ch),
            "blend_mae_um": mae("blend", ch),
            "cv": info.map(|i| &i.cv),
            "inputs": info.map(|i| i.features.clone()).unwrap_or_default(),
        }));
    }
    Ok(FlThermal {
        plan,
        cfg,
        table,
        secs,
        cpu,
    })
}

/// (a2) Seed spread: the default pipeline with ensemble base seeds
/// 1, 5, 9, ... (members never shared between seeds); test MAE of the
/// chosen model and of each network candidate.
fn seed_spread(
    plan: &Plan,
    cfg: &FitConfig,
    n_seeds: usize,
    json: bool,
) -> Result<Vec<serde_json::Value>> {
    let mut seeds_out = Vec::new();
    if n_seeds == 0 {
        return Ok(seeds_out);
    }
    let mut per: Vec<BTreeMap<String, Vec<f64>>> = vec![BTreeMap::new(); PUBLISHED.len()];
    let mut chosen_names: Vec<Vec<String>> = vec![vec![]; PUBLISHED.len()];
    for k in 0..n_seeds {
        let seed = 1 + 4 * k as u64;
        let c = FitConfig {
            net: NetOpts {
                seed,
                ..cfg.net.clone()
            },
            ..cfg.clone()
        };
        let r = fit_plan(plan, &c)?;
        for (i, (ch, _)) in PUBLISHED.iter().enumerate() {
            let chosen = r.chosen.get(*ch).cloned().unwrap_or_default();
            for m in &r.models {
                if let Some(x) = m.channels.get(*ch) {
                    per[i].entry(m.name.clone()).or_default().push(x.mae_um);
                    if m.name == chosen {
                        per[i].entry("chosen".into()).or_default().push(x.mae_um);
                    }
                }
            }
            chosen_names[i].push(chosen);
        }
        if !json {
            eprintln!("seed {seed}: chosen {:?}", r.chosen);
        }
    }
    for (i, (ch, _)) in PUBLISHED.iter().enumerate() {
        let stats: BTreeMap<&String, serde_json::Value> = per[i]
            .iter()
            .map(|(name, v)| {
                let n = v.len() as f64;
                let mean = v.iter().sum::<f64>() / n;
                let sd = (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>()
                    / (n - 1.0).max(1.0))
                .sqrt();
                (
                    name,
                    serde_json::json!({"mae_um": v, "mean_um": mean, "sd_um": sd,
                        "spread_pct": 100.0 * sd / mean}),
                )
            })
            .collect();
        seeds_out.push(serde_json::json!({"channel": ch,
            "base_seeds": (0..n_seeds).map(|k| 1 + 4 * k).collect::<Vec<_>>(),
            "chosen": chosen_names[i], "test_mae": stats}));
    }
    Ok(seeds_out)
}

/// (c) Fit time on 500,000 rows: FL_THERMAL's whole span interpolated
/// (≈ 3 Hz), default pipeline, both published channels.
fn big_fit(
    run: &Run,
    cfg: &FitConfig,
    big_rows: usize,
    write_big: Option<String>,
    json: bool,
) -> Result<serde_json::Value> {
    if big_rows == 0 {
        return Ok(serde_json::Value::Null);
    }
    let rb = resample_rows(run, big_rows)?;
    if let Some(p) = write_big {
        rb.write(std::path::Path::new(&p))?;
    }
    let n = rb.rows();
    let t_c = Instant::now();
    let c0 = cpu_s();
    let planb = Plan::new(vec![rb], vec!["fl-big".into()], 1, Some((0.6, 0.8)))?;
    let r = fit_plan(&planb, cfg)?;
    let secs = t_c.elapsed().as_secs_f64();
    let cpu = cpu_s().zip(c0).map(|(b, a)| b - a);
    let big = serde_json::json!({"rows": n, "fit_s": secs, "fit_cpu_s": cpu, "target_s": 30.0,
        "chosen": r.chosen,
        "cv": r.inputs.iter().map(|i| (i.channel.clone(), i.cv.clone())).collect::<BTreeMap<_, _>>()});
    if !json {
        eprintln!(
            "{n}-row fit: {secs:.1} s wall, {:.1} s CPU, chosen {:?}",
            cpu.unwrap_or(f64::NAN),
            r.chosen
        );
    }
    Ok(big)
}

/// (b) 4 h at 1 Hz: GA + LM against scikit-learn, what both reached.
struct Timing4h {
    specs: Vec<FeatureSpec>,
    train_rows: usize,
    test_rows: usize,
    ours_s: f64,
    info: NetInfo,
    ours: Metrics,
    sk: Option<serde_json::Value>,
    sk_err: Option<String>,
}

fn timing_4h(run: &Run, no_sklearn: bool) -> Result<Timing4h> {
    let r4 = resample_1hz(run, 24.0 * 3600.0, 28.0 * 3600.0)?;
    let kinds: Vec<(FeatureKind, Option<f64>)> =
        ["T_t4", "T_t5@1800", "T_t16@3600", "T_t9@7200", "rpm@1800"]
            .iter()
            .map(|s| parse_feature(s))
            .collect::<Result<_>>()?;
    let ch = "dch5_um";
    let plan4 = Plan::new(vec![r4], vec!["4h-1Hz".into()], 1, Some((0.6, 0.8)))?;
    let cache = SeriesCache::new(&plan4.runs, kinds.clone())?;
    let idx: Vec<usize> = (0..kinds.len()).collect();
    let full = cache.samples(&plan4.runs, &plan4.train, &idx, ch)?;
    let test = cache.samples(&plan4.runs, &plan4.val, &idx, ch)?;
    let (inner_seg, block_seg) = plan4.inner_block(0.15);
    let inner = cache.samples(&plan4.runs, &inner_seg, &idx, ch)?;
    let block = cache.samples(&plan4.runs, &block_seg, &idx, ch)?;
    let specs = ranged_specs(&kinds, &full);
    let opts = NetOpts::default();
    let t_b = Instant::now();
    let (members, infos) = train_ensemble(&specs, ch, &inner, &block, &full, &opts, &Silent);
    let ours_s = t_b.elapsed().as_secs_f64();
    let info = infos.into_iter().next().unwrap_or_default();
    let np = NetEnsemble {
        members: members.iter().collect(),
    };
    let pred: Vec<f64> = test.x.iter().map(|r| np.predict_raw(r)).collect();
    let ours = metrics(&test.y, &pred);
    let (sk, sk_err) = if no_sklearn {
        (None, None)
    } else {
        sklearn(kinds.len(), &specs, &full, &test)?
    };
    Ok(Timing4h {
        train_rows: full.y.len(),
        test_rows: test.y.len(),
        specs,
        ours_s,
        info,
        ours,
        sk,
        sk_err,
    })
}

/// scikit-learn's MLPRegressor on the same normalized inputs and rows
/// (`scripts/bench-sklearn.py`): its JSON, or why there is none.
fn sklearn(
    n_inputs: usize,
    specs: &[FeatureSpec],
    full: &Samples,
    test: &Samples,
) -> Result<(Option<serde_json::Value>, Option<String>)> {
    let mut sk: Option<serde_json::Value> = None;
    let mut sk_err: Option<String> = None;
    let dir = std::env::temp_dir().join(format!("bench-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let csv = dir.join("data.csv");
    let mut s = String::new();
    s.push_str(
        &(1..=n_inputs)
            .map(|i| format!("x{i}"))
            .collect::<Vec<_>>()
            .join(","),
    );
    s.push_str(",y,split\n");
    for (set, name) in [(full, "train"), (test, "test")] {
        for (r, y) in set.x.iter().zip(&set.y) {
            for (f, v) in specs.iter().zip(r) {
                s.push_str(&format!("{},", f.normalize(*v)));
            }
            s.push_str(&format!("{y},{name}\n"));
        }
    }
    std::fs::write(&csv, s)?;
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/bench-sklearn.py");
    let out =
        std::process::Command::new(std::env::var("PYTHON").unwrap_or_else(|_| "python3".into()))
            .arg(&script)
            .arg(&csv)
            .output();
    let _ = std::fs::remove_dir_all(&dir);
    match out {
        Ok(o) if o.status.success() => {
            match serde_json::from_slice::<serde_json::Value>(&o.stdout) {
                Ok(v) => sk = Some(v),
                Err(e) => sk_err = Some(format!("bad JSON from bench-sklearn.py: {e}")),
            }
        }
        Ok(o) => {
            sk_err = Some(format!(
                "bench-sklearn.py failed: {}",
                String::from_utf8_lossy(&o.stderr)
            ))
        }
        Err(e) => sk_err = Some(format!("cannot run python3: {e}")),
    }
    Ok((sk, sk_err))
}

impl Timing4h {
    fn sk_s(&self) -> Option<f64> {
        self.sk.as_ref().and_then(|v| v["train_s"].as_f64())
    }

    fn json(&self) -> serde_json::Value {
        let (info, ours, ours_s) = (&self.info, &self.ours, self.ours_s);
        serde_json::json!({
            "data": "FL_THERMAL 24-28 h interpolated to 1 Hz, chrono 60/20, channel dch5_um",
            "inputs": self.specs.iter().map(FeatureSpec::name).collect::<Vec<_>>(),
            "train_rows": self.train_rows, "test_rows": self.test_rows,
            "ours": {"train_s": ours_s, "ga_s": info.ga_s, "lm_s": info.lm_s, "lm_iters": info.lm_iters, "mae_um": ours.mae_um, "rms_um": ours.rms_um},
            "sklearn": self.sk, "sklearn_error": self.sk_err,
            "ratio_sklearn_over_ours": self.sk_s().map(|s| s / ours_s),
        })
    }

    fn print(&self) {
        let (info, ours, ours_s) = (&self.info, &self.ours, self.ours_s);
        println!(
            "Training time, 4 h at 1 Hz ({} train rows, {} test rows, 5 inputs, 11 hidden):",
            self.train_rows, self.test_rows
        );
        println!(
            "  ours GA + LM      {:>7.2} s (GA {:.2} s, LM {:.2} s, {} steps), test MAE {:.2} µm",
            ours_s, info.ga_s, info.lm_s, info.lm_iters, ours.mae_um
        );
        let sk_mae = self.sk.as_ref().and_then(|v| v["mae_um"].as_f64());
        match (self.sk_s(), sk_mae) {
            (Some(s), Some(m)) => {
                println!("  sklearn MLP (adam){:>7.2} s, test MAE {:.2} µm", s, m);
                println!("  ratio sklearn / ours: {:.2}", s / ours_s);
            }
            _ => println!(
                "  sklearn: {}",
                self.sk_err.clone().unwrap_or_else(|| "skipped".into())
            ),
        }
    }
}

/// The FL_THERMAL table as text.
fn print_fl_table(table: &[serde_json::Value]) {
    println!(
        "FL_THERMAL, chronological split (train first 60 %, test next 20 %), test MAE µm (float)"
    );
    println!(
        "{:<9} {:>10} {:>11} {:>8} {:>8} {:>8} {:>8}  {:<10} inputs (ours)",
        "channel", "published", "MLR static", "MLR", "blend", "hybrid", "GA-BPN", "chosen"
    );
    for row in table {
        let f = |k: &str| {
            row[k]
                .as_f64()
                .map_or("-".to_string(), |v| format!("{v:.2}"))
        };
        println!(
            "{:<9} {:>10} {:>11} {:>8} {:>8} {:>8} {:>8}  {:<10} {}",
            row["channel"].as_str().unwrap_or(""),
            f("published_seq2seq_attention_mae_um"),
            f("mlr_static_mae_um"),
            f("mlr_mae_um"),
            f("blend_mae_um"),
            f("hybrid_mae_um"),
            f("ga_bpn_mae_um"),
            row["chosen"].as_str().unwrap_or("-"),
            row["inputs"]
                .as_array()
                .map(|a| a
                    .iter()
                    .filter_map(|v| v.as_str())
                    .collect::<Vec<_>>()
                    .join(", "))
                .unwrap_or_default()
        );
    }
}

//! Benchmarks of `tcomp fit`:
//! (a) FL_THERMAL, chronological split 60 % / 20 %: published test MAE next to
//!     our MLR and GA-BPN (same rows, same metric);
//! (b) training time of GA + Levenberg–Marquardt on a 4-hour 1 Hz run (4 h of
//!     FL_THERMAL, 24–28 h, interpolated to 1 Hz) against scikit-learn's
//!     MLPRegressor(11, logistic) on the same inputs and split.
//!
//! Usage: bench-fit [--json] [--data run.csv] [--ensemble N] [--no-sklearn]

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::ProgressBar;
use tcomp::fit::net::NetOpts;
use tcomp::fit::run::{fit_plan, train_ensemble, FitConfig, Plan};
use tcomp::fit::*;
use tcomp::runcsv::Run;

const PUBLISHED: [(&str, f64); 2] = [("dch3_um", 3.70), ("dch5_um", 4.28)];

fn default_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/caiviac-fl-thermal/run.csv")
}

/// Rows with `t0 ≤ t ≤ t1` linearly interpolated to 1 Hz (time restarts at 0).
fn resample_1hz(run: &Run, t0: f64, t1: f64) -> Result<Run> {
    let t = run.time_s();
    let mut out = Run {
        meta: run.meta.clone(),
        columns: run.columns.clone(),
        data: vec![Vec::new(); run.columns.len()],
    };
    out.set_meta(
        "source",
        "FL_THERMAL resampled to 1 Hz (linear interpolation) for bench-fit",
    );
    let mut k = 0usize;
    let mut ts = t0;
    while ts <= t1 {
        while k + 1 < t.len() && t[k + 1] < ts {
            k += 1;
        }
        if k + 1 >= t.len() {
            break;
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
        ts += 1.0;
    }
    if out.rows() < 100 {
        bail!("resampling gave only {} rows", out.rows());
    }
    Ok(out)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let json = args.iter().any(|a| a == "--json");
    let no_sklearn = args.iter().any(|a| a == "--no-sklearn");
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let data = opt("--data")
        .map(PathBuf::from)
        .unwrap_or_else(default_data);
    let ensemble: usize = opt("--ensemble")
        .map(|s| s.parse())
        .transpose()
        .context("--ensemble")?
        .unwrap_or(NetOpts::default().ensemble);
    let run = Run::read(&data).with_context(|| "FL_THERMAL data (give --data <run.csv>)")?;

    // (a) FL_THERMAL chronological 60/20.
    let t_a = Instant::now();
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
        progress: !json,
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg)?;
    let fl_s = t_a.elapsed().as_secs_f64();
    let mae = |model: &str, ch: &str| {
        rep.models
            .iter()
            .find(|m| m.name == model)
            .and_then(|m| m.channels.get(ch))
            .map(|x| x.mae_um)
    };
    let mut table = Vec::new();
    for (ch, publ) in PUBLISHED {
        let inputs = rep
            .inputs
            .iter()
            .find(|i| i.channel == ch)
            .map(|i| i.features.clone())
            .unwrap_or_default();
        table.push(serde_json::json!({
            "channel": ch, "published_seq2seq_attention_mae_um": publ,
            "mlr_static_mae_um": mae("mlr-static", ch), "mlr_mae_um": mae("mlr", ch),
            "ga_bpn_mae_um": mae("ga-bpn", ch), "inputs": inputs,
        }));
    }

    // (b) 4 h at 1 Hz: GA + LM vs scikit-learn.
    let r4 = resample_1hz(&run, 24.0 * 3600.0, 28.0 * 3600.0)?;
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
    let (members, infos) = train_ensemble(
        &specs,
        ch,
        &inner,
        &block,
        &full,
        &opts,
        &ProgressBar::hidden(),
    );
    let ours_s = t_b.elapsed().as_secs_f64();
    let info = infos.into_iter().next().unwrap_or_default();
    let np = NetEnsemble {
        members: members.iter().collect(),
    };
    let pred: Vec<f64> = test.x.iter().map(|r| np.predict_raw(r)).collect();
    let ours = metrics(&test.y, &pred);

    let mut sk: Option<serde_json::Value> = None;
    let mut sk_err: Option<String> = None;
    if !no_sklearn {
        let dir = std::env::temp_dir().join(format!("bench-fit-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let csv = dir.join("data.csv");
        let mut s = String::new();
        s.push_str(
            &(1..=kinds.len())
                .map(|i| format!("x{i}"))
                .collect::<Vec<_>>()
                .join(","),
        );
        s.push_str(",y,split\n");
        for (set, name) in [(&full, "train"), (&test, "test")] {
            for (r, y) in set.x.iter().zip(&set.y) {
                for (f, v) in specs.iter().zip(r) {
                    s.push_str(&format!("{},", f.normalize(*v)));
                }
                s.push_str(&format!("{y},{name}\n"));
            }
        }
        std::fs::write(&csv, s)?;
        let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/bench-sklearn.py");
        let out = std::process::Command::new(
            std::env::var("PYTHON").unwrap_or_else(|_| "python3".into()),
        )
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
    }
    let sk_s = sk.as_ref().and_then(|v| v["train_s"].as_f64());
    let sk_mae = sk.as_ref().and_then(|v| v["mae_um"].as_f64());
    let timing = serde_json::json!({
        "data": "FL_THERMAL 24-28 h interpolated to 1 Hz, chrono 60/20, channel dch5_um",
        "inputs": specs.iter().map(FeatureSpec::name).collect::<Vec<_>>(),
        "train_rows": full.y.len(), "test_rows": test.y.len(),
        "ours": {"train_s": ours_s, "ga_s": info.ga_s, "lm_s": info.lm_s, "lm_iters": info.lm_iters, "mae_um": ours.mae_um, "rms_um": ours.rms_um},
        "sklearn": sk, "sklearn_error": sk_err,
        "ratio_sklearn_over_ours": sk_s.map(|s| s / ours_s),
    });
    let out =
        serde_json::json!({"fl_thermal": table, "fl_thermal_fit_s": fl_s, "timing_4h_1hz": timing});
    if json {
        println!("{out}");
        return Ok(());
    }
    println!("FL_THERMAL, chronological split (train first 60 %, test next 20 %), test MAE µm");
    println!(
        "{:<9} {:>10} {:>11} {:>8} {:>8}  inputs (ours)",
        "channel", "published", "MLR static", "MLR", "GA-BPN"
    );
    for row in &table {
        let f = |k: &str| {
            row[k]
                .as_f64()
                .map_or("-".to_string(), |v| format!("{v:.2}"))
        };
        println!(
            "{:<9} {:>10} {:>11} {:>8} {:>8}  {}",
            row["channel"].as_str().unwrap_or(""),
            f("published_seq2seq_attention_mae_um"),
            f("mlr_static_mae_um"),
            f("mlr_mae_um"),
            f("ga_bpn_mae_um"),
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
    println!("(published: seq2seq + attention, GPU; fit took {fl_s:.1} s for both channels)\n");
    println!(
        "Training time, 4 h at 1 Hz ({} train rows, {} test rows, 5 inputs, 11 hidden):",
        full.y.len(),
        test.y.len()
    );
    println!(
        "  ours GA + LM      {:>7.2} s (GA {:.2} s, LM {:.2} s, {} steps), test MAE {:.2} µm",
        ours_s, info.ga_s, info.lm_s, info.lm_iters, ours.mae_um
    );
    match (sk_s, sk_mae) {
        (Some(s), Some(m)) => {
            println!("  sklearn MLP (adam){:>7.2} s, test MAE {:.2} µm", s, m);
            println!("  ratio sklearn / ours: {:.2}", s / ours_s);
        }
        _ => println!("  sklearn: {}", sk_err.unwrap_or_else(|| "skipped".into())),
    }
    Ok(())
}

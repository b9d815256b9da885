//! What a fit reports: validation figures per model, channel and held-out
//! run, each channel's inputs and cross-validation, what `export` ships,
//! the fallbacks and the notes; printed as text or serialized for `--json`.

use std::collections::BTreeMap;

use serde::Serialize;

use super::choice::{CvScore, NetInfo};
use super::fallback;
use super::mlr::Metrics;
use super::model::ModelFile;
use super::shipped::{print_shipped, Shipped};
use super::split::Segment;
use super::stability::{Collinearity, Stability};
use crate::select::Selection;

/// Per-run figures.
#[derive(Clone, Debug, Serialize)]
pub struct RunMetrics {
    pub run: String,
    pub channel: String,
    #[serde(flatten)]
    pub metrics: Metrics,
}

#[derive(Clone, Debug, Serialize)]
pub struct ModelReport {
    pub name: String,
    /// Pooled over all validation rows, per channel.
    pub channels: BTreeMap<String, Metrics>,
    pub per_run: Vec<RunMetrics>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ChannelInfo {
    pub channel: String,
    pub features: Vec<String>,
    pub train_rows: usize,
    pub val_rows: usize,
    /// Blocked cross-validation RMS of the MLR on the chosen inputs (training rows only).
    pub cv_rms_um: Option<f64>,
    /// Blocked cross-validation per candidate model (training rows only): what chose it.
    pub cv: BTreeMap<String, CvScore>,
    pub net: Option<NetInfo>,
    /// Per linear candidate, how its coefficients moved across the CV folds
    /// (the stability rule, `stability.rs`).
    pub stability: BTreeMap<String, Stability>,
    /// How collinear the chosen model's inputs are on the training rows
    /// (condition number, largest variance inflation); none for `none`.
    pub collinearity: Option<Collinearity>,
}

#[derive(Clone, Debug, Serialize)]
pub struct FitReport {
    pub models: Vec<ModelReport>,
    /// Per channel, the model cross-validation chose (what `export` ships).
    pub chosen: BTreeMap<String, String>,
    /// What the board's limits ruled out, and how the runs were read.
    pub notes: Vec<String>,
    pub inputs: Vec<ChannelInfo>,
    pub selection: Option<Selection>,
    pub train_segments: Vec<Segment>,
    pub val_segments: Vec<Segment>,
    /// Fallback models per channel and excluded sensor(s), with their figures.
    pub fallbacks: Vec<fallback::FallbackReport>,
    /// Per channel, what `export` ships: the model, the sensors it reads,
    /// and every temperature column it does not read, with why.
    pub shipped: Vec<Shipped>,
    #[serde(skip)]
    pub model_file: ModelFile,
}

/// Plain-text report.
pub fn print_report(r: &FitReport) {
    for n in &r.notes {
        println!("note: {n}");
    }
    if let Some(s) = &r.selection {
        println!("selected sensors (training rows): {}", s.chosen.join(","));
    }
    print_shipped(&r.shipped);
    for i in &r.inputs {
        print!(
            "{}: inputs {} ({} train rows, {} validation rows)",
            i.channel,
            i.features.join(", "),
            i.train_rows,
            i.val_rows
        );
        if let Some(cv) = i.cv_rms_um {
            print!("; training CV RMS {cv:.2} µm");
        }
        if let Some(n) = &i.net {
            print!(
                "; GA {:.1} s, LM {} steps (best {}) {:.1} s",
                n.ga_s, n.lm_iters, n.best_iter, n.lm_s
            );
        }
        println!();
        print_guard(i, r.chosen.get(&i.channel).map_or("?", String::as_str));
    }
    println!();
    println!(
        "{:<11} {:<10} {:>9} {:>9} {:>9} {:>9} {:>10}",
        "model", "channel", "MAE µm", "RMS µm", "peak µm", "raw RMS", "reduction"
    );
    for m in &r.models {
        for (ch, x) in &m.channels {
            println!(
                "{:<11} {:<10} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.1}%",
                m.name, ch, x.mae_um, x.rms_um, x.peak_um, x.raw_rms_um, x.reduction_pct
            );
        }
    }
    if !r.fallbacks.is_empty() {
        println!("\nfallback models (degraded mode; validation rows):");
        for f in &r.fallbacks {
            let cv = f.cv.get(&f.model).map_or(f64::NAN, |c| c.rms_um);
            println!(
                "{:<10} without {:<16} {:<10} CV RMS {:>6.2} µm, RMS {:>6.2} µm, reduction {:>5.1}%  ({})",
                f.channel,
                f.excluded.join("+"),
                f.model,
                cv,
                f.validation.rms_um,
                f.validation.reduction_pct,
                f.features.join(", ")
            );
        }
    }
    let runs: std::collections::BTreeSet<&str> = r
        .models
        .iter()
        .flat_map(|m| m.per_run.iter().map(|p| p.run.as_str()))
        .collect();
    if runs.len() > 1 {
        println!("\nper held-out run:");
        for m in &r.models {
            for p in &m.per_run {
                println!(
                    "{:<11} {:<10} {:>9.2} {:>9.2} {:>9.2} {:>9.1}%  {}",
                    m.name,
                    p.channel,
                    p.metrics.mae_um,
                    p.metrics.rms_um,
                    p.metrics.peak_um,
                    p.metrics.reduction_pct,
                    p.run
                );
            }
        }
    }
}

/// The ridge's penalty, the chosen model's collinearity and every linear
/// candidate the stability rule finds unstable, one line.
fn print_guard(i: &ChannelInfo, chosen: &str) {
    let mut parts = vec![format!("chosen {chosen}")];
    if let Some(c) = &i.collinearity {
        let f = |v: Option<f64>| v.map_or("∞".to_string(), |v| format!("{v:.1}"));
        parts.push(format!(
            "inputs' condition number {}, max VIF {} ({})",
            f(c.condition_number),
            f(c.max_vif),
            c.max_vif_input.as_deref().unwrap_or("-")
        ));
    }
    if let Some(l) = i.cv.get("ridge").and_then(|s| s.penalty) {
        parts.push(format!("ridge penalty {l:.0e}"));
    }
    for (name, s) in i.stability.iter().filter(|(_, s)| !s.stable) {
        let input = s.worst_input.as_deref().unwrap_or("?");
        parts.push(match s.worst_factor {
            Some(f) if !s.sign_flip => format!("{name} unstable ({input} ×{f:.1} across folds)"),
            _ => format!("{name} unstable ({input} flips sign across folds)"),
        });
    }
    println!("  {}", parts.join("; "));
}

/// `{"models": [{"name", "channels": {...}}], ...}` (validation figures only).
pub fn report_json(r: &FitReport) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

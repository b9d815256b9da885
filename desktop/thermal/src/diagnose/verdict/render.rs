//! Rendering of a diagnosis: the markdown report and its SVG plots
//! (held-out residual by channel and by operating phase, before and after
//! the selected effect).

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use serde_json::Value;

use crate::diagnose::effects::periodic_claim;
use crate::diagnose::types::Diagnosis;
pub use crate::diagnose::types::SelectedGaps;

fn f2(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "–".into()
    }
}

/// The report's paragraph on an ambiguous answer: the explanations the
/// held-out data cannot separate and the measurement that would.
fn ambiguous_md(d: &Diagnosis) -> String {
    let mut s = format!(
        "**Ambiguous: the held-out data cannot separate {}** (ranked; the first explains the most, but not significantly more than the others): nothing is named as the cause. A measurement that would separate them:\n\n",
        d.ambiguous
            .iter()
            .map(|n| format!("`{n}`"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for m in &d.separate_by {
        s += &format!("- {m}\n");
    }
    s + "\n"
}

/// The report's paragraph when nothing is named: an ambiguous answer, or
/// no supported effect and the evidence for "no effect".
fn nothing_named_md(d: &Diagnosis) -> String {
    if !d.ambiguous.is_empty() {
        return ambiguous_md(d);
    }
    let mut s =
        "**No candidate effect is supported by the data** (BIC and held-out margin guards).\n\n"
            .to_string();
    if let Some(o) = d.no_effect.as_object() {
        s += &format!(
            "Evidence for \"no effect\": worst held-out RMS / noise {}, white residuals in {} of {} channels ({}).\n\n",
            o.get("worst_rms_over_noise").unwrap_or(&Value::Null),
            o.get("white_channels").unwrap_or(&Value::Null),
            o.get("tested_channels").unwrap_or(&Value::Null),
            o.get("rule").and_then(Value::as_str).unwrap_or("")
        );
    }
    s
}

/// Markdown report.
pub fn report_md(d: &Diagnosis, run_names: &[String]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "# Sim-to-real gap diagnosis — machine `{}`\n", d.machine);
    let _ = writeln!(s, "Runs: {}\n", run_names.join(", "));
    let _ = writeln!(
        s,
        "Nominal model, held-out data: RMS gap {} µm (peak {}), {} °C (peak {}); normalised gap {} (1 ≈ sensor noise).\n",
        d.nominal_gap_um.map_or("–".into(), |g| f2(g.0)),
        d.nominal_gap_um.map_or("–".into(), |g| f2(g.1)),
        d.nominal_gap_c.map_or("–".into(), |g| f2(g.0)),
        d.nominal_gap_c.map_or("–".into(), |g| f2(g.1)),
        f2(d.nominal_m_held.sqrt())
    );
    for m in &d.missing {
        let _ = writeln!(s, "- **Missing:** {m}");
    }
    if !d.missing.is_empty() {
        let _ = writeln!(s);
    }
    if let Some(o) = d.nominal.as_object() {
        let _ = writeln!(s, "## Nominal model\n");
        for (k, v) in o {
            let _ = writeln!(s, "- {k}: {v}");
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "## Which effect\n");
    let _ = writeln!(s, "Ranking rule: {}\n", d.ranking_rule);
    if d.findings.is_empty() {
        s.push_str(&nothing_named_md(d));
    } else {
        let _ = writeln!(s, "| rank | effect | params | held-out gap µm before → after | °C before → after | ΔBIC | signature r | driver r |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
        for (i, f) in d.findings.iter().enumerate() {
            let _ = writeln!(
                s,
                "| {} | **{}** | `{}` | {} → {} | {} → {} | {:.1} | {} | {} |",
                i + 1,
                f.name,
                f.params_json(),
                f.gap_um.map_or("–".into(), |g| f2(g.0 .0)),
                f.gap_um.map_or("–".into(), |g| f2(g.1 .0)),
                f.gap_c.map_or("–".into(), |g| f2(g.0 .0)),
                f.gap_c.map_or("–".into(), |g| f2(g.1 .0)),
                f.dbic,
                f.evidence
                    .get("signature_corr")
                    .cloned()
                    .unwrap_or(Value::Null),
                f.evidence
                    .get("driver_corr")
                    .cloned()
                    .unwrap_or(Value::Null),
            );
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "### All single candidates tried\n");
    let _ = writeln!(s, "| effect | fitted params | ΔBIC (fit part) | held-out norm. gap before → after | µm after | °C after |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for f in &d.tried {
        let _ = writeln!(
            s,
            "| {} | `{}` | {:.1} | {} → {} | {} | {} |",
            f.name,
            f.params_json(),
            f.dbic,
            f2(f.m_before.sqrt()),
            f2(f.m_after.sqrt()),
            f.gap_um.map_or("–".into(), |g| f2(g.1 .0)),
            f.gap_c.map_or("–".into(), |g| f2(g.1 .0)),
        );
    }
    // periodic drivers (periodic_claim.rs)
    s.push_str(&periodic_claim::report_md(&d.tried));
    let _ = writeln!(s, "\n## Where the gap lies (nominal model, all rows)\n");
    let w = &d.where_;
    for (title, key, unit) in [
        ("Per sensor", "sensors", "°C"),
        ("Per direction", "directions", "µm"),
    ] {
        if let Some(o) = w.get(key).and_then(|v| v.as_object()) {
            if o.is_empty() {
                continue;
            }
            let _ = writeln!(
                s,
                "### {title} ({unit})\n\n| channel | RMS | peak | mean |\n|---|---|---|---|"
            );
            for (k, v) in o {
                let _ = writeln!(s, "| {k} | {} | {} | {} |", v["rms"], v["peak"], v["mean"]);
            }
            let _ = writeln!(s);
        }
    }
    if let Some(o) = w.get("phases").and_then(|v| v.as_object()) {
        let _ = writeln!(
            s,
            "### Per operating phase\n\n| phase | rows | RMS °C | RMS µm |\n|---|---|---|---|"
        );
        for (k, v) in o {
            let _ = writeln!(
                s,
                "| {k} | {} | {} | {} |",
                v["rows"], v["rms_c"], v["rms_um"]
            );
        }
        let _ = writeln!(s);
    }
    if let Some(o) = w.get("bands").and_then(|v| v.as_object()) {
        let _ = writeln!(s, "### Per frequency band (moving-average split)\n\n| band | RMS °C | RMS µm |\n|---|---|---|");
        for (k, v) in o {
            let _ = writeln!(s, "| {k} | {} | {} |", v["rms_c"], v["rms_um"]);
        }
        let _ = writeln!(s);
    }
    if !d.untestable.is_empty() {
        let _ = writeln!(s, "## What these data cannot test\n");
        for (n, r) in &d.untestable {
            let _ = writeln!(s, "- **{n}**: {r}");
        }
        let _ = writeln!(s);
    }
    if !d.notes.is_empty() {
        let _ = writeln!(s, "## Notes\n");
        for n in &d.notes {
            let _ = writeln!(s, "- {n}");
        }
    }
    let _ = writeln!(
        s,
        "\n_{} candidate fits (simulations with a machine file) in {:.2} s._",
        d.sims, d.seconds
    );
    s
}

/// Write the markdown report at `path` and its SVG plots beside it
/// (`<stem>-channels.svg`, `<stem>-phases.svg`) when an effect was selected.
pub fn write_report(
    d: &Diagnosis,
    run_names: &[String],
    path: &Path,
) -> Result<Vec<std::path::PathBuf>> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !dir.is_dir() {
        return Err(anyhow!("report directory {} does not exist", dir.display()));
    }
    let mut md = report_md(d, run_names);
    let mut files = vec![path.to_path_buf()];
    if let Some(g) = &d.selected_gaps {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("diagnosis");
        let ch = dir.join(format!("{stem}-channels.svg"));
        let bars: Vec<(String, f64, f64)> = g
            .channels
            .iter()
            .map(|(n, disp, b, a)| (format!("{n} {}", if *disp { "µm" } else { "°C" }), *b, *a))
            .collect();
        bar_pairs(
            &ch,
            &format!(
                "Held-out RMS residual by channel, before / after {}",
                g.effect
            ),
            &bars,
        )?;
        let ph = dir.join(format!("{stem}-phases.svg"));
        bar_pairs(
            &ph,
            &format!(
                "Held-out RMS residual (°C) by operating phase, before / after {}",
                g.effect
            ),
            &g.phases,
        )?;
        md.push_str(&format!(
            "\n## Residual before and after `{}`\n\n![by channel]({})\n\n![by phase]({})\n",
            g.effect,
            ch.file_name().and_then(|s| s.to_str()).unwrap_or(""),
            ph.file_name().and_then(|s| s.to_str()).unwrap_or("")
        ));
        files.push(ch);
        files.push(ph);
    }
    std::fs::write(path, md).map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
    Ok(files)
}

/// Grey (before) and blue (after) bars per label.
fn bar_pairs(path: &Path, title: &str, bars: &[(String, f64, f64)]) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let top = bars
        .iter()
        .map(|b| b.1.max(b.2))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(1e-6);
    let root = SVGBackend::new(path, (960, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let n = bars.len().max(1);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(60)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..n as f64, 0.0..top * 1.1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc("held-out RMS")
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (label, b, a)) in bars.iter().enumerate() {
        let x = i as f64;
        let (b, a) = (
            if b.is_finite() { *b } else { 0.0 },
            if a.is_finite() { *a } else { 0.0 },
        );
        chart
            .draw_series([
                Rectangle::new(
                    [(x + 0.1, 0.0), (x + 0.45, b)],
                    RGBColor(160, 160, 160).filled(),
                ),
                Rectangle::new(
                    [(x + 0.5, 0.0), (x + 0.85, a)],
                    RGBColor(31, 119, 180).filled(),
                ),
            ])
            .map_err(|e| err(&e))?;
        chart
            .draw_series(std::iter::once(Text::new(
                label.clone(),
                (x + 0.1, -top * 0.04),
                ("sans-serif", 10),
            )))
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

//! `tcomp report`: SVG plots of a run — temperatures, measured error against
//! the board's served correction, the residual before and after
//! compensation, and the sensor clusters `select` forms. Predictions come
//! from `replay` (the board's own fixed-point output), so the plots show what
//! the machine would have seen.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use tcomp_data::runcsv::Run;

const SIZE: (u32, u32) = (1000, 560);

fn palette(i: usize) -> RGBColor {
    let c = Palette99::pick(i).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// One chart of several named series over time (hours).
fn line_chart(
    path: &Path,
    title: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (_, pts) in series {
        for &(x, y) in pts {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        return Err(anyhow!("{title}: nothing to plot"));
    }
    let pad = ((y1 - y0) * 0.05).max(1e-3);
    let root = SVGBackend::new(path, SIZE).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1.max(x0 + 1e-6), (y0 - pad)..(y1 + pad))
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("time (h)")
        .y_desc(y_label)
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = palette(i);
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), &color))
            .map_err(|e| err(&e))?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

fn series(run: &Run, col: &str, hours: &[f64]) -> Vec<(f64, f64)> {
    run.col(col)
        .map(|v| {
            hours
                .iter()
                .zip(v)
                .filter_map(|(&t, y)| y.map(|y| (t, y)))
                .collect()
        })
        .unwrap_or_default()
}

/// Write the report's plots into `dir`; returns the files written.
pub fn report(
    run_path: &Path,
    image: Option<&Path>,
    clusters: bool,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let run = Run::read_with_temperatures(run_path)?;
    // Every input is checked before the first file is written.
    let replayed = match image {
        Some(image) => {
            let bytes =
                std::fs::read(image).with_context(|| format!("reading {}", image.display()))?;
            let model = thermocomp_core::Model::parse(&bytes)
                .map_err(|e| anyhow!("{}: {e}", image.display()))?;
            let rows = crate::replay::replay_files(run_path, image)
                .with_context(|| format!("in run file {}", run_path.display()))?;
            Some((model, rows))
        }
        None => None,
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let hours: Vec<f64> = run.time_s().iter().map(|t| t / 3600.0).collect();
    let mut files = vec![];
    let temps: Vec<(String, Vec<(f64, f64)>)> = run
        .temperature_columns()
        .iter()
        .map(|c| (c.to_string(), series(&run, c, &hours)))
        .collect();
    let p = dir.join("temperatures.svg");
    line_chart(&p, "Temperatures", "°C", &temps)?;
    files.push(p);
    if let Some((model, rows)) = replayed {
        for d in 0..model.directions.len() {
            let col = format!("d{}_um", model.direction_name(d));
            let measured = series(&run, &col, &hours);
            if measured.is_empty() {
                continue;
            }
            let served: Vec<(f64, f64)> = rows
                .iter()
                .zip(&hours)
                .map(|(r, &t)| (t, f64::from(r.out.corrections[d]) / 10.0))
                .collect();
            let p = dir.join(format!("error_{col}.svg"));
            line_chart(
                &p,
                &format!("{col}: measured thermal error and the board's correction"),
                "µm",
                &[
                    ("measured".into(), measured.clone()),
                    ("served correction".into(), served),
                ],
            )?;
            files.push(p);
            let after: Vec<(f64, f64)> = rows
                .iter()
                .zip(&hours)
                .zip(run.col(&col).unwrap_or(&[]))
                .filter_map(|((r, &t), m)| {
                    m.map(|m| (t, m - f64::from(r.out.corrections[d]) / 10.0))
                })
                .collect();
            let p = dir.join(format!("residual_{col}.svg"));
            line_chart(
                &p,
                &format!("{col}: error before and after compensation"),
                "µm",
                &[
                    ("before (measured)".into(), measured),
                    ("after (measured − correction)".into(), after),
                ],
            )?;
            files.push(p);
        }
    }
    if clusters {
        let sel = crate::select::select(std::slice::from_ref(&run), 5, 0)?;
        let p = dir.join("clusters.svg");
        cluster_map(&p, &sel)?;
        files.push(p);
    }
    Ok(files)
}

/// Sensors by group (x) and correlation score (y); the chosen one per group ringed.
fn cluster_map(path: &Path, sel: &crate::select::Selection) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let max_score = sel.scores.values().cloned().fold(0.0, f64::max).max(1e-6);
    let root = SVGBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Temperature-sensitive points: K-means++ groups and correlation scores",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            -0.5..(sel.clusters.len() as f64 - 0.5),
            0.0..max_score * 1.15,
        )
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("group")
        .y_desc("Σ|r| over error directions")
        .draw()
        .map_err(|e| err(&e))?;
    for (g, members) in sel.clusters.iter().enumerate() {
        let color = palette(g);
        for (k, name) in members.iter().enumerate() {
            let score = sel.scores.get(name).copied().unwrap_or(0.0);
            let x = g as f64 + (k as f64 - members.len() as f64 / 2.0) * 0.06;
            chart
                .draw_series(std::iter::once(Circle::new((x, score), 5, color.filled())))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    name.clone(),
                    (x, score),
                    ("sans-serif", 12),
                )))
                .map_err(|e| err(&e))?;
            if sel.chosen.contains(name) {
                chart
                    .draw_series(std::iter::once(Circle::new(
                        (x, score),
                        10,
                        BLACK.stroke_width(2),
                    )))
                    .map_err(|e| err(&e))?;
            }
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

//! Plan rich against plan 14 on machines the identifier was not told the
//! class of (issue 49 item 1): `desktop/tcomp/tests/data/geometry_rich_gen.py`
//! (degree-5 polynomials plus waves for every error, per-line laser scale
//! 0.5 ppm, exact transforms, σ 0.5 µm) writes each machine's lines of
//! either plan (`--plan FILE`; the same machine and the same 20 held-out
//! lines for both), `smooth::identify_smooth` (the generic identifier of
//! `identify --method smooth`, its default degree) identifies it, and
//! `score` compares with the tabulated truth and the held-out lines.
//! Prints per machine and the worst machine: worst-term RMS [µm, µrad],
//! held-out reduction [%], and pooled over the machines.
//! With a method name (`poly`, `smooth`, `dense`, `generic`; default
//! `smooth`) that identifier is scored; for `poly` and `generic` also the
//! share of terms × positions (20 per stroke, squareness) whose true error
//! is within 3 printed σ (the σ's as `identify` prints them: the stated
//! 0.5 µm noise's posterior × the misfit inflation) and whether the stated
//! adequacy test passes.
//! `plans=NAME,NAME` picks the plans (`14`, `rich`, `rich-optics`: the rich
//! plan with one straightness-optics line, `plan_optics`; default 14,rich).
//! `cargo run -p tcomp-geometry --release --example plan_bench [-- MACHINES FIRST_SEED [METHOD] [plans=…]]`

use anyhow::{bail, Result};
use std::path::Path;
use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::bench_rich::{identify_with, Method};
use tcomp_geometry::errors::{GeometricErrors, Term};
use tcomp_geometry::identify::{
    identify, line_adequacy, squareness_sigma, term_sigma, LineKind, LineObs,
};
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::{average_runs, plan14, LineSpec};
use tcomp_geometry::plan::rich_lines;
use tcomp_geometry::plan_optics::rich_optics_lines;
use tcomp_geometry::score::{read_dir_lines, score, TabulatedTruth};
use tcomp_geometry::shape_free::coverage_3sigma;

const STROKE: [f64; 3] = [800.0, 500.0, 400.0];

fn write_plan(path: &Path, lines: &[LineSpec]) -> Result<()> {
    let v: Vec<serde_json::Value> = lines
        .iter()
        .map(|l| {
            let e = [0, 1, 2].map(|k| l.start_mm[k] + l.length_mm * l.direction[k]);
            let mut v = serde_json::json!({"line": l.id, "start_mm": l.start_mm, "end_mm": e,
                "tool_offset_mm": l.tool_offset_mm});
            if l.kind == LineKind::Straightness {
                v["sense"] = serde_json::json!(l.sense);
            }
            v
        })
        .collect();
    std::fs::write(path, serde_json::to_string(&v)?)?;
    Ok(())
}

fn generate(dir: &Path, plan: &Path, seed: u64) -> Result<()> {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tcomp/tests/data/geometry_rich_gen.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(["--seed", &seed.to_string(), "--noise-um", "0.5", "--plan"])
        .arg(plan)
        .arg("--out")
        .arg(dir)
        .output()?;
    if !out.status.success() {
        bail!("{}", String::from_utf8_lossy(&out.stderr));
    }
    Ok(())
}

/// 3σ coverage [%] of the printed σ's and the adequacy verdict (poly and
/// generic; None for the others).
fn coverage(
    method: Method,
    st: &Structure,
    obs: &[LineObs],
    model: &GeometricErrors,
    truth: &TabulatedTruth,
) -> Result<Option<(f64, bool)>> {
    let stroke = truth.stroke_mm;
    let noise = StatedNoise::new(Some(0.5))?;
    let line_sigma = vec![0.5 / 2f64.sqrt(); obs.len()];
    let sigma: Box<dyn Fn(Option<Term>, usize, f64) -> f64>;
    let adequate;
    match method {
        Method::Generic => {
            let g = tcomp_geometry::generic::identify_generic(st, obs, stroke)?;
            let adq = g.adequacy(&line_sigma, noise);
            let f = adq.sigma_inflation;
            adequate = adq.adequate;
            sigma = Box::new(move |t, i, q| match t {
                Some(t) => f * g.sigma(t, q),
                None => f * g.squareness_sigma(i),
            });
        }
        Method::Poly => {
            let id = identify(st, obs, Default::default(), stroke)?;
            let (adq, cov) = line_adequacy(st, obs, &id, &line_sigma, noise)?;
            let f = adq.sigma_inflation;
            adequate = adq.adequate;
            sigma = Box::new(move |t, i, q| match t {
                Some(t) => f * term_sigma(&id.basis, &cov, t, q),
                None => f * squareness_sigma(&id.basis, &cov, i),
            });
        }
        _ => return Ok(None),
    }
    Ok(Some((coverage_3sigma(model, truth, sigma), adequate)))
}

struct Row {
    seed: u64,
    wt: f64,
    wa: f64,
    /// The errors with the worst RMS (translational, angular).
    worst_terms: (String, String),
    before: f64,
    after: f64,
    pct: f64,
    unobservable: usize,
    cover: Option<(f64, bool)>,
}

fn main() -> Result<()> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let machines = args.first().copied().unwrap_or(10);
    let first = args.get(1).copied().unwrap_or(101);
    let base = std::env::temp_dir().join(format!("plan-bench-{}", std::process::id()));
    std::fs::create_dir_all(&base)?;
    let names = std::env::args()
        .skip(1)
        .find_map(|a| a.strip_prefix("plans=").map(str::to_string))
        .unwrap_or_else(|| "14,rich".into());
    let mut plans = Vec::new();
    for n in names.split(',') {
        let lines = match n {
            "14" => plan14(STROKE, 100.0, 100.0),
            "rich" => rich_lines(STROKE, 100.0, 100.0),
            "rich-optics" => rich_optics_lines(STROKE, 100.0, 100.0),
            _ => bail!("plans={n}: 14, rich or rich-optics"),
        };
        plans.push((n, lines));
    }
    let method = std::env::args()
        .skip(1)
        .find(|a| a.parse::<u64>().is_err() && !a.starts_with("plans="))
        .map_or(Ok(Method::Smooth), |m| Method::parse(&m))?;
    for (name, lines) in &plans {
        let pf = base.join(format!("plan_{name}.json"));
        write_plan(&pf, lines)?;
        let mut rows = Vec::new();
        for seed in first..first + machines {
            let dir = base.join(format!("{name}_{seed}"));
            generate(&dir, &pf, seed)?;
            let files = read_dir_lines(&dir)?;
            let st = files[0].structure.clone();
            let obs: Vec<LineObs> = average_runs(&files)?.into_iter().map(|a| a.obs).collect();
            let truth = TabulatedTruth::read(&dir.join("truth.json"))?;
            let held = read_dir_lines(&dir.join("heldout"))?;
            let (model, fit) = identify_with(method, &st, &obs, truth.stroke_mm)?;
            let cover = coverage(method, &st, &obs, &model, &truth)?;
            let s = score(&st, &model, &truth, &held);
            let h = s.heldout.unwrap();
            let worst_of = |angular: bool| {
                (s.terms.iter())
                    .filter(|(n, _)| n[1..2].contains(['A', 'B', 'C']) == angular)
                    .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
                    .map_or(String::new(), |(n, _)| n.clone())
            };
            let row = Row {
                seed,
                wt: s.worst_rms_translational_um,
                wa: s.worst_rms_angular_urad,
                worst_terms: (worst_of(false), worst_of(true)),
                before: h.before_um,
                after: h.after_um,
                pct: h.reduction_pct,
                unobservable: fit.map_or(0, |f| f.unobservable_terms.len()),
                cover,
            };
            let cv = row.cover.map_or(String::new(), |(c, a)| {
                format!(
                    ", 3σ covers {c:.1} %, {}",
                    if a { "adequate" } else { "INADEQUATE" }
                )
            });
            println!(
                "plan {name:4} seed {:3}: worst-term RMS {:5.2} µm ({}) / {:5.2} µrad ({}), held-out {:5.1} % ({:.2} → {:.2} µm), undetermined {}{cv}",
                row.seed, row.wt, row.worst_terms.0, row.wa, row.worst_terms.1, row.pct, row.before, row.after, row.unobservable
            );
            let _ = std::fs::remove_dir_all(&dir);
            rows.push(row);
        }
        let worst = |f: fn(&Row) -> f64| rows.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
        let b2: f64 = rows.iter().map(|r| r.before * r.before).sum();
        let a2: f64 = rows.iter().map(|r| r.after * r.after).sum();
        let pooled = 100.0 * (1.0 - (a2 / b2).sqrt());
        let worst_pct = rows.iter().map(|r| r.pct).fold(f64::INFINITY, f64::min);
        let covers: Vec<(f64, bool)> = rows.iter().filter_map(|r| r.cover).collect();
        let cv = if covers.is_empty() {
            String::new()
        } else {
            let mean = covers.iter().map(|c| c.0).sum::<f64>() / covers.len() as f64;
            let ok = covers.iter().filter(|c| c.1).count();
            format!(
                "; 3σ covers {mean:.1} % (mean over machines), adequate {ok} of {}",
                covers.len()
            )
        };
        println!(
            "PLAN {name} ({} lines), {} machines (seeds {first}..{}), method {method:?}: worst-term RMS, worst machine {:.2} µm / {:.2} µrad; held-out pooled {:.1} % (worst machine {:.1} %){cv}",
            lines.len(),
            rows.len(),
            first + machines - 1,
            worst(|r| r.wt),
            worst(|r| r.wa),
            pooled,
            worst_pct
        );
    }
    let _ = std::fs::remove_dir_all(&base);
    Ok(())
}

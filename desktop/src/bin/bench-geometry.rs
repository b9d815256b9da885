//! `bench-geometry [--json] [--seeds N]`: identification accuracy of the
//! 14-line method vs reading noise. Per noise level, N random machines
//! (default model degrees) are measured along the 14 lines with setup errors
//! (beam misalignment 200 µrad, reflector offset 1 mm, lost motion), written
//! to line files, read back and identified. Prints per term group the max
//! and RMS recovery error (worst over the machines) and the RMS tool-point
//! error over a held-out 6×6×6 grid before and after compensation.
use std::collections::BTreeMap;
use tcomp::fit::rng::Rng;
use tcomp::geometry::cli::{recovery, volumetric_residual};
use tcomp::geometry::identify::{identify, Degrees, LineObs};
use tcomp::geometry::lines::{average_runs, plan14, LineFile};
use tcomp::geometry::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp::geometry::{Structure, Term};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let json = args.iter().any(|a| a == "--json");
    let seeds: u64 = args
        .iter()
        .position(|a| a == "--seeds")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let stroke = [800.0, 500.0, 400.0];
    let st = Structure::parse("XY/Z")?;
    let plan = plan14(stroke, 100.0, 100.0);
    // The readings go through real files, as a user's would.
    let dir = std::env::temp_dir().join(format!("bench-geometry-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let t0 = std::time::Instant::now();
    let mut rows = Vec::new();
    for noise in [0.0, 0.1, 0.25, 0.5, 1.0, 2.0] {
        let mut worst: BTreeMap<&str, (f64, f64)> = BTreeMap::new();
        let (mut before, mut after, mut worst_red) = (0.0, 0.0, f64::INFINITY);
        let mut cond = 0.0;
        for seed in 0..seeds {
            let mut rng = Rng::new(1000 + seed);
            let truth = random_errors(stroke, &ErrorSizes::default(), &mut rng);
            let setup = MeasurementSetup {
                noise_um: noise,
                targets: 41,
                ..Default::default()
            };
            let mut files = Vec::new();
            for spec in &plan {
                for f in measure_line(&st, &truth, spec, &setup, None, &mut rng) {
                    let p = dir.join(format!("{}_{:?}.csv", spec.id, f.run));
                    f.write(&p)?;
                    files.push(LineFile::read(&p)?);
                }
            }
            let obs: Vec<LineObs> = average_runs(&files)?.into_iter().map(|a| a.obs).collect();
            let id = identify(&st, &obs, Degrees::default(), stroke)?;
            cond = id.condition_number;
            for (name, (mx, rms, _)) in recovery(&id.errors, &truth, stroke) {
                let t = Term::parse(&name).expect("own term name");
                let group = if t.component.is_angular() {
                    "angular_urad"
                } else {
                    "translational_um"
                };
                let w = worst.entry(group).or_insert((0.0, 0.0));
                w.0 = f64::max(w.0, mx);
                w.1 = f64::max(w.1, rms);
            }
            let (b, a) = volumetric_residual(&st, &id.errors, &truth, stroke);
            before += b / seeds as f64;
            after += a / seeds as f64;
            worst_red = f64::min(worst_red, 100.0 * (1.0 - a / b));
        }
        rows.push(serde_json::json!({
            "noise_um": noise,
            "translational_um": {"max": worst["translational_um"].0, "rms": worst["translational_um"].1},
            "angular_urad": {"max": worst["angular_urad"].0, "rms": worst["angular_urad"].1},
            "volumetric_rms_um": {"before": before, "after": after,
                "reduction_pct": 100.0 * (1.0 - after / before), "worst_reduction_pct": worst_red},
            "condition_number": cond,
        }));
    }
    let el = t0.elapsed().as_secs_f64();
    std::fs::remove_dir_all(&dir)?;
    if json {
        println!(
            "{}",
            serde_json::json!({"machines_per_level": seeds, "lines": 14, "rows": rows, "seconds": el})
        );
        return Ok(());
    }
    println!("14-line identification, {seeds} random machines per noise level (worst over machines), {el:.1} s");
    println!("noise µm | transl. max/RMS µm | angular max/RMS µrad | tool point RMS before → after µm (mean; worst reduction)");
    for r in &rows {
        println!(
            "{:8.2} | {:6.2} / {:5.2} | {:6.2} / {:5.2} | {:5.2} → {:5.2} ({:.1} %; worst {:.1} %)",
            r["noise_um"].as_f64().unwrap_or(0.0),
            r["translational_um"]["max"].as_f64().unwrap_or(0.0),
            r["translational_um"]["rms"].as_f64().unwrap_or(0.0),
            r["angular_urad"]["max"].as_f64().unwrap_or(0.0),
            r["angular_urad"]["rms"].as_f64().unwrap_or(0.0),
            r["volumetric_rms_um"]["before"].as_f64().unwrap_or(0.0),
            r["volumetric_rms_um"]["after"].as_f64().unwrap_or(0.0),
            r["volumetric_rms_um"]["reduction_pct"]
                .as_f64()
                .unwrap_or(0.0),
            r["volumetric_rms_um"]["worst_reduction_pct"]
                .as_f64()
                .unwrap_or(0.0),
        );
    }
    Ok(())
}

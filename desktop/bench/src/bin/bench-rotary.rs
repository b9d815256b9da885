//! `bench-rotary [--json] [--seeds N] [--noise-um S] [--thermal-cycles K]`:
//! the five-axis chain of issue 31 on N random machines (default 10,
//! σ = 0.5 µm on every reading): linear errors identified from 14 simulated
//! lines, R-test files of the default plan (3 nests, 129 poses each)
//! written and read back, the eight location errors identified together
//! with the component errors and a constant per file, then the tool-tip
//! error over the held-out grid (27 positions × A −90…90° × C 0…315° × 2
//! tools) before and after. Prints the worst location-error recovery, the
//! component errors' RMS recovery and the grid reduction; with
//! `--thermal-cycles K` (e.g. 18) the location errors drift with three
//! sensors over a warm-up and the grid is scored at four held-out states
//! of the cool-down after it. `--linear-known`: the true linear errors
//! instead of the 14-line identification (isolates the rotary fit).
use tcomp_geometry::rotary_check::run_case;

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(|| {
        let args: Vec<String> = std::env::args().skip(1).collect();
        tcomp_data::cli_error::check_args(
            &args,
            &["--json", "--linear-known"],
            &["--seeds", "--noise-um", "--thermal-cycles"],
        )?;
        let val = |k: &str, d: f64| -> anyhow::Result<f64> {
            match args.iter().position(|a| a == k) {
                Some(i) => args
                    .get(i + 1)
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| anyhow::anyhow!("{k} needs a number")),
                None => Ok(d),
            }
        };
        let (seeds, noise, cycles) = (
            val("--seeds", 10.0)? as u64,
            val("--noise-um", 0.5)?,
            val("--thermal-cycles", 0.0)? as usize,
        );
        let json = args.iter().any(|a| a == "--json");
        let mut cases = Vec::new();
        for seed in 1..=seeds {
            let c = run_case(
                1000 + seed,
                noise,
                cycles,
                args.iter().any(|a| a == "--linear-known"),
            )?;
            if !json {
                println!(
                    "machine {:2}: location worst {:.2} µm / {:.2} µrad; components rms {:.2} of {:.2} µm, {:.2} of {:.2} µrad; cond {:.0}; grid {:.2} → {:.2} µm ({:.1} %), linear model only {:.2} µm ({:.1} %)",
                    c.seed, c.worst_um, c.worst_urad, c.component_rms_um.0, c.component_rms_um.1,
                    c.component_rms_urad.0, c.component_rms_urad.1, c.condition_number.unwrap_or(f64::INFINITY),
                    c.grid.before_rms_um, c.grid.after_rms_um, c.grid.reduction_pct,
                    c.grid_linear_only.after_rms_um, c.grid_linear_only.reduction_pct
                );
            }
            cases.push(c);
        }
        let worst = |f: fn(&tcomp_geometry::rotary_check::CaseFigures) -> f64| {
            cases.iter().map(f).fold(0.0, f64::max)
        };
        let least = |f: fn(&tcomp_geometry::rotary_check::CaseFigures) -> f64| {
            cases.iter().map(f).fold(f64::INFINITY, f64::min)
        };
        let summary = serde_json::json!({
            "machines": cases.len(), "noise_um": noise, "thermal_cycles": cycles,
            "location_worst_um": worst(|c| c.worst_um), "location_worst_urad": worst(|c| c.worst_urad),
            "component_rms_um_worst": worst(|c| c.component_rms_um.0), "component_true_rms_um_mean": cases.iter().map(|c| c.component_rms_um.1).sum::<f64>() / cases.len().max(1) as f64,
            "component_rms_urad_worst": worst(|c| c.component_rms_urad.0), "component_true_rms_urad_mean": cases.iter().map(|c| c.component_rms_urad.1).sum::<f64>() / cases.len().max(1) as f64,
            "grid_reduction_pct_least": least(|c| c.grid.reduction_pct),
            "grid_linear_only_reduction_pct_least": least(|c| c.grid_linear_only.reduction_pct),
            "unobservable": cases.iter().flat_map(|c| c.unobservable.clone()).collect::<Vec<_>>(),
        });
        if json {
            println!(
                "{}",
                serde_json::json!({"summary": summary, "cases": cases})
            );
        } else {
            println!("{summary:#}");
        }
        Ok(())
    })
}

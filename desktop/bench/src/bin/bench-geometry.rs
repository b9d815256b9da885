//! `bench-geometry [--json] [--seeds N]`: identification accuracy of the
//! 14-line method vs reading noise. Per noise level, N random machines
//! (default model degrees) are measured along the 14 lines with setup errors
//! (beam misalignment 200 µrad, reflector offset 1 mm, lost motion), written
//! to line files, read back and identified. Prints per term group the max
//! and RMS recovery error (worst over the machines) and the RMS tool-point
//! error over a held-out 6×6×6 grid before and after compensation.
//!
//! The board slice (issue 14 item 4): the volumetric section of a random
//! machine's static geometry (`geometry table`) and a dense thermal one
//! (all 52 monomials, constant and per kelvin of three sensors: 208 terms)
//! are exported through `tcomp export`'s path, their quantisation error
//! reported (served vs f64 polynomial over a grid, with the stated bound),
//! and the instructions of one evaluation counted on the QEMU bench
//! firmware (`bench` mode, `-icount shift=0`, the method of
//! `scripts/bench-firmware.sh`). `--firmware <elf>` names the firmware
//! (default `target/thumbv7em-none-eabihf/firmware/board-qemu-mps2`; build it
//! with `cargo build -p board-qemu-mps2 --profile firmware --target
//! thumbv7em-none-eabihf`); `--board-only` skips the identification.
use std::collections::BTreeMap;
use std::path::PathBuf;
use tcomp_geometry::bench_rich::Method;
use tcomp_geometry::identify::{identify, Degrees, LineObs};
use tcomp_geometry::lines::{average_runs, plan14, LineFile};
use tcomp_geometry::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp_geometry::study::{recovery, volumetric_residual};
use tcomp_geometry::{Structure, Term};
use tcomp_numerics::rng::Rng;

/// Instructions (×100) of one volumetric evaluation of `image` on the
/// bench firmware, or why it could not be measured.
fn count_on_board(
    elf: &std::path::Path,
    image: &std::path::Path,
    key: &str,
) -> Result<f64, String> {
    if !elf.exists() {
        return Err(format!(
            "no QEMU firmware at {} (cargo build -p board-qemu-mps2 --profile firmware --target thumbv7em-none-eabihf)",
            elf.display()
        ));
    }
    let out = std::process::Command::new("qemu-system-arm")
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic"])
        .args([
            "-semihosting-config",
            "enable=on,target=native",
            "-icount",
            "shift=0",
        ])
        .arg("-kernel")
        .arg(elf)
        .arg("-append")
        .arg(format!("bench no-golden-file {}", image.display()))
        .output()
        .map_err(|e| format!("qemu-system-arm: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .rfind(|l| l.starts_with('{'))
        .ok_or_else(|| format!("the bench firmware printed no figures: {text}"))?;
    let v: serde_json::Value = serde_json::from_str(line).map_err(|e| format!("{e}: {line}"))?;
    v[key]
        .as_f64()
        .map(|x| x / 100.0)
        .ok_or_else(|| format!("no {key} in {line}"))
}

/// Quantisation and instruction count of the static and a dense thermal section.
fn board_figures(
    st: &Structure,
    stroke: [f64; 3],
    elf: &std::path::Path,
    dir: &std::path::Path,
) -> anyhow::Result<serde_json::Value> {
    use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
    use tcomp_geometry::volumetric::{build, VolTerm, VolumetricPoly};
    let truth = random_errors(stroke, &ErrorSizes::default(), &mut Rng::new(1000));
    let static_poly = build(st, stroke, &truth, None)?;
    // Dense thermal: every monomial of the full table (the static one's
    // coefficient where it has one, else 0.3 µm), constant and per kelvin
    // of three sensors (a tenth of it per kelvin).
    let full = build(st, stroke, &truth, None).map(|mut p| {
        p.terms.clear();
        p
    })?;
    let mut terms = Vec::new();
    for e in 0..=1u8 {
        for a in 0..=3u8 {
            for b in 0..=3u8 {
                for c in 0..=3u8 {
                    if a + b + c + e > 4 {
                        continue;
                    }
                    let m = [a, b, c, e];
                    let base = static_poly
                        .terms
                        .iter()
                        .find(|t| t.monomial == m)
                        .map_or([0.3, -0.3, 0.3], |t| t.coef_um);
                    for sensor in [None, Some(0), Some(1), Some(2)] {
                        let k = if sensor.is_some() { 0.1 } else { 1.0 };
                        terms.push(VolTerm {
                            monomial: m,
                            sensor,
                            coef_um: base.map(|c| c * k),
                        });
                    }
                }
            }
        }
    }
    let dense = VolumetricPoly {
        sensors: vec!["a".into(), "b".into(), "c".into()],
        t_ref_c: vec![20.0, 21.0, 22.5],
        terms,
        ..full
    };
    let mut out = serde_json::Map::new();
    // Targets: the static geometry of a three-axis machine within a few
    // compensator steps; the densest section (208 of the 256 terms) within
    // 30,000 instructions ≈ 0.27 ms at 168 MHz and ~1.5 cycles per
    // instruction, well inside the reply to the PLC's position write.
    for (name, poly, channels, target) in [
        ("static", &static_poly, vec![], 5_000),
        ("thermal_dense", &dense, vec![0u8, 1, 2], 30_000),
    ] {
        let opts = BoardOptions {
            channels,
            slots: [0, 1, 2],
            origin_mm: [0.0; 3],
            tool_max_mm: 500.0,
            max_correction_um: 500.0,
        };
        let v = quantize(poly, &opts)?;
        let report = quantisation_report(poly, &v, &opts);
        let img = dir.join(format!("{name}.img"));
        let summary = tcomp_model::export::export_with(
            &thermocomp_core::float::demo_model(1),
            Some((v, report.clone())),
            &img,
        )?;
        let insn = count_on_board(elf, &img, "volumetric_evaluate_insn_x100");
        out.insert(
            name.into(),
            serde_json::json!({
                "terms": report.terms,
                "sensors": report.sensors,
                "section_bytes": report.section_bytes,
                "image_bytes": summary.bytes,
                "quantisation": report,
                "evaluate_instructions": insn.as_ref().ok(),
                "evaluate_instructions_error": insn.as_ref().err(),
                "target_instructions": target,
            }),
        );
    }
    out.insert(
        "thermal_dense_five_axis".into(),
        five_axis_figures(&dense, elf, dir, false)?,
    );
    // The same section in the R-test location mode (a model with drift).
    out.insert(
        "thermal_dense_five_axis_rtest".into(),
        five_axis_figures(&dense, elf, dir, true)?,
    );
    Ok(serde_json::Value::Object(out))
}

/// Issue 31: the dense thermal section with a five-axis section (kind 4)
/// as dense as the board takes: the eight location errors with slopes on
/// all three sensors, all twelve component errors to order 4; the whole
/// evaluation (kind 3 + the rotary chain) counted on the bench firmware.
/// `rtest`: the section's R-test location mode (issue 31 item 3: the
/// location slots served as (I − R(θ))·ξ_L(T)).
fn five_axis_figures(
    dense: &tcomp_geometry::volumetric::VolumetricPoly,
    elf: &std::path::Path,
    dir: &std::path::Path,
    rtest: bool,
) -> anyhow::Result<serde_json::Value> {
    use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
    use tcomp_geometry::board5::{
        quantize_five_axis, FiveAxisOptions, Location, LocationValue, RotaryModel,
    };
    use tcomp_geometry::five_axis::Fourier;
    let opts = BoardOptions {
        channels: vec![0, 1, 2],
        slots: [0, 1, 2],
        origin_mm: [0.0; 3],
        tool_max_mm: 500.0,
        max_correction_um: 500.0,
    };
    let v = quantize(dense, &opts)?;
    let report = quantisation_report(dense, &v, &opts);
    let mut r = RotaryModel {
        pivot_a_mm: [400.0, 250.0, -150.0],
        offset_c_mm: [0.0, 0.0, 120.0],
        sensors: dense.sensors.clone(),
        t_ref_c: dense.t_ref_c.clone(),
        rtest_location: rtest,
        ..Default::default()
    };
    for (k, name) in thermocomp_core::five_axis::LOCATION_NAMES
        .iter()
        .enumerate()
    {
        let s = 0.1 * (k as f64 + 1.0);
        r.location.insert(
            name.to_string(),
            LocationValue::Thermal(Location {
                value: 10.0 - 2.5 * k as f64,
                per_k: vec![s, -s, s / 2.0],
            }),
        );
    }
    for axis in ['A', 'C'] {
        for m in thermocomp_core::five_axis::MOTION_LETTERS {
            r.motion.insert(
                format!("E{m}{axis}"),
                Fourier {
                    cos: vec![2.0, -1.0, 0.5, 0.25],
                    sin: vec![-1.5, 0.75, -0.4, 0.2],
                },
            );
        }
    }
    let f = quantize_five_axis(&r, &v, &dense.sensors, &FiveAxisOptions::default())?;
    let five_bytes = 4 + f.encoded_len();
    let order = f.order;
    let (mut model, _) = thermocomp_core::float::demo_model(1)
        .quantize()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    model.volumetric = Some(v);
    model.five_axis = Some(f);
    let mut buf = vec![0u8; model.encoded_len()];
    model.encode(&mut buf).map_err(|e| anyhow::anyhow!("{e}"))?;
    let img = dir.join(if rtest {
        "thermal_dense_five_axis_rtest.img"
    } else {
        "thermal_dense_five_axis.img"
    });
    std::fs::write(&img, &buf)?;
    let insn = count_on_board(elf, &img, "five_axis_evaluate_insn_x100");
    Ok(serde_json::json!({
        "terms": report.terms,
        "sensors": report.sensors,
        "section_bytes": report.section_bytes + five_bytes,
        "five_axis_section_bytes": five_bytes,
        "fourier_order": order,
        "rtest_location": rtest,
        "image_bytes": buf.len(),
        "quantisation": report,
        "evaluate_instructions": insn.as_ref().ok(),
        "evaluate_instructions_error": insn.as_ref().err(),
        "target_instructions": 30_000,
    }))
}

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(run)
}

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    name = "bench-geometry",
    about = "Identification accuracy of the 14-line method against reading noise, and the volumetric section on the board (quantisation, instructions per evaluation under QEMU)"
)]
struct Args {
    /// Print the figures as one JSON object.
    #[arg(long)]
    json: bool,
    /// Random machines per noise level (with --rich: machines, seeds S…S+N−1).
    #[arg(long, value_name = "N", default_value_t = 10)]
    seeds: u64,
    /// Only the board's figures: skip the identification.
    #[arg(long = "board-only")]
    board_only: bool,
    /// The QEMU bench firmware that counts the instructions (default: $CARGO_TARGET_DIR or target, then thumbv7em-none-eabihf/firmware/board-qemu-mps2).
    #[arg(long, value_name = "ELF")]
    firmware: Option<PathBuf>,
    /// Machines richer than the model (issue 29: desktop/tcomp/tests/data/geometry_rich_gen.py), σ = 0 and 0.5 µm.
    #[arg(long)]
    rich: bool,
    /// With --rich: the identifier scored (poly, smooth or dense).
    #[arg(long, value_name = "METHOD", default_value = "smooth", value_parser = parse_method)]
    method: Method,
    /// With --rich: the first machine's seed S.
    #[arg(long = "first-seed", value_name = "S", default_value_t = 1)]
    first_seed: u64,
    /// With --rich: machines without the waves of 0.5–1.5 strokes.
    #[arg(long = "no-wave")]
    no_wave: bool,
}

/// `--method`: poly, smooth or dense.
fn parse_method(s: &str) -> Result<Method, String> {
    Method::parse(s).map_err(|_| "poly, smooth or dense".to_string())
}

/// `--rich [--method poly|smooth|dense] [--seeds N] [--first-seed S] [--no-wave]`:
/// machines of `desktop/tcomp/tests/data/geometry_rich_gen.py` (issue 29), σ = 0 and 0.5 µm.
fn rich(args: &Args) -> anyhow::Result<()> {
    use tcomp_geometry::bench_rich::run;
    let (method, seeds, first, json) = (args.method, args.seeds, args.first_seed, args.json);
    let wave = !args.no_wave;
    let t0 = std::time::Instant::now();
    let v = run(seeds, first, &[0.0, 0.5], wave, method)?;
    if json {
        println!("{v}");
        return Ok(());
    }
    println!(
        "rich machines (degree-5 polynomials{} , per-line scale 0.5 ppm), method {method:?}, seeds {first}..{}, {:.1} s",
        if wave { " + waves of 0.5–1.5 strokes" } else { "" },
        first + seeds - 1,
        t0.elapsed().as_secs_f64()
    );
    println!("noise µm | worst-term RMS µm (min–max over machines) | µrad | held-out lines RMS reduction % (min–max)");
    for r in v["rows"].as_array().into_iter().flatten() {
        let f = |k: &str, m: &str| r[k][m].as_f64().unwrap_or(f64::NAN);
        println!(
            "{:8.2} | {:.2}–{:.2} | {:.2}–{:.2} | {:.1}–{:.1}",
            r["noise_um"].as_f64().unwrap_or(0.0),
            f("worst_rms_translational_um", "min"),
            f("worst_rms_translational_um", "max"),
            f("worst_rms_angular_urad", "min"),
            f("worst_rms_angular_urad", "max"),
            f("heldout_reduction_pct", "min"),
            f("heldout_reduction_pct", "max"),
        );
        if let (Some(p), Some(s)) = (
            r["coverage_3sigma_poly_pct"].as_f64(),
            r["coverage_3sigma_shape_free_pct"].as_f64(),
        ) {
            println!(
                "         | 3σ covers the true error (mean over machines): {p:.1} % with the polynomial posterior's σ, {s:.1} % with the shape-free σ (printed)"
            );
        }
    }
    Ok(())
}

fn run() -> anyhow::Result<()> {
    let args: Args = tcomp_bench::cli::parse()?;
    if args.rich {
        return rich(&args);
    }
    standard(&args)
}

/// The identification on simulated machines of the model's own class and
/// the board's figures (the bench without `--rich`).
fn standard(args: &Args) -> anyhow::Result<()> {
    let (board_only, seeds, json) = (args.board_only, args.seeds, args.json);
    let elf: PathBuf = args.firmware.clone().unwrap_or_else(|| {
        std::path::Path::new(&std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
            .join("thumbv7em-none-eabihf/firmware/board-qemu-mps2")
    });
    let stroke = [800.0, 500.0, 400.0];
    let st = Structure::parse("XY/Z")?;
    let plan = plan14(stroke, 100.0, 100.0);
    // The readings go through real files, as a user's would.
    let dir = std::env::temp_dir().join(format!("bench-geometry-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let t0 = std::time::Instant::now();
    let mut rows = Vec::new();
    let board = board_figures(&st, stroke, &elf, &dir)?;
    let noises: &[f64] = if board_only {
        &[]
    } else {
        &[0.0, 0.1, 0.25, 0.5, 1.0, 2.0]
    };
    for &noise in noises {
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
            serde_json::json!({"machines_per_level": seeds, "lines": 14, "rows": rows, "seconds": el,
                "board_volumetric": board})
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
    println!(
        "volumetric section on the board (QEMU bench firmware {}):",
        elf.display()
    );
    for (name, b) in board.as_object().into_iter().flatten() {
        let q = &b["quantisation"];
        let insn = match b["evaluate_instructions"].as_f64() {
            Some(x) => format!(
                "{x:.0} instructions per evaluation (target ≤ {})",
                b["target_instructions"]
            ),
            None => format!(
                "instructions not measured: {}",
                b["evaluate_instructions_error"].as_str().unwrap_or("?")
            ),
        };
        println!(
            "  {name}: {} terms, {} sensors, {} B; {insn}; served vs f64 worst {:.4} µm ({:.6} µm before rounding, bound {:.4} µm)",
            b["terms"],
            b["sensors"],
            b["section_bytes"],
            q["max_error_um"].as_f64().unwrap_or(f64::NAN),
            q["max_error_before_rounding_um"].as_f64().unwrap_or(f64::NAN),
            q["bound_um"].as_f64().unwrap_or(f64::NAN),
        );
    }
    Ok(())
}

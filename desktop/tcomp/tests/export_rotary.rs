//! `tcomp export --geometry … --rotary …` end to end (issue 31): a machine
//! with random linear, location and component errors is simulated
//! (`geometry sim-rotary --lines`), its lines and R-test files identified,
//! the image exported with sections kind 3 and 4; the image's board
//! prediction (the core's `five_axis::evaluate`, bit-exact with the board)
//! then agrees with the identified model's f64 prediction within the
//! quantisation bound and corrects the true tool-tip error at held-out
//! poses. Refusals are one line.
mod common;
use common::{ok, refused};
use std::path::Path;

use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::rotary::{nominal_chain, tool_tip_error, Linear, Pose, RotaryModel};
use tcomp_geometry::rotary_frames::rotary_error_machine;
use tcomp_geometry::study::ErrorsJson;
use tcomp_geometry::GeometricErrors;
use tcomp_numerics::rng::Rng;
use thermocomp_core::five_axis::{self, fstatus};
use thermocomp_core::image::Model;
use thermocomp_core::volumetric::vstatus;

/// sim-rotary → identify (lines) → table → identify-rotary, in `d`; with
/// `joint`, identify-rotary fits the line files with the R-test files and
/// its corrected linear model (`--linear-out`) makes the table instead.
fn identified_machine(d: &Path, seed: &str) {
    identified_machine_as(d, seed, false)
}

fn identified_machine_as(d: &Path, seed: &str, joint: bool) {
    ok(
        d,
        &[
            "geometry",
            "sim-rotary",
            "--out",
            ".",
            "--lines",
            "--seed",
            seed,
        ],
    );
    let lines = identify_lines(d);
    let mut rotary = vec![
        "geometry",
        "identify-rotary",
        "N1.csv",
        "N2.csv",
        "N3.csv",
        "--model-out",
        "rotary.json",
        "--lines",
    ];
    let table_from = if joint {
        rotary.extend(lines.iter().map(String::as_str));
        rotary.extend(["--linear-out", "lin-joint.json"]);
        ok(d, &rotary);
        "lin-joint.json"
    } else {
        rotary.push("lin.json");
        ok(d, &rotary);
        "lin.json"
    };
    let vol = ok(d, &["geometry", "table", "--model", table_from, "--json"]);
    std::fs::write(d.join("vol.json"), vol).unwrap();
}

/// The simulated 14 line files (sorted) identified into `lin.json`.
fn identify_lines(d: &Path) -> Vec<String> {
    let mut lines: Vec<String> = std::fs::read_dir(d.join("lines"))
        .unwrap()
        .map(|e| format!("lines/{}", e.unwrap().file_name().to_string_lossy()))
        .filter(|n| n.ends_with(".csv"))
        .collect();
    lines.sort();
    let mut args = vec!["geometry", "identify", "--json"];
    args.extend(lines.iter().map(String::as_str));
    std::fs::write(d.join("lin.json"), ok(d, &args)).unwrap();
    lines
}

/// What `sim-rotary` and `identify-rotary` wrote in `d`: the true and the
/// identified rotary model, the true linear errors.
struct Written {
    truth: RotaryModel,
    model: RotaryModel,
    lin: ErrorsJson,
    structure: Structure,
    lin_errors: GeometricErrors,
}

impl Written {
    fn read(d: &Path) -> Self {
        let lin = ErrorsJson::read(&d.join("errors.json")).unwrap();
        Written {
            truth: RotaryModel::read(&d.join("rotary-truth.json")).unwrap(),
            model: RotaryModel::read(&d.join("rotary.json")).unwrap(),
            structure: Structure::parse(&lin.structure).unwrap(),
            lin_errors: lin.to_errors().unwrap(),
            lin,
        }
    }

    fn linear(&self) -> Linear<'_> {
        Linear {
            structure: &self.structure,
            errors: &self.lin_errors,
        }
    }
}

struct Figures {
    served_vs_model_um: f64,
    before_rms_um: f64,
    after_rms_um: f64,
}

/// Held-out poses (random positions, tools, A over ±90°, C over a turn):
/// the image's prediction against the identified model and against the truth.
fn score(d: &Path, img: &Model, seed: u64) -> Figures {
    let w = Written::read(d);
    let (truth, model, lin) = (&w.truth, &w.model, &w.lin);
    let lt = w.linear();
    let (v, f) = (
        img.volumetric.as_ref().unwrap(),
        img.five_axis.as_ref().unwrap(),
    );
    let mut rng = Rng::new(seed);
    let (mut worst, mut before, mut after) = (0.0f64, 0.0, 0.0);
    let n = 400;
    for _ in 0..n {
        let pos_um: [i32; 3] =
            std::array::from_fn(|k| (rng.range(0.1, 0.9) * lin.stroke_mm[k] * 1e3).round() as i32);
        let tool_um = (rng.range(60.0, 220.0) * 1e3).round() as i32;
        let a_m = (rng.range(-90.0, 90.0) * 1e3).round() as i32;
        let c_m = (rng.range(0.0, 360.0) * 1e3).round() as i32;
        let mut positions = [0i32; thermocomp_core::limits::MAX_AXES];
        for k in 0..3 {
            positions[usize::from(v.slots[k])] = pos_um[k];
        }
        let out = five_axis::evaluate(v, f, &positions, tool_um, [a_m, c_m], &[]);
        assert!(out.status & vstatus::VALID != 0 && out.five_status & fstatus::INCLUDED != 0);
        let (a, c) = (f64::from(a_m) / 1e3, f64::from(c_m) / 1e3);
        let pos_mm = pos_um.map(|p| f64::from(p) / 1e3);
        let tool = f64::from(tool_um) / 1e3;
        let p_mm = [pos_mm[0], pos_mm[1], pos_mm[2] + tool];
        let want = rotary_error_machine(model, &model.location, p_mm, a, c);
        for k in 0..3 {
            worst = worst.max((f64::from(out.rotary[k]) / 10.0 - want[k]).abs());
        }
        let pose = Pose {
            pos_mm,
            a_deg: a,
            c_deg: c,
            tool_mm: [0.0, 0.0, tool],
        };
        let rot = nominal_chain(truth.pivot_a_mm, truth.offset_c_mm, a, c).rotation;
        let t = rot * tool_tip_error(truth, &truth.location, Some(lt), &pose);
        let served = out.corrections.map(|v| f64::from(v) / 10.0);
        before += t.norm_squared();
        after += (0..3).map(|k| (t[k] - served[k]).powi(2)).sum::<f64>();
    }
    Figures {
        served_vs_model_um: worst,
        before_rms_um: (before / n as f64).sqrt(),
        after_rms_um: (after / n as f64).sqrt(),
    }
}

#[test]
fn the_image_serves_the_identified_rotary_model_and_corrects_the_machine() {
    let (mut least, mut worst_served) = (100.0f64, 0.0f64);
    for seed in 1..=10u64 {
        let seed = &seed.to_string();
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        identified_machine(d, seed);
        let out = ok(
            d,
            &[
                "export",
                "--demo",
                "--geometry",
                "vol.json",
                "--rotary",
                "rotary.json",
                "-o",
                "m.img",
                "--json",
            ],
        );
        let s: serde_json::Value = serde_json::from_str(&out).unwrap();
        let r = &s["five_axis"];
        // identify-rotary's default orders (C 3, A 2) need 4 and 3: exact.
        assert_eq!(r["order"].as_u64(), Some(4), "{r}");
        assert_eq!(r["truncated_rms_um"].as_f64(), Some(0.0));
        let bound = r["bound_um"].as_f64().unwrap();
        assert!(r["max_error_um"].as_f64().unwrap() <= bound, "{r}");
        let img = Model::parse(&std::fs::read(d.join("m.img")).unwrap()).unwrap();
        let fig = score(d, &img, seed.parse().unwrap());
        let reduction = 100.0 * (1.0 - fig.after_rms_um / fig.before_rms_um);
        println!(
            "seed {seed}: served rotary part vs the model's f64 {:.4} µm (bound {bound:.4}); held-out tool tip {:.2} → {:.2} µm RMS ({reduction:.1} % less)",
            fig.served_vs_model_um, fig.before_rms_um, fig.after_rms_um
        );
        assert!(
            fig.served_vs_model_um <= bound,
            "{} > {bound}",
            fig.served_vs_model_um
        );
        assert!(
            fig.before_rms_um > 10.0,
            "a machine worth correcting: {}",
            fig.before_rms_um
        );
        assert!(reduction >= 85.0, "reduction {reduction:.1} %");
        least = least.min(reduction);
        worst_served = worst_served.max(fig.served_vs_model_um);
    }
    println!(
        "10 machines: least reduction {least:.1} %, worst served − model {worst_served:.4} µm"
    );
}

/// The joint fit's corrected linear model through `geometry table` and the
/// image: the whole pipeline a user runs with line files, scored like the
/// fixed path on the same machines; the joint path must not be worse on
/// average and must meet the 85 % on each machine.
#[test]
fn the_joint_fit_s_corrected_linear_model_reaches_the_image() {
    let (mut fixed_sum, mut joint_sum) = (0.0f64, 0.0f64);
    for seed in 1..=4u64 {
        let mut after = [0.0f64; 2];
        for (k, joint) in [false, true].into_iter().enumerate() {
            let dir = tempfile::tempdir().unwrap();
            let d = dir.path();
            identified_machine_as(d, &seed.to_string(), joint);
            let args = [
                "export",
                "--demo",
                "--geometry",
                "vol.json",
                "--rotary",
                "rotary.json",
                "-o",
                "m.img",
            ];
            ok(d, &args);
            let img = Model::parse(&std::fs::read(d.join("m.img")).unwrap()).unwrap();
            let fig = score(d, &img, seed);
            let reduction = 100.0 * (1.0 - fig.after_rms_um / fig.before_rms_um);
            assert!(
                reduction >= 85.0,
                "seed {seed} joint {joint}: {reduction:.1} %"
            );
            after[k] = fig.after_rms_um;
        }
        println!(
            "seed {seed}: held-out tool tip after, 14-line model as input {:.2} µm, joint fit {:.2} µm",
            after[0], after[1]
        );
        fixed_sum += after[0];
        joint_sum += after[1];
    }
    assert!(
        joint_sum <= fixed_sum,
        "joint {joint_sum:.2} > fixed {fixed_sum:.2} (sum over 4 machines)"
    );
}

#[path = "export_rotary/drift.rs"]
mod drift;

#[test]
fn bad_rotary_files_and_unobservable_models_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &["geometry", "simulate", "--out", "lines", "--seed", "3"],
    );
    let vol = ok(
        d,
        &[
            "geometry",
            "table",
            "--model",
            "lines/errors.json",
            "--json",
        ],
    );
    std::fs::write(d.join("vol.json"), vol).unwrap();
    let export = |rotary: &str| {
        vec![
            "export",
            "--demo",
            "--geometry",
            "vol.json",
            "--rotary",
            rotary,
            "-o",
            "m.img",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>()
    };
    let run = |args: &[String], needle: &str| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(d, &a, needle);
    };
    run(&export("missing.json"), "missing.json");
    std::fs::write(d.join("bad.json"), "{\"pivot_a_mm\": [1, 2]}").unwrap();
    run(&export("bad.json"), "bad.json");
    let mut m = RotaryModel {
        pivot_a_mm: [400.0, 350.0, 400.0],
        offset_c_mm: [0.0, 0.0, 120.0],
        ..Default::default()
    };
    m.location.xoc_um = 5.0;
    m.unobservable = vec!["EZC".into(), "XOC".into()];
    std::fs::write(d.join("part.json"), serde_json::to_string(&m).unwrap()).unwrap();
    run(&export("part.json"), "--allow-unobservable");
    let mut allowed = export("part.json");
    allowed.push("--allow-unobservable".into());
    let a: Vec<&str> = allowed.iter().map(String::as_str).collect();
    ok(d, &a);
    m.unobservable.clear();
    // A drifting model's sensors need their board channels (--run).
    m.drift.push(tcomp_geometry::rotary::Drift {
        sensor: "ctable".into(),
        reference_c: 20.0,
        per_kelvin: Default::default(),
    });
    std::fs::write(d.join("drift.json"), serde_json::to_string(&m).unwrap()).unwrap();
    run(&export("drift.json"), "--run");
    // More sensors than the board's section takes.
    for s in ["a", "b", "c", "e"] {
        m.drift.push(tcomp_geometry::rotary::Drift {
            sensor: s.into(),
            reference_c: 20.0,
            per_kelvin: Default::default(),
        });
    }
    std::fs::write(d.join("drift5.json"), serde_json::to_string(&m).unwrap()).unwrap();
    run(&export("drift5.json"), "at most 4");
    refused(
        d,
        &["export", "--demo", "--rotary", "part.json", "-o", "m.img"],
        "--geometry",
    );
}

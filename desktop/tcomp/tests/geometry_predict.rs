//! `tcomp geometry predict` (issue 49 item 4): the identified model's
//! tool-tip error at the user's own poses agrees with `geometry tooltip`
//! and with the library's chains; with `--image` the served value is the
//! math core's own evaluation (bit for bit, computed here directly) and
//! within the stated bound of the desktop's f64; bad input is refused in
//! one line. Every model and image is made by the CLI from simulated files
//! (`geometry simulate`, `sim-rotary --lines`, identified and exported).
mod common;
use common::{ok, refused};
use std::path::Path;

use tcomp_geometry::kinematics::{tool_tip_error_linear, Structure};
use tcomp_geometry::rotary::{tool_tip_error, Linear, Pose, RotaryModel};
use tcomp_geometry::rotary_frames::rotary_error_machine;
use tcomp_geometry::study::ErrorsJson;
use thermocomp_core::five_axis;
use thermocomp_core::image::Model;
use thermocomp_core::limits::MAX_AXES;

fn json(s: &str) -> serde_json::Value {
    serde_json::from_str(s).unwrap()
}

fn v3(v: &serde_json::Value) -> [f64; 3] {
    std::array::from_fn(|k| v[k].as_f64().unwrap())
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64, what: &str) {
    for k in 0..3 {
        assert!((a[k] - b[k]).abs() <= tol, "{what}: {a:?} vs {b:?}");
    }
}

/// The 14 simulated lines in `lines/` identified into `id.json`, its
/// table `vol.json`.
fn identify(d: &Path, dir: &str) {
    let mut files: Vec<String> = std::fs::read_dir(d.join(dir))
        .unwrap()
        .map(|e| format!("{dir}/{}", e.unwrap().file_name().to_string_lossy()))
        .filter(|n| n.ends_with(".csv"))
        .collect();
    files.sort();
    let mut args = vec!["geometry", "identify", "--json"];
    args.extend(files.iter().map(String::as_str));
    std::fs::write(d.join("id.json"), ok(d, &args)).unwrap();
    let vol = ok(d, &["geometry", "table", "--model", "id.json", "--json"]);
    std::fs::write(d.join("vol.json"), vol).unwrap();
}

/// The board's inputs for a row, as the test computes them itself.
fn positions(img: &Model, pos_mm: [f64; 3]) -> [i32; MAX_AXES] {
    let v = img.volumetric.as_ref().unwrap();
    let mut p = [0i32; MAX_AXES];
    for k in 0..3 {
        p[usize::from(v.slots[k])] = (pos_mm[k] * 1e3).round() as i32;
    }
    p
}

const POSES3: &str = "id,x,y,z,tool
p1,0,0,0,100
p2,800,500,400,0
p3,123.4567,321.0009,77.7,150.25
p4,400,250,200,250
p5,799.999,12.5,399,60
";

#[test]
fn three_axis_predict_agrees_with_tooltip_and_the_image_with_the_core() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &["geometry", "simulate", "--out", "lines", "--seed", "3"],
    );
    identify(d, "lines");
    ok(
        d,
        &["export", "--demo", "--geometry", "vol.json", "-o", "m.img"],
    );
    std::fs::write(d.join("poses.csv"), POSES3).unwrap();
    let base = [
        "geometry",
        "predict",
        "--model",
        "id.json",
        "--poses",
        "poses.csv",
    ];
    let mut args = base.to_vec();
    args.extend(["--image", "m.img", "--json"]);
    let out = json(&ok(d, &args));
    assert_eq!(out["unit"], "um");
    assert_eq!(out["adequate"]["model"], true, "{}", out["adequate"]);
    assert_eq!(out["image"]["compared"], "total");
    let img = Model::parse(&std::fs::read(d.join("m.img")).unwrap()).unwrap();
    let v = img.volumetric.as_ref().unwrap();
    let rows = out["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 5);
    let mut worst = 0.0f64;
    for r in rows {
        let (pos, tool) = (
            [
                r["x_mm"].as_f64().unwrap(),
                r["y_mm"].as_f64().unwrap(),
                r["z_mm"].as_f64().unwrap(),
            ],
            r["tool_mm"].as_f64().unwrap(),
        );
        // The desktop: tooltip's figures at the same pose, same frame.
        let at = format!("{},{},{}", pos[0], pos[1], pos[2]);
        let t = json(&ok(
            d,
            &[
                "geometry",
                "tooltip",
                "--errors",
                "id.json",
                "--at",
                &at,
                "--tool",
                &format!("0,0,{tool}"),
                "--json",
            ],
        ));
        assert_eq!(t["frame"], "workpiece");
        close(
            v3(&r["error_workpiece_um"]),
            v3(&t["first_order_um"]),
            1e-9,
            "first order",
        );
        close(
            v3(&r["exact_workpiece_um"]),
            v3(&t["exact_um"]),
            1e-9,
            "exact",
        );
        close(
            v3(&r["error_machine_um"]),
            v3(&t["first_order_um"]),
            1e-9,
            "machine = workpiece",
        );
        // The board: the core evaluated here, bit for bit.
        let o = v.evaluate(&positions(&img, pos), (tool * 1e3).round() as i32, &[]);
        let served = v3(&r["served"]["correction_machine_um"]);
        assert_eq!(served, o.corrections.map(|c| f64::from(c) / 10.0), "{r}");
        let (diff, bound) = (
            v3(&r["served_minus_desktop_um"]),
            r["bound_um"].as_f64().unwrap(),
        );
        assert!(bound > 0.05 && bound < 0.06, "{r}");
        for d in diff {
            // At µm-exact inputs the difference is the served minus the desktop as printed.
            assert!(d.abs() <= bound, "{r}");
            worst = worst.max(d.abs());
        }
        assert_eq!(r["within_bound"], true);
    }
    println!("three-axis: served − desktop at most {worst:.4} µm over 5 poses");
    // The table gives the same desktop figures (the polynomial of the errors).
    let mut args = base.to_vec();
    args[3] = "vol.json";
    args.push("--json");
    let table = json(&ok(d, &args));
    for (a, b) in rows.iter().zip(table["rows"].as_array().unwrap()) {
        close(
            v3(&a["error_machine_um"]),
            v3(&b["error_machine_um"]),
            1e-3,
            "table",
        );
        assert!(b["exact_workpiece_um"].is_null());
    }
    // Text output names the frame and the comparison.
    let mut args = base.to_vec();
    args.extend(["--image", "m.img"]);
    let text = ok(d, &args);
    assert!(
        text.contains("machine frame") && text.contains("served − desktop (total)"),
        "{text}"
    );
}

/// sim-rotary → lines identified (`id.json`, `vol.json`) → identify-rotary
/// (`rotary.json`) → export with both sections (`m.img`).
fn five_axis_machine(d: &Path, seed: &str) {
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
    identify(d, "lines");
    ok(
        d,
        &[
            "geometry",
            "identify-rotary",
            "N1.csv",
            "N2.csv",
            "N3.csv",
            "--model-out",
            "rotary.json",
            "--lines",
            "id.json",
        ],
    );
    ok(
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
        ],
    );
}

#[test]
fn five_axis_predict_is_the_model_s_chain_and_the_image_the_core_s() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    five_axis_machine(d, "2");
    let lin = ErrorsJson::read(&d.join("id.json")).unwrap();
    let (st, errs) = (
        Structure::parse(&lin.structure).unwrap(),
        lin.to_errors().unwrap(),
    );
    let m = RotaryModel::read(&d.join("rotary.json")).unwrap();
    let s = lin.stroke_mm;
    let mut csv = String::from("x,y,z,a,c,tool\n");
    let mut rng = tcomp_numerics::rng::Rng::new(7);
    for i in 0..20 {
        let p: [f64; 3] =
            std::array::from_fn(|k| (rng.range(0.05, 0.95) * s[k] * 1e3).round() / 1e3);
        let (a, c) = if i == 0 {
            (0.0, 0.0)
        } else {
            (rng.range(-90.0, 90.0), rng.range(-300.0, 300.0))
        };
        let tool = rng.range(50.0, 250.0);
        csv += &format!("{},{},{},{a:.3},{c:.3},{tool:.3}\n", p[0], p[1], p[2]);
    }
    std::fs::write(d.join("poses.csv"), csv).unwrap();
    let args = [
        "geometry",
        "predict",
        "--model",
        "id.json",
        "--rotary",
        "rotary.json",
        "--poses",
        "poses.csv",
        "--image",
        "m.img",
        "--json",
    ];
    let out = json(&ok(d, &args));
    assert_eq!(out["image"]["compared"], "total", "{}", out["image"]);
    let img = Model::parse(&std::fs::read(d.join("m.img")).unwrap()).unwrap();
    let (v, f) = (
        img.volumetric.as_ref().unwrap(),
        img.five_axis.as_ref().unwrap(),
    );
    let mut worst = 0.0f64;
    for (i, r) in out["rows"].as_array().unwrap().iter().enumerate() {
        let g = |k: &str| r[k].as_f64().unwrap();
        let (pos, a, c, tool) = (
            [g("x_mm"), g("y_mm"), g("z_mm")],
            g("a_deg"),
            g("c_deg"),
            g("tool_mm"),
        );
        // The desktop: the linear first order plus the rotary model's, machine frame.
        let lin_part = tool_tip_error_linear(&st, &errs, pos, [0.0, 0.0, tool]);
        // an identified spindle's tilt at this tool, relative to the model's
        // reference tool: the desktop adds it, the board does not serve it
        let sp: [f64; 3] = m
            .spindle
            .map_or([0.0; 3], |s| s.offset_um([0.0, 0.0, tool]).into());
        let rot = rotary_error_machine(&m, &m.location, [pos[0], pos[1], pos[2] + tool], a, c);
        close(
            v3(&r["error_machine_um"]),
            [0, 1, 2].map(|k| lin_part[k] + rot[k] + sp[k]),
            1e-9,
            "machine",
        );
        // The exact chain in the workpiece frame, and first order near it.
        let pose = Pose {
            pos_mm: pos,
            a_deg: a,
            c_deg: c,
            tool_mm: [0.0, 0.0, tool],
        };
        let linear = Linear {
            structure: &st,
            errors: &errs,
        };
        let exact = tool_tip_error(&m, &m.location, Some(linear), &pose);
        close(
            v3(&r["exact_workpiece_um"]),
            [exact.x, exact.y, exact.z],
            1e-9,
            "exact",
        );
        close(
            v3(&r["error_workpiece_um"]),
            [exact.x, exact.y, exact.z],
            0.05,
            "second order",
        );
        if i == 0 {
            let at = format!("{},{},{}", pos[0], pos[1], pos[2]);
            let t = json(&ok(
                d,
                &[
                    "geometry",
                    "tooltip",
                    "--errors",
                    "id.json",
                    "--at",
                    &at,
                    "--tool",
                    &format!("0,0,{tool}"),
                    "--json",
                ],
            ));
            // A = C = 0: tooltip's three-axis figure and the spindle's share
            let w = v3(&r["error_workpiece_um"]);
            close(
                [0, 1, 2].map(|k| w[k] - sp[k]),
                v3(&t["first_order_um"]),
                1e-9,
                "tooltip",
            );
        }
        // The board: the core evaluated here at the board's inputs, bit for bit.
        let angles = [(a * 1e3).round() as i32, (c * 1e3).round() as i32];
        let o = five_axis::evaluate(
            v,
            f,
            &positions(&img, pos),
            (tool * 1e3).round() as i32,
            angles,
            &[],
        );
        assert_eq!(
            v3(&r["served"]["correction_machine_um"]),
            o.corrections.map(|x| f64::from(x) / 10.0)
        );
        assert_eq!(
            v3(&r["served"]["rotary_part_machine_um"]),
            o.rotary.map(|x| f64::from(x) / 10.0)
        );
        let bound = g("bound_um");
        assert!(
            bound < 0.08 + sp.iter().map(|x| x * x).sum::<f64>().sqrt(),
            "{r}"
        );
        assert_eq!(r["within_bound"], true, "{r}");
        worst = worst.max(
            v3(&r["served_minus_desktop_um"])
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs())),
        );
    }
    println!("five-axis: served − desktop at most {worst:.4} µm over 20 poses");
    // The rotary model alone: its part of the served value.
    let out = json(&ok(
        d,
        &[
            "geometry",
            "predict",
            "--rotary",
            "rotary.json",
            "--poses",
            "poses.csv",
            "--image",
            "m.img",
            "--json",
        ],
    ));
    assert_eq!(out["image"]["compared"], "rotary part");
    assert!(out["rows"]
        .as_array()
        .unwrap()
        .iter()
        .all(|r| r["within_bound"] == true));
}

#[test]
fn a_drifting_model_needs_its_temperature() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut m = RotaryModel {
        pivot_a_mm: [400.0, 350.0, 400.0],
        offset_c_mm: [0.0, 0.0, 120.0],
        ..Default::default()
    };
    m.location.xoc_um = 5.0;
    let per_k = tcomp_geometry::rotary::Location {
        xoc_um: 1.5,
        ..Default::default()
    };
    m.drift.push(tcomp_geometry::rotary::Drift {
        sensor: "ctable".into(),
        reference_c: 20.0,
        per_kelvin: per_k,
    });
    m.adequate = Some(true);
    std::fs::write(d.join("r.json"), serde_json::to_string(&m).unwrap()).unwrap();
    std::fs::write(d.join("cold.csv"), "x,y,z,a,c\n400,350,300,0,90\n").unwrap();
    refused(
        d,
        &[
            "geometry", "predict", "--rotary", "r.json", "--poses", "cold.csv",
        ],
        "T_ctable",
    );
    std::fs::write(
        d.join("warm.csv"),
        "x,y,z,a,c,T_ctable\n400,350,300,0,90,24\n",
    )
    .unwrap();
    let out = json(&ok(
        d,
        &[
            "geometry", "predict", "--rotary", "r.json", "--poses", "warm.csv", "--json",
        ],
    ));
    let r = &out["rows"][0];
    let loc = m
        .location_at(&[("ctable".to_string(), 24.0)].into_iter().collect())
        .unwrap();
    assert!((loc.xoc_um - 11.0).abs() < 1e-12);
    let want = rotary_error_machine(&m, &loc, [400.0, 350.0, 400.0], 0.0, 90.0);
    close(
        v3(&r["error_machine_um"]),
        [want.x, want.y, want.z],
        1e-9,
        "drift",
    );
    assert!(want.norm() > 10.0, "the drift shows: {want}");
}

#[test]
fn bad_input_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &["geometry", "simulate", "--out", "lines", "--seed", "3"],
    );
    identify(d, "lines");
    ok(d, &["export", "--demo", "-o", "plain.img"]);
    let files = [
        ("noz.csv", "x,y\n1,2\n"),
        ("nan.csv", "x,y,z\n1,2,3\n4,abc,6\n"),
        ("out.csv", "x,y,z\n900,20,30\n"),
        ("odd.csv", "x,y,z,speed\n1,2,3,4\n"),
        ("ok.csv", "x,y,z\n100,200,300\n"),
        ("ac.csv", "x,y,z,a,c\n100,200,300,10,0\n"),
    ];
    for (n, t) in files {
        std::fs::write(d.join(n), t).unwrap();
    }
    let p = |poses: &'static str| {
        vec![
            "geometry", "predict", "--model", "id.json", "--poses", poses,
        ]
    };
    refused(d, &p("noz.csv"), "no column z");
    refused(
        d,
        &p("nan.csv"),
        "line 3, column y: \"abc\" is not a number",
    );
    refused(d, &p("out.csv"), "outside the model's stroke");
    let mut allow = p("out.csv");
    allow.push("--allow-outside");
    ok(d, &allow);
    refused(d, &p("odd.csv"), "unknown column \"speed\"");
    refused(d, &p("ac.csv"), "no --rotary");
    let mut img = p("ok.csv");
    img.extend(["--image", "plain.img"]);
    refused(d, &img, "no volumetric section");
    refused(d, &["geometry", "predict", "--poses", "ok.csv"], "--model");
    // A rotary model given as --model, and a linear one as --rotary, are named.
    let m = RotaryModel {
        pivot_a_mm: [1.0, 2.0, 3.0],
        ..Default::default()
    };
    std::fs::write(d.join("rot.json"), serde_json::to_string(&m).unwrap()).unwrap();
    refused(
        d,
        &[
            "geometry", "predict", "--model", "rot.json", "--poses", "ok.csv",
        ],
        "give it as --rotary",
    );
    refused(
        d,
        &[
            "geometry", "predict", "--rotary", "id.json", "--poses", "ok.csv",
        ],
        "give it as --model",
    );
    // The adequacy verdict: refused when false unless --accept-inadequate.
    let mut bad = json(&std::fs::read_to_string(d.join("id.json")).unwrap());
    bad["adequate"] = serde_json::json!(false);
    std::fs::write(d.join("bad.json"), bad.to_string()).unwrap();
    refused(
        d,
        &[
            "geometry", "predict", "--model", "bad.json", "--poses", "ok.csv",
        ],
        "--accept-inadequate",
    );
    let out = json(&ok(
        d,
        &[
            "geometry",
            "predict",
            "--model",
            "bad.json",
            "--poses",
            "ok.csv",
            "--accept-inadequate",
            "--json",
        ],
    ));
    assert_eq!(out["adequate"]["model"], false);
}

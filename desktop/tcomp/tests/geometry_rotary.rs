//! `tcomp geometry sim-rotary | identify-rotary | check-rotary` end to end:
//! simulated R-test files with linear errors, identified with the 14-line
//! model as known input, checked on the five-axis grid; too few nests refused.
use std::path::Path;
use std::process::{Command, Output};

fn tcomp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

#[test]
fn simulate_identify_and_check_the_rotary_axes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = tcomp(&[
        "geometry",
        "sim-rotary",
        "--out",
        &s(d),
        "--lines",
        "--seed",
        "5",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines: Vec<String> = std::fs::read_dir(d.join("lines"))
        .unwrap()
        .map(|e| s(&e.unwrap().path()))
        .collect();
    lines.sort();
    assert_eq!(lines.len(), 28);
    let model = d.join("model.json");
    let mut args: Vec<String> = ["geometry", "identify-rotary", "N1.csv", "N2.csv", "N3.csv"]
        .iter()
        .map(|a| {
            if a.ends_with(".csv") {
                s(&d.join(a))
            } else {
                a.to_string()
            }
        })
        .collect();
    args.extend([
        "--truth".into(),
        s(&d.join("rotary-truth.json")),
        "--model-out".into(),
        s(&model),
        "--json".into(),
        "--lines".into(),
    ]);
    args.extend(lines);
    let out = tcomp(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["condition_number"].as_f64().unwrap() < 100.0);
    // line files: fitted with the R-test files, each with its own noise
    let j = &v["linear"];
    let (sl, sr) = (
        j["sigma_lines_um"].as_f64().unwrap(),
        j["sigma_rtest_um"].as_f64().unwrap(),
    );
    assert!(
        (0.25..0.45).contains(&sl) && (0.45..0.65).contains(&sr),
        "{j}"
    );
    assert_eq!(v["unobservable_terms"].as_array().unwrap().len(), 0);
    // the orders by the evidence (default `auto`): the simulated machine's
    // own, harmonics 1–3 on C and 1–2 on A, each candidate's evidence listed
    let orders = v["orders"].as_array().unwrap();
    for (axis, truth) in [("A", 2), ("C", 3)] {
        let o = orders.iter().find(|o| o["axis"] == axis).unwrap();
        assert_eq!(o["chosen_by"], "evidence", "{o}");
        assert_eq!(o["order"], truth, "{o}");
        assert_eq!(o["candidates"].as_array().unwrap().len(), 7, "{o}");
    }
    for (name, e) in v["recovery"]["location_error"].as_object().unwrap() {
        let tol = if name.starts_with('X') || name.starts_with('Y') || name.starts_with('Z') {
            1.5
        } else {
            4.0
        };
        assert!(e.as_f64().unwrap().abs() < tol, "{name}: {e}");
    }
    let out = tcomp(&[
        "geometry",
        "check-rotary",
        "--truth",
        &s(&d.join("rotary-truth.json")),
        "--model",
        &s(&model),
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["grid"]["reduction_pct"].as_f64().unwrap() > 85.0, "{v}");
    // the measured error carries the check's own noise: more left over
    let after = |k: &str| v[k]["after_rms_um"].as_f64().unwrap();
    assert!(after("grid_true") < after("grid"), "{v}");
    // the 14-line model as known input, and the corrected linear model out
    let lin_out = d.join("linear-corrected.json");
    let mut fixed = args.clone();
    fixed.push("--linear-fixed".into());
    let out = tcomp(&fixed.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v.get("linear").is_none(), "{v}");
    let out = tcomp(
        &fixed
            .iter()
            .map(String::as_str)
            .chain(["--linear-out", &s(&lin_out)])
            .collect::<Vec<_>>(),
    );
    assert!(!out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim().lines().count(),
        1
    );
    let out = tcomp(
        &args
            .iter()
            .map(String::as_str)
            .chain(["--linear-out", &s(&lin_out)])
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success());
    let ej = tcomp_geometry::study::ErrorsJson::read(&lin_out).unwrap();
    assert_eq!(ej.structure, "/XYZ");
    // two nests: the C location is refused with the reason, on one line
    let out = tcomp(&[
        "geometry",
        "identify-rotary",
        &s(&d.join("N1.csv")),
        &s(&d.join("N2.csv")),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not observable") && err.contains("XOC") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("fewer than three non-collinear"));
}

/// Drift over a warm-up, and the bias step on tool-tip readings at three
/// other states of the cool-down: the held-out state's error left over
/// shrinks (or at worst stays), scored against the true error.
#[test]
fn the_bias_step_of_check_rotary_scores_beside_the_drift_model() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = tcomp(&[
        "geometry",
        "sim-rotary",
        "--out",
        &s(d),
        "--thermal-cycles",
        "12",
        "--seed",
        "4",
    ]);
    assert!(out.status.success());
    let mut files: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| s(&e.unwrap().path()))
        .filter(|p| p.ends_with(".csv"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 12);
    let model = s(&d.join("model.json"));
    let mut args = vec![
        "geometry",
        "identify-rotary",
        "--drift",
        "all",
        "--model-out",
        &model,
    ];
    args.extend(files.iter().map(String::as_str));
    let out = tcomp(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth = s(&d.join("rotary-truth.json"));
    let out = tcomp(&[
        "geometry",
        "check-rotary",
        "--truth",
        &truth,
        "--model",
        &model,
        "--temps",
        "ctable=22.0,trunnion=22.5,bed=21.2",
        "--bias-temps",
        "ctable=24.0,trunnion=23.3,bed=21.5;ctable=21.0,trunnion=22.0,bed=21.1;ctable=23.0,trunnion=23.0,bed=21.4",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["bias_states"], 3);
    let red = |k: &str| v[k]["reduction_pct"].as_f64().unwrap();
    println!(
        "held-out state: {:.1} % without, {:.1} % with the bias step (true error)",
        red("grid_true"),
        red("grid_bias_true")
    );
    assert!(
        red("grid_true") > 85.0 && red("grid_bias_true") > 85.0,
        "{v}"
    );
    // a state that is not name=°C is refused in one line
    let out = tcomp(&[
        "geometry",
        "check-rotary",
        "--truth",
        &truth,
        "--model",
        &model,
        "--temps",
        "ctable=22,trunnion=22,bed=21",
        "--bias-temps",
        "ctable=hot",
    ]);
    assert!(!out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim().lines().count(),
        1
    );
}

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
    assert_eq!(v["unobservable_terms"].as_array().unwrap().len(), 0);
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

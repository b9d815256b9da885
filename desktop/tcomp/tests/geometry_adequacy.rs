//! Adequacy that can fail (issue 29 item 3) and the per-node identifier
//! (`identify --method dense`). The default polynomial model reports each
//! line predicted from the others beside the fit residual and the readings'
//! own noise; it warns in one line on a machine it cannot hold
//! (`data/geometry_rich_gen.py`: degree-5 polynomials plus waves) and not on
//! one it can (`data/geometry_lines_gen.py`, its own class).
mod common;
use common::*;
use std::path::PathBuf;

/// `identify --json`'s leave-one-line-out block and the stderr warning.
fn loo(files: &[PathBuf]) -> (serde_json::Value, String) {
    let out = run(&["geometry", "identify", "--json"], files);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    (
        v["leave_one_line_out"].clone(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn leave_one_line_out_warns_on_a_machine_the_model_cannot_hold_and_not_on_one_it_can() {
    for noise in [0.0, 0.5] {
        let own = tempfile::tempdir().unwrap();
        let (l, err) = loo(&generate("geometry_lines_gen.py", own.path(), 1, noise));
        assert!(l["warning"].is_null(), "own class, σ {noise}: {l}");
        assert!(err.is_empty(), "{err}");
        let (r, n) = (
            l["rms_um"].as_f64().unwrap(),
            l["noise_um"].as_f64().unwrap(),
        );
        // The noise of the averaged runs is σ/√2; the prediction holds it.
        assert!((n - noise / 2f64.sqrt()).abs() < 0.05, "noise {n}");
        assert!(
            r < 1.4 * n + 0.01,
            "own class, σ {noise}: LOLO {r} vs noise {n}"
        );

        let rich = tempfile::tempdir().unwrap();
        let files = generate("geometry_rich_gen.py", rich.path(), 2, noise);
        let (l, err) = loo(&files);
        assert!(l["warning"].is_string(), "rich, σ {noise}: {l}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.starts_with("warning: "), "{err}");
        let text = run(&["geometry", "identify"], &files);
        let t = String::from_utf8_lossy(&text.stdout);
        assert!(t.contains("leave-one-line-out prediction RMS"), "{t}");
        assert_eq!(t.matches("WARNING:").count(), 1, "{t}");
    }
}

#[test]
fn dense_identification_is_refused_or_honest_on_a_rich_machine() {
    let dir = tempfile::tempdir().unwrap();
    let files = generate("geometry_rich_gen.py", dir.path(), 3, 0.0);
    // 11 nodes keep the debug-build test short; the method is the same.
    let args = ["geometry", "identify", "--method", "dense", "--nodes", "11"];
    let plain = run(&args, &files);
    let out = run(&[&args[..], &["--partial", "--json"]].concat(), &files);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["method"], "dense");
    let marked: Vec<String> = v["unobservable_terms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect();
    assert_eq!(plain.status.success(), marked.is_empty());
    let id = &v["identification"];
    let eff = id["effective_parameters"].as_f64().unwrap();
    let unknowns = id["unknowns"].as_f64().unwrap();
    assert!(eff > 20.0 && eff < unknowns, "{eff} of {unknowns}");
    assert!(id["hyper"]["length_scale_strokes"].as_f64().unwrap() > 0.0);
    let model = dir.path().join("id.json");
    std::fs::write(&model, &out.stdout).unwrap();
    let s = run(
        &[
            "geometry",
            "score",
            "--json",
            "--model",
            model.to_str().unwrap(),
            "--truth",
            dir.path().join("truth.json").to_str().unwrap(),
        ],
        &[],
    );
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    let s: serde_json::Value = serde_json::from_slice(&s.stdout).unwrap();
    for (name, r) in s["terms"].as_object().unwrap() {
        let limit = if "ABC".contains(&name[1..2]) {
            4.0
        } else {
            1.0
        };
        let rms = r[1].as_f64().unwrap();
        assert!(
            marked.contains(name) || rms <= limit,
            "{name} off by {rms} RMS, not marked"
        );
    }
}

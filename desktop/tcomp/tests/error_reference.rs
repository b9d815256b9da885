//! Runs whose metadata says `error_reference: absolute`: `fit`, `select` and
//! `replay` take the error columns as rises from their first valid sample
//! (the run format's rule) and say so; the fitted model and the replay
//! figures are those of the same run written relative.

use std::path::{Path, PathBuf};
use std::process::Command;

use tcomp_data::runcsv::Run;

/// A warm-up/cool-down run; `offset` added to every error value, and the
/// metadata line marking it absolute when `offset` is given.
fn write_run(dir: &Path, name: &str, offset: Option<f64>) -> PathBuf {
    let mut s = String::from("# run: synthetic\n");
    if offset.is_some() {
        s.push_str("# error_reference: absolute\n");
    }
    s.push_str("time_s,spindle_rpm,T_a,T_b,dx_um\n");
    let mut temp = 20.0;
    for k in 0..1200 {
        let rpm = if (k / 200) % 2 == 0 { 4000.0 } else { 0.0 };
        // the first row is the cold machine: a relative run starts at 0 µm
        let tb = 20.0 + (temp - 20.0) * 0.4 + (k as f64 * 0.01).sin() * 0.2;
        let dx = 3.0 * (temp - 20.0) - 1.5 * (tb - 20.0) + offset.unwrap_or(0.0);
        s.push_str(&format!("{},{rpm},{temp:.4},{tb:.4},{dx:.4}\n", k * 30));
        let target = 20.0 + rpm / 500.0;
        temp = target + (-30.0f64 / 1800.0).exp() * (temp - target);
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

fn tcomp(args: &[&std::ffi::OsStr]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "tcomp {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn errors_as_rises_subtracts_the_first_valid_sample_once() {
    let mut run = Run {
        meta: vec![("error_reference".into(), "absolute".into())],
        columns: vec!["time_s".into(), "T_a".into(), "dx_um".into()],
        data: vec![
            vec![Some(0.0), Some(1.0), Some(2.0)],
            vec![Some(20.0), Some(21.0), Some(22.0)],
            vec![None, Some(50.0), Some(53.5)],
        ],
    };
    let note = run
        .errors_as_rises("r.csv")
        .expect("an absolute run is re-zeroed");
    assert!(
        note.contains("r.csv") && note.contains("dx_um +50 µm"),
        "{note}"
    );
    assert_eq!(run.data[2], vec![None, Some(0.0), Some(3.5)]);
    assert_eq!(run.data[1], vec![Some(20.0), Some(21.0), Some(22.0)]);
    assert_eq!(run.meta("error_reference"), Some("relative"));
    // Already rises: nothing changes, nothing said.
    assert!(run.errors_as_rises("r.csv").is_none());
    assert_eq!(run.data[2], vec![None, Some(0.0), Some(3.5)]);
}

#[test]
fn an_absolute_run_fits_and_replays_as_the_same_run_written_relative() {
    let dir = tempfile::tempdir().unwrap();
    let rel = write_run(dir.path(), "rel.csv", None);
    let abs = write_run(dir.path(), "abs.csv", Some(57.25));
    let mut fits = Vec::new();
    for (run, name) in [(&rel, "rel.json"), (&abs, "abs.json")] {
        let out = dir.path().join(name);
        let o = tcomp(&[
            "fit".as_ref(),
            run.as_os_str(),
            "--split-chrono".as_ref(),
            "0.6,0.8".as_ref(),
            "--mlr-only".as_ref(),
            "--json".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let said_absolute = v["notes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("error_reference is absolute"));
        assert_eq!(said_absolute, run == &abs, "notes: {}", v["notes"]);
        let file: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        fits.push(file);
    }
    // The same model: the 57.25 µm offset went nowhere (no intercept shift).
    let (a, b) = (&fits[0]["mlr"][0], &fits[1]["mlr"][0]);
    assert_eq!(a["features"], b["features"]);
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    assert!((num(&a["c0"]) - num(&b["c0"])).abs() < 1e-9, "{a} vs {b}");
    for (x, y) in a["coef"]
        .as_array()
        .unwrap()
        .iter()
        .zip(b["coef"].as_array().unwrap())
    {
        assert!((num(x) - num(y)).abs() < 1e-9, "{a} vs {b}");
    }
    assert_eq!(fits[0]["chosen"], fits[1]["chosen"]);

    let img = dir.path().join("m.img");
    tcomp(&[
        "export".as_ref(),
        "--model".as_ref(),
        dir.path().join("abs.json").as_os_str(),
        "--run".as_ref(),
        abs.as_os_str(),
        "-o".as_ref(),
        img.as_os_str(),
    ]);
    let mut figures = Vec::new();
    for run in [&rel, &abs] {
        let o = tcomp(&[
            "replay".as_ref(),
            run.as_os_str(),
            img.as_os_str(),
            "--from".as_ref(),
            "0.6".as_ref(),
            "--to".as_ref(),
            "0.8".as_ref(),
            "--json".as_ref(),
        ]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let ch = &v["channels"][0];
        assert_eq!(ch["never_worse"], true, "{v}");
        assert_eq!(
            v["notes"].as_array().unwrap().len(),
            usize::from(run == &abs),
            "{v}"
        );
        figures.push((
            ch["mae_um"].as_f64().unwrap(),
            ch["uncompensated_rms_um"].as_f64().unwrap(),
        ));
    }
    // Scored about the run's start: the absolute file gives the relative
    // file's figures, not a 57 µm residual.
    assert!((figures[0].0 - figures[1].0).abs() < 1e-9, "{figures:?}");
    assert!((figures[0].1 - figures[1].1).abs() < 1e-9, "{figures:?}");
    assert!(figures[1].0 < 1.0, "{figures:?}");
}

//! `diagnose fit` on run sets shaped as measured data come: runs of
//! different lengths and sample periods, one run with `spindle_rpm` and one
//! without, empty cells. No crash; a JSON answer with the contract's keys.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A run of `rows` samples every `dt` s; `spindle` adds the column; `gaps`
/// empties a few cells.
fn write_run(dir: &Path, name: &str, rows: usize, dt: f64, spindle: bool, gaps: bool) -> PathBuf {
    let mut s = String::new();
    s.push_str("time_s");
    if spindle {
        s.push_str(",spindle_rpm");
    }
    s.push_str(",T_a,T_b,T_c,T_ambient,dx_um,dz_um\n");
    let (mut a, mut b, mut c) = (20.0f64, 20.0f64, 20.0f64);
    for k in 0..rows {
        let t = k as f64 * dt;
        let rpm = if ((t / 3600.0) as usize).is_multiple_of(2) {
            4000.0
        } else {
            0.0
        };
        let amb = 20.0 + 0.3 * (t / 20000.0).sin();
        let heat = rpm / 800.0;
        a += dt / 1200.0 * (amb + heat - a);
        b += dt / 3000.0 * (a - b) + dt / 6000.0 * (amb - b);
        c += dt / 8000.0 * (b - c);
        let dx = 1.8 * (a - 20.0) - 0.6 * (c - 20.0);
        let dz = -2.5 * (b - 20.0);
        let mut cells = vec![format!("{t}")];
        if spindle {
            cells.push(format!("{rpm}"));
        }
        for v in [a, b, c, amb] {
            cells.push(format!("{:.4}", (v * 16.0).round() / 16.0));
        }
        cells.push(format!("{dx:.3}"));
        cells.push(format!("{dz:.3}"));
        if gaps && k % 113 == 7 {
            cells[if spindle { 2 } else { 1 }] = String::new();
        }
        if gaps && k % 157 == 11 {
            let last = cells.len() - 1;
            cells[last] = String::new();
        }
        s.push_str(&cells.join(","));
        s.push('\n');
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

fn diagnose_fit(runs: &[PathBuf]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(["diagnose", "fit"])
        .args(runs)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for k in ["effects", "where", "untestable"] {
        assert!(v.get(k).is_some(), "no `{k}` in {v}");
    }
    v
}

#[test]
fn runs_of_different_lengths_and_sample_periods() {
    // 6 h at 30 s and 2 h at 10 s: their free decays differ in number.
    let dir = tempfile::tempdir().unwrap();
    let long = write_run(dir.path(), "long.csv", 720, 30.0, true, false);
    let short = write_run(dir.path(), "short.csv", 720, 10.0, true, false);
    let v = diagnose_fit(&[long, short]);
    assert!(v["gap_before_um"].as_f64().unwrap().is_finite(), "{v}");
}

#[test]
fn one_run_with_spindle_speed_one_without_and_empty_cells() {
    let dir = tempfile::tempdir().unwrap();
    let with = write_run(dir.path(), "with.csv", 600, 30.0, true, true);
    let without = write_run(dir.path(), "without.csv", 500, 30.0, false, true);
    let v = diagnose_fit(&[with, without]);
    assert!(v["gap_before_um"].as_f64().unwrap().is_finite(), "{v}");
}

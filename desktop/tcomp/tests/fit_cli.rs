//! `tcomp select --json` and `tcomp fit --json` output the documented keys.

use std::process::Command;

fn write_run(dir: &std::path::Path, name: &str, n: usize, phase: f64) -> std::path::PathBuf {
    let mut s = String::from("# run: synthetic\ntime_s,spindle_rpm,T_a,T_b,T_c,dx_um,dz_um\n");
    let mut temp = 20.0;
    for k in 0..n {
        let rpm = if (k / 150) % 2 == 0 { 4000.0 } else { 0.0 };
        let target = 20.0 + rpm / 500.0;
        temp = target + (-30.0f64 / 1800.0).exp() * (temp - target);
        let tb = 20.0 + (temp - 20.0) * 0.5 + (k as f64 * 0.01 + phase).sin() * 0.2;
        let tc = 21.0 + (k as f64 * 0.003).cos();
        let dx = 3.0 * (temp - 20.0);
        let dz = -2.0 * (tb - 20.0) + 0.5 * (tc - 21.0);
        s.push_str(&format!(
            "{},{rpm},{temp:.4},{tb:.4},{tc:.4},{dx:.4},{dz:.4}\n",
            k * 30
        ));
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

#[test]
fn select_and_fit_json_have_the_documented_keys() {
    let dir = tempfile::tempdir().unwrap();
    let a = write_run(dir.path(), "a.csv", 900, 0.0);
    let b = write_run(dir.path(), "b.csv", 600, 1.0);
    let exe = env!("CARGO_BIN_EXE_tcomp");

    let out = Command::new(exe)
        .args(["select", "--groups", "2", "--json"])
        .arg(&a)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for k in ["clusters", "scores", "chosen", "correlations"] {
        assert!(v.get(k).is_some(), "select --json lacks {k}");
    }
    assert_eq!(v["chosen"].as_array().unwrap().len(), 2);

    let model = dir.path().join("model.json");
    let out = Command::new(exe)
        .args(["fit"])
        .arg(&a)
        .arg("--validate")
        .arg(&b)
        .args([
            "--groups",
            "2",
            "--generations",
            "5",
            "--population",
            "10",
            "--lm-iters",
            "20",
            "--hidden",
            "4",
            "--json",
            "--out",
        ])
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let models = v["models"].as_array().unwrap();
    let names: Vec<&str> = models.iter().map(|m| m["name"].as_str().unwrap()).collect();
    assert!(
        names.contains(&"mlr") && names.contains(&"ga-bpn"),
        "{names:?}"
    );
    for m in models {
        for ch in ["dx_um", "dz_um"] {
            let c = &m["channels"][ch];
            for k in ["mae_um", "rms_um", "peak_um", "reduction_pct"] {
                assert!(c[k].as_f64().is_some(), "{} {ch} lacks {k}", m["name"]);
            }
        }
    }
    // The model file holds the board's parameter structs.
    let mf: tcomp_model::fit::ModelFile =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    // Each channel's network is an ensemble; the CV choice is in the file.
    assert_eq!(mf.nets.len() % 2, 0);
    assert!(
        mf.nets.iter().any(|n| n.channel == "dx_um")
            && mf.nets.iter().any(|n| n.channel == "dz_um")
    );
    assert_eq!(mf.chosen.len(), 2, "{:?}", mf.chosen);
    assert_eq!(mf.mlr.len(), 2);
    assert_eq!(mf.nets[0].w1.len(), 4);

    // Errors on user input are clear, not panics.
    let out = Command::new(exe)
        .args(["fit", "/nonexistent.csv", "--split-chrono", "0.6,0.8"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot open run file"));
    let out = Command::new(exe)
        .arg("fit")
        .arg(&a)
        .args(["--split-chrono", "0.8,0.6"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("split-chrono"));
}

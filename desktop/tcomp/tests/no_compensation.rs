//! `none` (no compensation) is a candidate of the fit's choice: a channel
//! whose error no model predicts better than 0 in the training CV ships as
//! 0, so the board never makes it worse; `export` refuses an image with
//! nothing in it, and `--use` still ships a model on request.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Deterministic standard-normal-ish noise (sum of 12 uniforms − 6).
struct Noise(u64);
impl Noise {
    fn next(&mut self) -> f64 {
        let mut s = 0.0;
        for _ in 0..12 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            s += (self.0 >> 11) as f64 / (1u64 << 53) as f64;
        }
        s - 6.0
    }
}

/// `dx_um` follows the temperatures; `dz_um` is 1 µm of noise unrelated to
/// anything (with `both_noise`, `dx_um` too).
fn write_run(dir: &Path, name: &str, both_noise: bool) -> PathBuf {
    let mut g = Noise(7);
    let mut s = String::from("time_s,spindle_rpm,T_a,T_b,dx_um,dz_um\n");
    let (mut ta, mut tb) = (20.0, 20.0);
    for k in 0..2000 {
        let rpm = if (k / 300) % 2 == 0 { 3000.0 } else { 0.0 };
        let dx = if both_noise {
            g.next()
        } else {
            2.0 * (ta - 20.0) - 0.5 * (tb - 20.0) + 0.2 * g.next()
        };
        let dz = g.next();
        s.push_str(&format!(
            "{},{rpm},{ta:.4},{tb:.4},{dx:.4},{dz:.4}\n",
            k * 30
        ));
        let target = 20.0 + rpm / 600.0;
        ta = target + (-30.0f64 / 900.0).exp() * (ta - target);
        tb = 20.0
            + (target - 20.0) / 2.0
            + (-30.0f64 / 2400.0).exp() * (tb - 20.0 - (target - 20.0) / 2.0);
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

fn tcomp(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn fit(run: &Path, out: &Path) -> serde_json::Value {
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
    ok(&o);
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `tcomp export --model FIT --run RUN -o IMG` plus `more`.
fn export(fit: &Path, run: &Path, img: &Path, more: &[&str]) -> std::process::Output {
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "export".as_ref(),
        "--model".as_ref(),
        fit.as_os_str(),
        "--run".as_ref(),
        run.as_os_str(),
        "-o".as_ref(),
        img.as_os_str(),
    ];
    args.extend(more.iter().map(|a| std::ffi::OsStr::new(*a)));
    tcomp(&args)
}

fn replay(run: &Path, img: &Path) -> serde_json::Value {
    let o = tcomp(&[
        "replay".as_ref(),
        run.as_os_str(),
        img.as_os_str(),
        "--from".as_ref(),
        "0.6".as_ref(),
        "--to".as_ref(),
        "1.0".as_ref(),
        "--json".as_ref(),
    ]);
    ok(&o);
    serde_json::from_slice(&o.stdout).unwrap()
}

fn channel<'a>(v: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    v["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["column"] == name)
        .unwrap()
}

#[test]
fn a_channel_no_model_predicts_ships_as_no_compensation() {
    let dir = tempfile::tempdir().unwrap();
    let run = write_run(dir.path(), "run.csv", false);
    let fit_file = dir.path().join("fit.json");
    let v = fit(&run, &fit_file);
    assert_eq!(v["chosen"]["dz_um"], "none", "{}", v["chosen"]);
    assert_ne!(v["chosen"]["dx_um"], "none", "{}", v["chosen"]);
    assert!(
        v["notes"].as_array().unwrap().iter().any(|n| n
            .as_str()
            .unwrap()
            .starts_with("dz_um: no model beats no compensation")),
        "{}",
        v["notes"]
    );

    let img = dir.path().join("m.img");
    let o = export(&fit_file, &run, &img, &["--json"]);
    ok(&o);
    let shipped: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let r = replay(&run, &img);
    let dz = channel(&r, "dz_um");
    // Served 0 throughout: the residual is the measured error itself.
    assert_eq!(dz["never_worse"], true, "{dz}");
    assert_eq!(dz["rms_um"], dz["uncompensated_rms_um"], "{dz}");
    let dx = channel(&r, "dx_um");
    assert!(dx["reduction_pct"].as_f64().unwrap() > 80.0, "{dx}");

    // `--use` still ships the lagged MLR for it on request.
    let img2 = dir.path().join("m2.img");
    let o = export(&fit_file, &run, &img2, &["--use", "dz_um=mlr", "--json"]);
    ok(&o);
    let forced: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // The z table is in the image now (more bytes, a quantised z model).
    assert!(
        forced["bytes"].as_u64() > shipped["bytes"].as_u64(),
        "{forced} vs {shipped}"
    );
    assert_eq!(shipped["max_deviation_um"][1], 0.0, "{shipped}");
    assert!(
        forced["max_deviation_um"][1].as_f64().unwrap() > 0.0,
        "{forced}"
    );
}

#[test]
fn export_refuses_an_image_with_no_model_in_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = write_run(dir.path(), "noise.csv", true);
    let fit_file = dir.path().join("fit.json");
    let v = fit(&run, &fit_file);
    assert_eq!(v["chosen"]["dx_um"], "none", "{}", v["chosen"]);
    assert_eq!(v["chosen"]["dz_um"], "none", "{}", v["chosen"]);
    let img = dir.path().join("m.img");
    let o = export(&fit_file, &run, &img, &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("no channel has a model to ship"), "{err}");
    assert!(!img.exists());
}

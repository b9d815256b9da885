//! `tcomp diagnose fit` (no machine file) on runs written exactly as the
//! run-CSV format defines them: `T_ambient` as the ambient input, sensors
//! named `T_T0…T_T15`, no `coolant_on`, one run without `spindle_rpm`
//! (data in tests/data/diagnose-fit, made by its make.sh).
use tcomp::diagnose::fitmode::diagnose_fit;
use tcomp::diagnose::ident::Problem;
use tcomp::diagnose::series;
use tcomp::diagnose::Options;
use tcomp::runcsv::Run;

fn data(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/diagnose-fit")
        .join(name)
}

fn read(name: &str) -> (String, Run) {
    (name.to_string(), Run::read(&data(name)).unwrap())
}

#[test]
fn t_ambient_is_the_ambient_input_and_every_t_column_a_sensor() {
    let runs = [read("warm-a.csv"), read("mixed-b.csv")];
    let ds = series::load(&runs, 1500).unwrap();
    assert!(ds.has_ambient && ds.has_rpm && !ds.has_coolant);
    let want: Vec<String> = (0..16).map(|i| format!("T_T{i}")).collect();
    assert_eq!(ds.sensors, want);
    assert_eq!(ds.disps, vec!["dx_um", "dz_um"]);
    let d = diagnose_fit(&runs, &Options::default()).unwrap();
    let j = d.to_json();
    let sensors = j["where"]["sensors"].as_object().unwrap();
    assert_eq!(sensors.len(), 16);
    assert!(!sensors.contains_key("T_ambient") && !sensors.contains_key("ambient"));
    for s in &want {
        assert!(
            sensors[s]["rms"].as_f64().unwrap() > 0.0,
            "{s} has no residual"
        );
    }
    // the nominal reports its own held-out fit, in °C and µm
    assert!(j["nominal"]["held_out_rms_c"].as_f64().unwrap() > 0.0);
    assert!(j["nominal"]["held_out_rms_um"].as_f64().unwrap() > 0.0);
    assert_eq!(
        j["missing"].as_array().unwrap().len(),
        1,
        "{}",
        j["missing"]
    );
    assert!(j["missing"][0].as_str().unwrap().contains("coolant_on"));
}

#[test]
fn every_run_is_used_for_fitting_and_for_scoring() {
    let runs = [read("warm-a.csv"), read("mixed-b.csv")];
    let ds = series::load(&runs, 1500).unwrap();
    for r in &ds.runs {
        let held = r.held.iter().filter(|h| **h).count();
        assert!(
            held > r.rows() / 4 && held < r.rows() / 2,
            "{held} of {}",
            r.rows()
        );
        // fit rows at the start and at the end of each run, held-out in between
        assert!(!r.held[0] && !r.held[r.rows() - 1]);
        assert!(r.held[r.rows() * 3 / 10] && r.held[r.rows() * 7 / 10]);
    }
    let p = Problem::new(&ds);
    let (_, fit) = p.identify();
    let fit_rows: usize = ds
        .runs
        .iter()
        .map(|r| r.held.iter().filter(|h| !**h).count())
        .sum();
    // each sensor's model is fitted on the fit rows of both runs
    for f in fit.outs.iter() {
        assert_eq!(f.n_fit, fit_rows);
        assert_eq!(f.resid.len(), 2);
    }
}

#[test]
fn a_run_without_spindle_rpm_is_diagnosed_and_says_what_it_costs() {
    let exe = env!("CARGO_BIN_EXE_tcomp");
    let out = std::process::Command::new(exe)
        .args(["diagnose", "fit"])
        .arg(data("norpm-a.csv"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains("spindle_rpm"))
        .collect();
    assert_eq!(lines.len(), 1, "{stdout}");
    assert!(lines[0].contains("cannot be tested"), "{}", lines[0]);
    let out = std::process::Command::new(exe)
        .args(["diagnose", "fit", "--json"])
        .arg(data("norpm-a.csv"))
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["nominal"]["speed_exponent"], serde_json::Value::Null);
    assert!(v["nominal"]["drive"]
        .as_str()
        .unwrap()
        .contains("temperatures"));
    assert!(v["untestable"]
        .as_array()
        .unwrap()
        .iter()
        .any(|u| u["name"].as_str().unwrap().contains("speed")));
    assert_eq!(v["where"]["sensors"].as_object().unwrap().len(), 16);
}

#[test]
fn bad_runs_get_one_line_errors() {
    let exe = env!("CARGO_BIN_EXE_tcomp");
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("amb-only.csv");
    let mut s = String::from("time_s,T_ambient,dx_um\n");
    for k in 0..30 {
        s.push_str(&format!("{},20,{}\n", k * 60, k as f64 * 0.1));
    }
    std::fs::write(&p, s).unwrap();
    let out = std::process::Command::new(exe)
        .args(["diagnose", "fit"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no temperature sensor column"), "{err}");
    assert!(!err.contains("{ "), "Debug form in {err}");
}

//! Diagnosis: finds a strong injected effect, claims nothing on a clean run,
//! JSON shape, phase classification, CLI end to end.
use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{diagnose, phases, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

/// `desktop/`, where the machine and duty files are.
fn examples() -> std::path::PathBuf {
    std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"))
}

fn turning() -> Machine {
    Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap()
}

fn run_with(m: &Machine, effects: Vec<Effect>, seed: u64) -> Run {
    let duty = Duty::load(&examples().join("duty/production-mixed.toml")).unwrap();
    sim_run(
        m,
        &duty,
        &SimOptions {
            effects,
            seed,
            hours: Some(4.0),
            sample_period_s: Some(20.0),
            noise: true,
        },
    )
    .unwrap()
}

#[test]
fn finds_a_strong_ballscrew_effect_and_shrinks_the_gap() {
    let m = turning();
    let run = run_with(&m, vec![Effect::Ballscrew { k_w: 120.0 }], 11);
    // closed world: the file is the simulator's own, exact by construction
    let exact = Options {
        exact: true,
        ..Options::default()
    };
    let d = diagnose(&m, &[("r".into(), run)], &exact).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(top.name, "ballscrew");
    let ((before, _), (after, _)) = top.gap_um.unwrap();
    assert!(after < 0.3 * before, "held-out gap {before} → {after} µm");
    let k = top.params_json()["k_w"].as_f64().unwrap();
    assert!((k - 120.0).abs() < 25.0, "fitted k_w {k}");
    let j = d.to_json();
    let e = &j["effects"][0];
    for key in [
        "name",
        "params",
        "gap_before_um",
        "gap_after_um",
        "evidence",
    ] {
        assert!(!e[key].is_null(), "missing {key}");
    }
    assert!(j["where"]["sensors"]["T10"].is_object());
    assert!(j["where"]["phases"].is_object() && j["where"]["bands"].is_object());
}

#[test]
fn finds_a_sensor_offset_on_the_right_sensor() {
    let m = turning();
    let run = run_with(
        &m,
        vec![Effect::SensorOffset {
            sensor: "T07".into(),
            offset_c: -0.8,
            at_s: 0.0,
            run: None,
        }],
        12,
    );
    let d = diagnose(&m, &[("r".into(), run)], &Options::default()).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(top.name, "sensor_offset");
    assert_eq!(top.params_json()["sensor"], "T07");
    assert!((top.params_json()["offset_c"].as_f64().unwrap() + 0.8).abs() < 0.05);
}

#[test]
fn claims_nothing_on_clean_runs() {
    let m = turning();
    for seed in [21, 22] {
        let run = run_with(&m, vec![], seed);
        let d = diagnose(&m, &[("r".into(), run)], &Options::default()).unwrap();
        assert!(
            d.findings.is_empty(),
            "false alarm: {:?}",
            d.findings.iter().map(|f| &f.name).collect::<Vec<_>>()
        );
        assert_eq!(d.to_json()["effects"].as_array().unwrap().len(), 0);
    }
}

#[test]
fn two_runs_hold_out_the_end_of_every_hour_of_each() {
    let m = turning();
    let a = run_with(&m, vec![Effect::Convection { h_w_per_m2k: 12.0 }], 31);
    let b = run_with(&m, vec![Effect::Convection { h_w_per_m2k: 12.0 }], 32);
    let runs = [("a".to_string(), a.clone()), ("b".to_string(), b.clone())];
    let ps = tcomp_thermal::diagnose::prepare_all(&m, &runs, &Options::default()).unwrap();
    for p in &ps {
        let dt = p.inputs.dt;
        for (k, held) in p.held.iter().enumerate() {
            // 20 s rows: minutes 36–60 of every hour are held out
            let minute = (k as f64 * dt / 60.0) % 60.0;
            assert_eq!(*held, minute >= 36.0 - 1e-9, "row {k} ({minute} min)");
        }
    }
    let d = diagnose(
        &m,
        &[("a".into(), a), ("b".into(), b)],
        &Options {
            only: vec!["convection".into(), "coolant".into()],
            // the file is the simulator's own (exact): the convection effect
            exact: true,
            ..Options::default()
        },
    )
    .unwrap();
    assert_eq!(d.findings[0].name, "convection");
    let h = d.findings[0].params_json()["h"].as_f64().unwrap();
    assert!((h - 12.0).abs() < 1.5, "h = {h}");
}

#[test]
fn phases_from_spindle_speed() {
    let mut rpm = vec![0.0; 10];
    rpm.extend(vec![3000.0; 400]);
    rpm.extend(vec![6000.0; 100]);
    rpm.extend(vec![0.0; 10]);
    let p = phases(&rpm, 10.0);
    assert_eq!(p[0], "idle");
    assert_eq!(p[15], "warm_up");
    assert_eq!(p[380], "steady");
    assert_eq!(p[415], "speed_change");
    assert_eq!(p[515], "cool_down");
}

#[test]
fn cli_sim_then_diagnose_json() {
    let exe = env!("CARGO_BIN_EXE_tcomp");
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("run.csv");
    let st = std::process::Command::new(exe)
        .args([
            "sim",
            "machines/turning-center-16.toml",
            "--duty",
            "duty/warmup-steps.toml",
            "--hours",
            "4",
            "--sample-period",
            "30",
        ])
        .args(["--effect", "bending=k_um_per_k:2.5", "--seed", "3", "-o"])
        .arg(&csv)
        .current_dir(examples())
        .status()
        .unwrap();
    assert!(st.success());
    let out = std::process::Command::new(exe)
        .args([
            "diagnose",
            "machines/turning-center-16.toml",
            "--json",
            "--report",
        ])
        .arg(dir.path().join("r.md"))
        .arg(&csv)
        .current_dir(examples())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["effects"][0]["name"], "bending");
    let md = std::fs::read_to_string(dir.path().join("r.md")).unwrap();
    assert!(md.contains("## Where the gap lies"));
    // a bad effect spec is a clear error
    let out = std::process::Command::new(exe)
        .args([
            "sim",
            "machines/turning-center-16.toml",
            "--duty",
            "duty/warmup-steps.toml",
            "--effect",
            "convection=h:x",
            "-o",
        ])
        .arg(&csv)
        .current_dir(examples())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("must be a number"));
}

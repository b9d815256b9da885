//! `tcomp export` on a run that records each column's sensor by ROM code
//! (`# rom.T_a: …`, as `tcomp record` writes them): the image names the
//! model's sensors by ROM (`"sensors_by_rom"` in `--json`), `tcomp replay`
//! reads them from the run's columns by ROM, and a run with ROM codes for
//! only some of the model's sensors is refused in one line.
use std::process::Command;

use tcomp_model::fit::{FeatureKind, FeatureSpec, MlrParams, ModelFile};

fn tcomp(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap()
}

/// A DS18B20 ROM code with a valid CRC-8, as 16 hex digits.
fn rom(n: u8) -> ([u8; 8], String) {
    let mut r = [0x28, n, 0x4C, 0x1A, 0x02, 0x16, 0x03, 0];
    r[7] = thermocomp_core::image::rom_crc8(&r[..7]);
    (r, tcomp_data::runcsv::format_rom(&r))
}

#[test]
fn export_names_sensors_by_the_rom_codes_the_run_records() {
    let dir = std::env::temp_dir().join(format!("tcomp-export-rom-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let feature = |name: &str| FeatureSpec {
        kind: FeatureKind::SensorRise(name.into()),
        tau_s: None,
        min: -0.5,
        max: 12.0,
    };
    let file = ModelFile {
        mlr: vec![MlrParams {
            features: vec![feature("T_b"), feature("T_a")],
            c0: 0.5,
            coef: vec![4.0, -1.5],
            channel: "dz_um".into(),
        }],
        chosen: [("dz_um".to_string(), "mlr".to_string())]
            .into_iter()
            .collect(),
        ..Default::default()
    };
    let fit = dir.join("fit.json");
    std::fs::write(&fit, serde_json::to_string(&file).unwrap()).unwrap();
    let (ra, ha) = rom(1);
    let (rb, hb) = rom(2);
    let mut body = String::from("time_s,spindle_rpm,T_a,T_b,dz_um\n");
    for i in 0..60 {
        body += &format!(
            "{},0,{:.2},{:.2},0\n",
            i * 60,
            20.0 + 0.05 * f64::from(i),
            21.0 + 0.1 * f64::from(i)
        );
    }
    let run = dir.join("run.csv");
    std::fs::write(
        &run,
        format!("# source: recorded\n# rom.T_a: {ha}\n# rom.T_b: {hb}\n{body}"),
    )
    .unwrap();
    let img = dir.join("by-rom.img");
    let (f, r, i) = (
        fit.to_str().unwrap(),
        run.to_str().unwrap(),
        img.to_str().unwrap(),
    );
    let out = tcomp(&["export", "--model", f, "--run", r, "-o", i, "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["sensors_by_rom"], 2, "{json}");
    let model = thermocomp_core::Model::parse(&std::fs::read(&img).unwrap()).unwrap();
    // Sensor 0 is T_b (the first feature), column 1; sensor 1 is T_a, column 0.
    assert_eq!((model.sensors[0].rom, model.sensors[0].channel), (rb, 1));
    assert_eq!((model.sensors[1].rom, model.sensors[1].channel), (ra, 0));
    // The replay reads them by ROM: the same run with the columns' sensors
    // recorded the other way round (and their data swapped) replays the same.
    let base = tcomp(&["replay", r, i, "--json"]);
    assert!(
        base.status.success(),
        "{}",
        String::from_utf8_lossy(&base.stderr)
    );
    let mut swapped_body = String::from("time_s,spindle_rpm,T_a,T_b,dz_um\n");
    for line in body.lines().skip(1) {
        let v: Vec<&str> = line.split(',').collect();
        swapped_body += &format!("{},{},{},{},{}\n", v[0], v[1], v[3], v[2], v[4]);
    }
    let swapped = dir.join("swapped.csv");
    std::fs::write(
        &swapped,
        format!("# rom.T_a: {hb}\n# rom.T_b: {ha}\n{swapped_body}"),
    )
    .unwrap();
    let again = tcomp(&["replay", swapped.to_str().unwrap(), i, "--json"]);
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    let channels = |o: &std::process::Output| {
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["channels"].clone()
    };
    assert_eq!(channels(&base), channels(&again));
    assert!(channels(&base).to_string().contains("rms_um"));
    // ROM codes for only one of the two sensors: refused in one line.
    let partial = dir.join("partial.csv");
    std::fs::write(&partial, format!("# rom.T_a: {ha}\n{body}")).unwrap();
    let out = tcomp(&[
        "export",
        "--model",
        f,
        "--run",
        partial.to_str().unwrap(),
        "-o",
        i,
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("not for T_b"), "{err}");
    // A mistyped code: one line naming the key.
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, format!("# rom.T_a: {}0\n{body}", &ha[..15])).unwrap();
    let out = tcomp(&[
        "export",
        "--model",
        f,
        "--run",
        bad.to_str().unwrap(),
        "-o",
        i,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("rom.T_a"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// `export --demo --model-version N` writes version N into the image (the
/// board's command 1 refuses an image not newer than the one it serves).
#[test]
fn the_demo_export_takes_the_model_version_it_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.bin");
    let o = tcomp(&[
        "export",
        "--demo",
        "--model-version",
        "7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&out).unwrap();
    let model = thermocomp_core::image::Model::parse(&bytes).unwrap();
    assert_eq!(model.model_version, 7);
}

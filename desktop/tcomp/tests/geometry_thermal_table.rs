//! From line files at several temperature states to the board's image:
//! `geometry fit-thermal --table` writes the volumetric polynomial with its
//! per-kelvin terms (seed 001 s31–s32) and `export --geometry` packs it.
use std::process::Command;
use tcomp_geometry::volumetric::VolumetricPoly;

fn tcomp(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn fit_thermal_writes_a_table_with_temperature_terms_that_export_packs() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).display().to_string();
    tcomp(&[
        "geometry",
        "simulate",
        "--seed",
        "4",
        "--states",
        "7",
        "-o",
        &d("lines"),
    ]);
    let mut files: Vec<String> = std::fs::read_dir(d("lines"))
        .unwrap()
        .map(|e| e.unwrap().path().display().to_string())
        .filter(|p| p.ends_with(".csv"))
        .collect();
    files.sort();
    let mut args = vec!["geometry", "fit-thermal", "--json", "--table"];
    let table = d("vol.json");
    args.push(&table);
    args.extend(files.iter().map(String::as_str));
    let report: serde_json::Value = serde_json::from_str(&tcomp(&args)).unwrap();
    assert_eq!(report["table"]["path"], table.as_str());

    let poly: VolumetricPoly =
        serde_json::from_str(&std::fs::read_to_string(&table).unwrap()).unwrap();
    assert_eq!(poly.sensors, ["xscrew", "column", "bed"]);
    assert!(poly.max_fit_error_um < 0.01, "{}", poly.max_fit_error_um);
    assert!(poly.terms.iter().any(|t| t.sensor.is_some()));
    // The simulated machine's errors change by about a tenth of the cold
    // errors per kelvin: 5 K on one sensor must move the stroke-end tool tip.
    let end = [800.0, 500.0, 400.0];
    let at_ref = poly.eval(end, 100.0, &poly.t_ref_c);
    let warm: Vec<f64> = poly.t_ref_c.iter().map(|t| t + 5.0).collect();
    let at_warm = poly.eval(end, 100.0, &warm);
    let moved = (0..3)
        .map(|k| (at_warm[k] - at_ref[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(moved > 1.0, "{moved} µm for +5 K");

    // A run whose T_ columns give the sensors' board channels.
    std::fs::write(
        d("run.csv"),
        "time_s,T_bed,T_xscrew,T_column,dx_um\n0,20,20,20,0\n10,21,22,20.5,1\n",
    )
    .unwrap();
    let img = d("x.img");
    let out: serde_json::Value = serde_json::from_str(&tcomp(&[
        "export",
        "--demo",
        "--geometry",
        &table,
        "--run",
        &d("run.csv"),
        "-o",
        &img,
        "--json",
    ]))
    .unwrap();
    let v = &out["volumetric"];
    assert_eq!(v["sensors"], 3);
    assert_eq!(v["terms"], poly.terms.len());
    assert!(v["max_error_um"].as_f64().unwrap() <= v["bound_um"].as_f64().unwrap());
    let bytes = std::fs::read(&img).unwrap();
    let model = thermocomp_core::Model::parse(&bytes).unwrap();
    let section = model
        .volumetric
        .as_ref()
        .expect("the image carries the section");
    // Channels follow the run's column order: bed is channel 0, xscrew 1, column 2.
    let channels: Vec<u8> = section.sensors.iter().map(|s| s.sensor.channel).collect();
    assert_eq!(channels, [1, 2, 0]);
}

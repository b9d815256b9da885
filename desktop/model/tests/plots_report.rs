//! `tcomp report` writes the promised SVG plots from a run and a model image.
#[test]
fn report_writes_temperature_error_residual_and_cluster_plots() {
    let dir = tempfile::tempdir().unwrap();
    let img = dir.path().join("model.img");
    tcomp_model::export::export(&thermocomp_core::float::demo_model(1), &img).unwrap();
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06,dZ_um,dX_um\n");
    for i in 0..200 {
        csv += &format!("{},{}", i * 15, if i > 20 { 6000 } else { 0 });
        for c in 0..6 {
            csv += &format!(
                ",{:.3}",
                20.0 + f64::from(i) * 0.01 * f64::from(c + 1) + f64::from((i * 7 + c) % 5) * 0.05
            );
        }
        csv += &format!(",{:.2},{:.2}\n", f64::from(i) * -0.1, f64::from(i) * 0.05);
    }
    let run = dir.path().join("run.csv");
    std::fs::write(&run, csv).unwrap();
    let out = dir.path().join("plots");
    let files = tcomp_model::plots::report(&run, Some(&img), true, &out).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "temperatures.svg",
            "error_dZ_um.svg",
            "residual_dZ_um.svg",
            "error_dX_um.svg",
            "residual_dX_um.svg",
            "clusters.svg"
        ]
    );
    let error = std::fs::read_to_string(out.join("error_dZ_um.svg")).unwrap();
    assert!(
        error.contains("served correction") && error.contains("<polyline"),
        "no series drawn"
    );
    let residual = std::fs::read_to_string(out.join("residual_dX_um.svg")).unwrap();
    assert!(residual.contains("after (measured"));
    let temps = std::fs::read_to_string(out.join("temperatures.svg")).unwrap();
    assert!(temps.contains("T06"));
    assert!(std::fs::read_to_string(out.join("clusters.svg"))
        .unwrap()
        .contains("T01"));
    // A missing run is a clear error, not a panic.
    let e =
        tcomp_model::plots::report(&dir.path().join("nope.csv"), None, false, &out).unwrap_err();
    assert!(format!("{e:#}").contains("nope.csv"), "{e:#}");
}

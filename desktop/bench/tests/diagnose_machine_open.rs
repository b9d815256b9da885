//! Diagnosis WITH a machine file on the open world: the effect-free design
//! file of the separate truth model (`examples/machines/vertical-mc-truth.toml`,
//! `diagnose/truth.rs`), the machine-format parts it needs (feed-driven
//! sources, a chiller-held coolant circuit switched with the spindle, the
//! `chiller` effect) and one-line errors for them.
use tcomp_bench::truth::{simulate as truth_sim, TruthEffect};
use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{diagnose, Options};
use tcomp_thermal::sim::{simulate, Duty, Effect, Inputs, Machine};

fn design() -> Machine {
    let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/machines/vertical-mc-truth.toml");
    Machine::load(&p).unwrap()
}

/// A light and a heavy 4 h duty (start s, rpm, feed).
fn duties() -> [Vec<(f64, f64, f64)>; 2] {
    [
        vec![
            (0.0, 0.0, 0.0),
            (900.0, 4000.0, 0.3),
            (4500.0, 0.0, 0.0),
            (6300.0, 6000.0, 0.6),
            (10800.0, 2500.0, 0.1),
        ],
        vec![
            (0.0, 0.0, 0.0),
            (600.0, 11000.0, 0.8),
            (4200.0, 0.0, 0.0),
            (5400.0, 8000.0, 0.4),
            (9000.0, 12000.0, 1.0),
            (12600.0, 0.0, 0.0),
        ],
    ]
}

fn case(effects: &[TruthEffect], seed: u64) -> Vec<(String, Run)> {
    duties()
        .iter()
        .enumerate()
        .map(|(i, d)| {
            // a sensor step happens once: in the second run only
            let eff: Vec<TruthEffect> = effects
                .iter()
                .filter(|e| i == 1 || !matches!(e, TruthEffect::SensorStep { .. }))
                .cloned()
                .collect();
            (
                format!("run{i}"),
                truth_sim(d, &eff, 4.0, 10.0, seed + i as u64).run,
            )
        })
        .collect()
}

fn inputs(n: usize, rpm: f64, feed: f64) -> Inputs {
    Inputs {
        t0: 0.0,
        dt: 10.0,
        rpm: vec![rpm; n],
        feed: vec![feed; n],
        coolant: vec![0.0; n],
        ambient: vec![20.0; n],
    }
}

#[test]
fn the_design_file_follows_the_truth_machine_on_a_clean_run() {
    let m = design();
    let runs = case(&[], 3);
    for (name, run) in &runs {
        let duty = Duty::from_run(run, name).unwrap();
        let inp = duty.inputs_rows(20.0);
        let out = simulate(&m, &inp, &[], 1).unwrap();
        for (s, col) in m.sensor_cols.iter().enumerate() {
            let meas = run.col(col).unwrap();
            let rms = (meas
                .iter()
                .zip(&out.temps[s])
                .map(|(a, b)| (a.unwrap() - b).powi(2))
                .sum::<f64>()
                / meas.len() as f64)
                .sqrt();
            // sensor noise 0.02 °C and the 1/16 °C step: ≈ 0.03 °C
            assert!(rms < 0.08, "{name} {col}: nominal gap {rms:.3} °C");
        }
        let dz = run.col("dz_um").unwrap();
        let z = m.dir_cols.iter().position(|c| c == "dz_um").unwrap();
        let peak = dz.iter().map(|v| v.unwrap().abs()).fold(0.0, f64::max);
        let rms = (dz
            .iter()
            .zip(&out.disp[z])
            .map(|(a, b)| (a.unwrap() - b).powi(2))
            .sum::<f64>()
            / dz.len() as f64)
            .sqrt();
        assert!(peak > 5.0, "{name}: the run moves ({peak:.1} µm)");
        assert!(rms < 0.1 * peak, "{name}: dz gap {rms:.2} µm of {peak:.1}");
    }
}

#[test]
fn feed_sources_and_the_spindle_switched_jacket_act_as_written() {
    let m = design();
    let table = m.sensor_cols.iter().position(|c| c == "T_T8").unwrap();
    let nose = m.sensor_cols.iter().position(|c| c == "T_T0").unwrap();
    let tank = m.sensor_cols.iter().position(|c| c == "T_T9").unwrap();
    let rest = simulate(&m, &inputs(720, 0.0, 0.0), &[], 1).unwrap();
    let fed = simulate(&m, &inputs(720, 0.0, 1.0), &[], 1).unwrap();
    // 35 W into the table (feed only, spindle still): it warms
    let rise = fed.temps[table][719] - rest.temps[table][719];
    assert!(rise > 0.5, "table rose {rise:.2} °C under feed");
    assert!((fed.temps[nose][719] - rest.temps[nose][719]).abs() < 0.2);
    // the jacket flows with the spindle: at 19 °C it pulls the nose below
    // what the same heat gives without the circuit
    let run = simulate(&m, &inputs(720, 6000.0, 0.0), &[], 1).unwrap();
    let mut dry = m.spec.clone();
    dry.coolant = None;
    dry.sensors.retain(|s| s.node != "coolant");
    let dry = Machine::compile(dry).unwrap();
    let run_dry = simulate(&dry, &inputs(720, 6000.0, 0.0), &[], 1).unwrap();
    assert!(
        run.temps[nose][719] < run_dry.temps[nose][719] - 0.3,
        "jacket {:.2} vs none {:.2}",
        run.temps[nose][719],
        run_dry.temps[nose][719]
    );
    // the coolant probe reads the set point; a cycling chiller swings it
    // within its band around the set point
    assert!(run.temps[tank].iter().all(|v| (*v - 19.0).abs() < 1e-12));
    let cyc = simulate(
        &m,
        &inputs(1440, 6000.0, 0.0),
        &[Effect::Chiller {
            band_c: 1.0,
            power_w: 800.0,
            load_frac: 0.45,
        }],
        1,
    )
    .unwrap();
    let (lo, hi) = cyc.temps[tank]
        .iter()
        .fold((f64::MAX, f64::MIN), |a, v| (a.0.min(*v), a.1.max(*v)));
    assert!(lo > 18.49 && hi < 19.51, "swing {lo:.3}..{hi:.3}");
    assert!(hi - lo > 0.95, "swing {:.3}", hi - lo);
}

#[test]
fn machine_format_errors_are_one_line() {
    let text = std::fs::read_to_string(
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/machines/vertical-mc-truth.toml"),
    )
    .unwrap();
    let cases = [
        (
            text.replace("flows = \"spindle\"", "flows = \"sometimes\""),
            "unknown variant `sometimes`",
        ),
        (
            text.replace(
                "{ node = \"h1\", g_w_per_k = 1.5 }",
                "{ node = \"h1\", g_w_per_k = -1.5 }",
            ),
            "coolant.jacket `h1`: g_w_per_k = -1.5: allowed 0..=1000000 W/K",
        ),
        (
            text.replace(
                "{ node = \"h1\", g_w_per_k = 1.5 }",
                "{ node = \"spindle\", g_w_per_k = 1.5 }",
            ),
            "coolant.jacket: unknown node `spindle`",
        ),
        (
            text.replace("supply_c = 19.0", "supply_c = 900.0"),
            "coolant.supply_c = 900",
        ),
        (
            text.replace("driver = \"feed\"", "driver = \"coolant\""),
            "unknown variant `coolant`",
        ),
        (
            text.replace(
                "bearing_nodes = [\"h1\", \"h8\"]",
                "bearing_nodes = [\"h1\", \"h88\"]",
            ),
            "effects.bearing_nodes: unknown node `h88`",
        ),
    ];
    for (bad, want) in cases {
        let e = format!("{:#}", Machine::from_toml(&bad).unwrap_err());
        assert!(e.contains(want), "`{e}` lacks `{want}`");
        assert!(!e.contains('\n'), "multi-line error: {e}");
    }
    // the chiller needs a circuit with a tank
    let mut dry = design().spec.clone();
    dry.coolant = None;
    dry.sensors.retain(|s| s.node != "coolant");
    let dry = Machine::compile(dry).unwrap();
    let e = simulate(
        &dry,
        &inputs(10, 0.0, 0.0),
        &[Effect::parse("chiller=band_c:1").unwrap()],
        1,
    )
    .unwrap_err();
    assert!(format!("{e}").contains("no [coolant] circuit"), "{e}");
    assert!(Effect::parse("chiller=load_frac:1.5").is_err());
}

#[test]
fn diagnoses_a_sensor_step_on_its_sensor_and_the_run_it_happened_in() {
    let m = design();
    let runs = case(
        &[TruthEffect::SensorStep {
            sensor: 5,
            step_c: 0.6,
            at_s: 6000.0,
        }],
        21,
    );
    let d = diagnose(&m, &runs, &Options::default()).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(top.name, "sensor_offset");
    let p = top.params_json();
    assert_eq!(p["sensor"], "T_T5");
    assert_eq!(p["run"], "run1");
    let at = p["at_s"].as_f64().unwrap();
    assert!((at - 6000.0).abs() <= 1200.0, "onset {at} s");
    assert!((p["offset_c"].as_f64().unwrap() - 0.6).abs() < 0.1, "{p}");
    let ((before, _), (after, _)) = top.gap_c.unwrap();
    assert!(after < 0.7 * before, "held-out {before} → {after} °C");
}

#[test]
fn a_stuck_or_dead_sensor_is_left_out_of_its_run_and_said_and_a_real_step_is_still_found() {
    // the step case above, with T_T4 in the second run stuck at the
    // DS18B20's power-on 85 °C, or unplugged: that channel is left out of
    // that run (said in `missing`), and the step on T_T5 is still named
    // (with the stuck value fitted as is, nothing was named)
    let m = design();
    for stuck in [Some(85.0), None] {
        let mut runs = case(
            &[TruthEffect::SensorStep {
                sensor: 5,
                step_c: 0.6,
                at_s: 6000.0,
            }],
            21,
        );
        let run = &mut runs[1].1;
        let c = run.columns.iter().position(|c| c == "T_T4").unwrap();
        run.data[c].iter_mut().for_each(|v| *v = stuck);
        let d = diagnose(&m, &runs, &Options::default()).unwrap();
        let said: Vec<&String> = d
            .missing
            .iter()
            .filter(|l| l.starts_with("T_T4 "))
            .collect();
        assert_eq!(said.len(), 1, "{:?}", d.missing);
        assert!(said[0].contains("run1"), "{}", said[0]);
        assert_eq!(said[0].contains("(stuck)"), stuck.is_some(), "{}", said[0]);
        let top = d.findings.first().expect("an effect");
        assert_eq!(top.name, "sensor_offset");
        assert_eq!(top.params_json()["sensor"], "T_T5");
    }
}

#[test]
fn diagnoses_a_cycling_chiller_without_a_coolant_on_column() {
    let m = design();
    let runs = case(
        &[TruthEffect::ChillerCycling {
            band_c: 0.8,
            power_w: 900.0,
        }],
        31,
    );
    assert!(runs[0].1.col("coolant_on").is_none());
    let d = diagnose(&m, &runs, &Options::default()).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(
        top.name,
        "chiller",
        "{:?}",
        d.findings.iter().map(|f| &f.name).collect::<Vec<_>>()
    );
    let band = top.params_json()["band_c"].as_f64().unwrap();
    assert!((band - 0.8).abs() < 0.2, "band {band}");
}

#[test]
fn diagnoses_speed_dependent_bearing_heat_at_the_nose_and_nothing_on_a_clean_case() {
    let m = design();
    let runs = case(&[TruthEffect::BearingNonlinear { k_w: 80.0, p: 2.8 }], 41);
    let d = diagnose(&m, &runs, &Options::default()).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(top.name, "bearing_nonlinear");
    assert_eq!(top.params_json()["node"], "h1");
    let ((before, _), (after, _)) = top.gap_um.unwrap();
    assert!(after < before, "held-out µm gap {before} → {after}");
    let clean = diagnose(&m, &case(&[], 51), &Options::default()).unwrap();
    assert!(
        clean.findings.is_empty(),
        "clean case named {:?}",
        clean.findings.iter().map(|f| &f.name).collect::<Vec<_>>()
    );
}

fn design_error() -> Machine {
    let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/machines/vertical-mc-design-error.toml");
    Machine::load(&p).unwrap()
}

#[test]
fn the_design_error_file_is_the_design_off_by_10_to_20_percent_everywhere() {
    let (t, e) = (design(), design_error());
    let mut ratios = Vec::new();
    for (a, b) in t.spec.nodes.iter().zip(&e.spec.nodes) {
        assert_eq!(a.name, b.name);
        ratios.push(b.c_j_per_k / a.c_j_per_k);
        ratios.push(b.g_amb_w_per_k / a.g_amb_w_per_k);
        assert_eq!(a.area_m2, b.area_m2);
    }
    for (a, b) in t.spec.links.iter().zip(&e.spec.links) {
        ratios.push(b.g_w_per_k / a.g_w_per_k);
    }
    for (a, b) in t.spec.sources.iter().zip(&e.spec.sources) {
        ratios.push(b.w_at_nmax / a.w_at_nmax);
        assert_eq!(a.exponent, b.exponent);
    }
    let (ca, cb) = (
        t.spec.coolant.as_ref().unwrap(),
        e.spec.coolant.as_ref().unwrap(),
    );
    ratios.push(cb.tank_c_j_per_k / ca.tank_c_j_per_k);
    ratios.push(cb.tank_g_amb_w_per_k / ca.tank_g_amb_w_per_k);
    for (a, b) in ca.jacket.iter().zip(&cb.jacket) {
        ratios.push(b.g_w_per_k / a.g_w_per_k);
    }
    for (a, b) in t.spec.directions.iter().zip(&e.spec.directions) {
        for (x, y) in a.terms.iter().zip(&b.terms) {
            ratios.push(y.length_mm / x.length_mm);
        }
    }
    assert_eq!(ratios.len(), 99);
    for r in &ratios {
        let off = (r - 1.0).abs();
        assert!((0.099..=0.201).contains(&off), "factor {r}");
    }
    assert!(ratios.iter().filter(|r| **r > 1.0).count() >= 40);
    assert!(ratios.iter().filter(|r| **r < 1.0).count() >= 40);
}

#[test]
fn a_wrong_design_is_calibrated_on_the_fit_rows_and_a_clean_case_names_nothing() {
    let m = design_error();
    let runs = case(&[], 51);
    // taken as exact, the wrong design leaves a gap an effect would absorb
    let opt = Options {
        calibrate: true,
        ..Options::default()
    };
    let ps = tcomp_thermal::diagnose::prepare_all(&m, &runs, &opt).unwrap();
    let cal = tcomp_thermal::diagnose::calibrate::calibrate(&m, &ps, 2).unwrap();
    let before = cal.json["held_out_norm_gap_design"].as_f64().unwrap();
    let after = cal.json["held_out_norm_gap_calibrated"].as_f64().unwrap();
    assert!(after < 0.5 * before, "held-out gap {before} → {after}");
    assert!(cal.json["on_bound"].is_array());
    let d = diagnose(&m, &runs, &opt).unwrap();
    assert!(
        d.findings.is_empty(),
        "clean case named {:?}",
        d.findings.iter().map(|f| &f.name).collect::<Vec<_>>()
    );
    assert!(d.notes.iter().any(|n| n.contains("calibrated")));
    // one heat gain per heated node (h1, h5, h8, table), not per driver
    assert_eq!(d.to_json()["nominal"]["calibration"]["parameters"], 97);
}

#[test]
fn a_wrong_design_still_finds_a_sensor_step_on_its_sensor() {
    let m = design_error();
    let runs = case(
        &[TruthEffect::SensorStep {
            sensor: 6,
            step_c: 0.8,
            at_s: 7000.0,
        }],
        61,
    );
    let opt = Options {
        calibrate: true,
        ..Options::default()
    };
    let d = diagnose(&m, &runs, &opt).unwrap();
    let top = d.findings.first().expect("an effect");
    assert_eq!(top.name, "sensor_offset");
    assert_eq!(top.params_json()["sensor"], "T_T6");
}

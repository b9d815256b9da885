//! MLR recovery, lag filter, feature semantics, GA-BPN vs MLR on held-out blocks.

use tcomp_data::runcsv::Run;
use tcomp_model::fit::net::NetOpts;
use tcomp_model::fit::pipeline::{fit_plan, FeatureChoice, FitConfig, Plan};
use tcomp_model::fit::*;

fn run_from(cols: Vec<(&str, Vec<f64>)>) -> Run {
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.to_string()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

#[test]
fn mlr_recovers_known_coefficients() {
    let n = 500;
    let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin() * 5.0).collect();
    let x2: Vec<f64> = (0..n)
        .map(|i| (i as f64 * 0.11).cos() * 3.0 + 1.0)
        .collect();
    let y: Vec<f64> = x1
        .iter()
        .zip(&x2)
        .map(|(a, b)| 3.0 + 2.0 * a - 1.5 * b)
        .collect();
    let s = Samples {
        x: x1.iter().zip(&x2).map(|(a, b)| vec![*a, *b]).collect(),
        y: y.clone(),
        rows: (0..n).map(|r| (0, r)).collect(),
    };
    let kinds = vec![
        (FeatureKind::SensorRise("T_a".into()), None),
        (FeatureKind::SensorRise("T_b".into()), None),
    ];
    let specs = ranged_specs(&kinds, &s);
    let m = fit_mlr(specs, &s, "dx_um").unwrap();
    // Slopes in raw units: c_i · 2 / (max − min).
    let slope = |i: usize| m.coef[i] * 2.0 / (m.features[i].max - m.features[i].min);
    assert!((slope(0) - 2.0).abs() < 1e-8, "{}", slope(0));
    assert!((slope(1) + 1.5).abs() < 1e-8, "{}", slope(1));
    for (r, t) in s.x.iter().zip(&y) {
        assert!(
            (m.predict_raw(r) - t).abs() < 1e-6,
            "{} vs {t}",
            m.predict_raw(r)
        );
    }
    // JSON round trip of the parameters.
    let j = serde_json::to_string(&m).unwrap();
    let back: MlrParams = serde_json::from_str(&j).unwrap();
    assert_eq!(back, m);
}

/// The board's lag filter on a 1 °C step (the fit trains on the core's
/// pipeline): y(t_k) = 1 − exp(−(t_k − t_0)/τ) for uniform and non-uniform
/// sampling, within the Q8 feature LSB (1/4096 °C) and the Q30 decay's rounding.
#[test]
fn lag_matches_first_order_step_response() {
    let tau = 600.0;
    for times in [
        (0..400).map(|k| k as f64 * 15.0).collect::<Vec<f64>>(),
        (0..400)
            .map(|k| (k * 15 + (k % 3) * 7) as f64)
            .collect::<Vec<f64>>(),
    ] {
        let temp: Vec<f64> = (0..times.len())
            .map(|k| if k == 0 { 20.0 } else { 21.0 })
            .collect();
        let run = run_from(vec![("time_s", times.clone()), ("T_a", temp)]);
        let y = feature_series(&run, &FeatureKind::SensorRise("T_a".into()), Some(tau)).unwrap();
        assert_eq!(y[0], 0.0);
        for k in 1..times.len() {
            let expect = 1.0 - (-(times[k] - times[0]) / tau).exp();
            assert!(
                (y[k] - expect).abs() < 1.0 / 4096.0 + 1e-6,
                "k={k}: {} vs {expect}",
                y[k]
            );
        }
    }
}

/// Gaps and the reference row as on the board: a row with an empty sensor
/// cell has no feature (the board holds its correction), the reference is the
/// first row with a value, and after a gap the filter catches up over the
/// whole elapsed steps (the same value as without the gap for a steady input).
#[test]
fn features_follow_the_boards_gap_and_reference_rules() {
    let times: Vec<f64> = (0..20).map(|k| k as f64 * 15.0).collect();
    let temp = |k: usize| if k < 3 { 20.0 } else { 22.0 };
    let full = run_from(vec![
        ("time_s", times.clone()),
        ("T_a", (0..20).map(temp).collect()),
    ]);
    let mut gappy = full.clone();
    gappy.data[1][0] = None; // leading gap: the reference is row 1
    gappy.data[1][8] = None;
    gappy.data[1][9] = None;
    let kind = FeatureKind::SensorRise("T_a".into());
    let a = feature_series(&full, &kind, Some(300.0)).unwrap();
    let b = feature_series(&gappy, &kind, Some(300.0)).unwrap();
    assert!(b[0].is_nan() && b[8].is_nan() && b[9].is_nan());
    assert_eq!(b[1], 0.0, "reference row 1");
    assert!(
        (b[10] - a[10]).abs() < 1.0 / 4096.0,
        "{} vs {}",
        b[10],
        a[10]
    );
    let rise = feature_series(&gappy, &kind, None).unwrap();
    assert_eq!(rise[5], 2.0);
}

#[test]
fn features_quantize_rise_and_diff() {
    let run = run_from(vec![
        ("time_s", vec![0.0, 10.0, 20.0]),
        ("spindle_rpm", vec![0.0, 1000.0, 1000.0]),
        ("T_a", vec![20.03, 21.0, 22.51]),
        ("T_b", vec![19.0, 19.0, 19.97]),
        ("dx_um", vec![0.0, 1.0, 2.0]),
    ]);
    let rise = feature_series(&run, &FeatureKind::SensorRise("T_a".into()), None).unwrap();
    // 20.03 → 20.0 (1/16 steps), 21.0 → 21.0, 22.51 → 22.5.
    assert_eq!(rise, vec![0.0, 1.0, 2.5]);
    let diff = feature_series(
        &run,
        &FeatureKind::SensorDiff("T_a".into(), "T_b".into()),
        None,
    )
    .unwrap();
    assert_eq!(diff, vec![1.0, 2.0, 2.5]);
    let rpm = feature_series(&run, &FeatureKind::Spindle, Some(10.0)).unwrap();
    assert_eq!(rpm[0], 0.0);
    // Ten whole 1 s steps of the Q30 decay; the feature is Q8 of 1 rpm.
    assert!((rpm[1] - 1000.0 * (1.0 - (-1.0f64).exp())).abs() < 1.0 / 256.0 + 1e-6);
    assert!(feature_series(&run, &FeatureKind::SensorRise("T_zz".into()), None).is_err());
    let (k, t) = parse_feature("T_a-T_b@1800").unwrap();
    assert_eq!(k, FeatureKind::SensorDiff("T_a".into(), "T_b".into()));
    assert_eq!(t, Some(1800.0));
    assert_eq!(
        parse_feature("rpm@0").unwrap(),
        (FeatureKind::Spindle, None)
    );
    assert!(parse_feature("T_a@x").is_err());
    let spec = FeatureSpec {
        kind: FeatureKind::Spindle,
        tau_s: None,
        min: 0.0,
        max: 10.0,
    };
    assert_eq!(spec.normalize(-5.0), -1.0);
    assert_eq!(spec.normalize(5.0), 0.0);
    assert_eq!(spec.normalize(50.0), 1.0);
}

/// Heating/cooling cycles with a target that saturates nonlinearly in a lagged rise.
pub fn synthetic_nonlinear() -> Run {
    let n = 3000;
    let dt = 20.0;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let mut temp = vec![20.0];
    let mut rpm = vec![0.0];
    for k in 1..n {
        // Alternate speeds; periods of various lengths.
        let phase = (k / 250) % 4;
        let s = [3000.0, 0.0, 6000.0, 1500.0][phase];
        rpm.push(s);
        let target = 20.0 + s / 400.0;
        let prev = temp[k - 1];
        temp.push(target + (-dt / 2500.0f64).exp() * (prev - target));
    }
    let q = |v: f64| (v * 16.0).round() / 16.0;
    let rise: Vec<f64> = temp.iter().map(|v| q(*v) - q(temp[0])).collect();
    let lagged = tcomp_thermal::diagnose::lag::lag_signal(&rise, dt, 1500.0);
    let y: Vec<f64> = lagged
        .iter()
        .map(|r| 40.0 * (r / 6.0).tanh() - 0.8 * r)
        .collect();
    run_from(vec![
        ("time_s", t),
        ("spindle_rpm", rpm),
        ("T_a", temp),
        ("dx_um", y),
    ])
}

#[test]
fn gabpn_beats_mlr_on_nonlinear_lagged_target() {
    let run = synthetic_nonlinear();
    let n = run.rows();
    let plan = Plan::new(vec![run], vec!["syn".into()], 1, Some((0.7, 1.0))).unwrap();
    assert_eq!(plan.val[0].end, n);
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        features: FeatureChoice::List(vec![(FeatureKind::SensorRise("T_a".into()), Some(1500.0))]),
        net: NetOpts {
            hidden: 5,
            population: 16,
            generations: 10,
            lm_iters: 100,
            ..NetOpts::default()
        },
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    let get = |name: &str| rep.models.iter().find(|m| m.name == name).unwrap().channels["dx_um"];
    let (mlr, net) = (get("mlr"), get("ga-bpn"));
    assert!(
        net.rms_um < 0.5 * mlr.rms_um,
        "net {:?} vs mlr {:?}",
        net,
        mlr
    );
    assert!(net.reduction_pct > 90.0, "{net:?}");
    // Cross-validation on the training rows alone picks the network here.
    assert_eq!(rep.chosen["dx_um"], "ga-bpn", "{:?}", rep.inputs[0].cv);
    assert_eq!(rep.model_file.nets.len(), NetOpts::default().ensemble);
    // The exported network predicts exactly what was validated.
    let np = &rep.model_file.nets[0];
    assert_eq!(np.w1.len(), 5);
    assert!(np
        .w1
        .iter()
        .flatten()
        .chain(&np.b1)
        .all(|w| w.abs() < 2000.0));
}

/// Two sensors warming at different rates (first-order responses to the
/// spindle schedule of `synthetic_nonlinear`), and a target linear in them.
fn synthetic_linear(n_extra_sensors: usize) -> Run {
    let base = synthetic_nonlinear();
    let t = base.time_s();
    let rpm: Vec<f64> = base
        .col("spindle_rpm")
        .unwrap()
        .iter()
        .map(|v| v.unwrap())
        .collect();
    let respond = |tau: f64, gain: f64| -> Vec<f64> {
        let mut out = vec![20.0];
        for k in 1..t.len() {
            let target = 20.0 + rpm[k] * gain;
            let prev = out[k - 1];
            out.push(target + (-(t[k] - t[k - 1]) / tau).exp() * (prev - target));
        }
        out
    };
    let a = respond(2500.0, 1.0 / 400.0);
    let b = respond(9000.0, 1.0 / 900.0);
    let y: Vec<f64> = a
        .iter()
        .zip(&b)
        .map(|(a, b)| 3.0 * (a - 20.0) - 2.0 * (b - 20.0))
        .collect();
    let mut cols = vec![
        ("time_s".to_string(), t.clone()),
        ("spindle_rpm".to_string(), rpm.clone()),
    ];
    // Extra sensors first: the informative pair sits beyond them.
    for i in 0..n_extra_sensors {
        cols.push((
            format!("T_x{i:02}"),
            respond(4000.0 + 300.0 * i as f64, 1.0 / 5000.0),
        ));
    }
    cols.push(("T_a".into(), a));
    cols.push(("T_b".into(), b));
    cols.push(("dx_um".into(), y));
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.clone()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

fn quick_net() -> NetOpts {
    NetOpts {
        hidden: 4,
        population: 12,
        generations: 6,
        lm_iters: 40,
        ensemble: 2,
        ..NetOpts::default()
    }
}

#[test]
fn cross_validation_prefers_the_simplest_model_that_is_good_enough() {
    let run = synthetic_linear(0);
    let plan = Plan::new(vec![run], vec!["lin".into()], 1, Some((0.7, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        candidates: tcomp_model::fit::pipeline::Candidates::All,
        net: quick_net(),
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    let cv = &rep.inputs[0].cv;
    assert!(
        cv.contains_key("mlr") && cv.contains_key("ga-bpn"),
        "{cv:?}"
    );
    // The target is linear in the sensors: a network cannot be clearly better,
    // so the choice is a linear model, and it is what the model file ships.
    assert_ne!(rep.chosen["dx_um"], "ga-bpn", "{cv:?}");
    assert_eq!(rep.model_file.chosen, rep.chosen);
    let chosen = &cv[&rep.chosen["dx_um"]];
    assert!(chosen.rms_um < 0.5, "{cv:?}");
    // The validation block was never used for the choice: the CV rows are training rows.
    let train_rows: usize = rep.train_segments.iter().map(|s| s.end - s.start).sum();
    assert!(
        chosen.rows <= train_rows && chosen.rows > train_rows / 2,
        "{chosen:?}"
    );
}

#[test]
fn sensors_beyond_the_boards_channels_are_never_candidates() {
    use thermocomp_core::limits::MAX_SENSORS;
    // 22 extra sensors: T_a and T_b (the informative ones) are columns 23 and 24.
    let run = synthetic_linear(22);
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    let plan = Plan::new(vec![run], vec!["wide".into()], 1, Some((0.7, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        candidates: tcomp_model::fit::pipeline::Candidates::All,
        skip_net: true,
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    assert!(
        rep.notes.iter().any(|n| n.contains("beyond the board")),
        "{:?}",
        rep.notes
    );
    for m in rep.model_file.mlr.iter().chain(&rep.model_file.mlr_static) {
        for f in &m.features {
            for c in f.kind.columns() {
                if c != "spindle_rpm" {
                    let ch = columns.iter().position(|x| x == c).unwrap();
                    assert!(ch < MAX_SENSORS, "{c} is channel {ch}");
                }
            }
        }
    }
    // What fit produced exports; a model naming channel 23 is refused, naming the limit.
    let opts = tcomp_model::export::ExportOptions::default();
    tcomp_model::export::float_model_from_fit(&rep.model_file, &columns, &opts).unwrap();
    let mut bad = rep.model_file.clone();
    bad.mlr[0].features[0].kind = FeatureKind::SensorRise("T_a".into());
    bad.chosen.insert("dx_um".into(), "mlr".into());
    let err = tcomp_model::export::float_model_from_fit(&bad, &columns, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("MAX_SENSORS") && err.contains("T_a"), "{err}");
    assert!(!err.contains('\n'), "one line: {err}");
}

#[test]
fn lags_longer_than_the_training_span_are_not_candidates() {
    let run = synthetic_linear(0);
    // 3000 rows × 20 s, 30 % for training: 5 h; a 6 h lag cannot be learned.
    let plan = Plan::new(vec![run], vec!["short".into()], 1, Some((0.3, 0.5))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.3, 0.5)),
        lags: vec![0.0, 3600.0, 21600.0],
        skip_net: true,
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    assert!(
        rep.notes.iter().any(|n| n.contains("training span")),
        "{:?}",
        rep.notes
    );
    for i in &rep.inputs {
        assert!(
            i.features.iter().all(|f| !f.ends_with("@21600")),
            "{:?}",
            i.features
        );
    }
}

#[test]
fn capped_samples_stride_evenly_across_segments() {
    let run = synthetic_nonlinear();
    let runs = vec![run];
    let cache =
        SeriesCache::new(&runs, vec![(FeatureKind::SensorRise("T_a".into()), None)]).unwrap();
    let segs = [
        Segment {
            run: 0,
            start: 0,
            end: 1000,
        },
        Segment {
            run: 0,
            start: 2000,
            end: 3000,
        },
    ];
    let full = cache.samples(&runs, &segs, &[0], "dx_um").unwrap();
    let capped = cache
        .samples_capped(&runs, &segs, &[0], "dx_um", 300)
        .unwrap();
    assert_eq!(full.y.len(), 2000);
    assert!(
        capped.y.len() <= 300 && capped.y.len() >= 250,
        "{}",
        capped.y.len()
    );
    // Every 7th row of the concatenated segments (2000 / 300 rounded up), both segments sampled.
    assert_eq!(capped.rows[0], (0, 0));
    assert_eq!(capped.rows[1], (0, 7));
    assert!(capped.rows.iter().any(|r| r.1 >= 2000));
    for (i, r) in capped.rows.iter().enumerate() {
        let k = full.rows.iter().position(|f| f == r).unwrap();
        assert_eq!(k, 7 * i);
        assert_eq!(capped.y[i], full.y[k]);
    }
}

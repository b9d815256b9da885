//! Degraded mode on the desktop (issue 15): `fit` adds fallback models
//! without each model sensor, `export` packs them (image v2), `replay
//! --fail-sensor` shows what the board serves with a sensor lost.
use tcomp_data::runcsv::Run;
use tcomp_model::export::{float_model_from_fit, ExportOptions};
use tcomp_model::fit::pipeline::{fit_plan, FeatureChoice, FitConfig, Plan};
use tcomp_model::fit::*;
use tcomp_model::replay::{parse_failure, replay_failing, residuals, SensorFailure};
use thermocomp_core::compensator::{status, ACTIVE_NONE};
use thermocomp_core::Model;

/// Spindle-driven heating: T_a and T_b respond alike (redundant), T_c
/// slower; the error reads T_a and T_c.
fn machine() -> Run {
    let (n, dt) = (3000usize, 20.0);
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let rpm: Vec<f64> = (0..n)
        .map(|k| [3000.0, 0.0, 6000.0, 1500.0][(k / 250) % 4])
        .collect();
    let respond = |tau: f64, gain: f64| -> Vec<f64> {
        let mut out = vec![20.0];
        for k in 1..n {
            let target = 20.0 + rpm[k] * gain;
            out.push(target + (-dt / tau).exp() * (out[k - 1] - target));
        }
        out
    };
    let a = respond(2500.0, 1.0 / 400.0);
    let b = respond(2700.0, 1.0 / 410.0);
    let c = respond(9000.0, 1.0 / 900.0);
    let y: Vec<f64> = a
        .iter()
        .zip(&c)
        .map(|(a, c)| 3.0 * (a - 20.0) - 2.0 * (c - 20.0))
        .collect();
    let cols = vec![
        ("time_s", t),
        ("spindle_rpm", rpm),
        ("T_a", a),
        ("T_b", b),
        ("T_c", c),
        ("dx_um", y),
    ];
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.to_string()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

fn fitted() -> (Run, pipeline::FitReport) {
    let run = machine();
    let plan = Plan::new(vec![run.clone()], vec!["m".into()], 1, Some((0.6, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.6, 1.0)),
        features: FeatureChoice::List(vec![
            (FeatureKind::SensorRise("T_a".into()), None),
            (FeatureKind::SensorRise("T_c".into()), None),
            (FeatureKind::SensorRise("T_b".into()), None),
        ]),
        skip_net: true,
        ..FitConfig::default()
    };
    (run, fit_plan(&plan, &cfg).unwrap())
}

#[test]
fn fit_adds_a_fallback_per_model_sensor_chosen_and_validated_like_the_main_model() {
    let (_, rep) = fitted();
    let fb = &rep.fallbacks;
    let excluded: Vec<&str> = fb.iter().map(|f| f.excluded[0].as_str()).collect();
    assert_eq!(excluded, ["T_a", "T_c", "T_b"], "{fb:?}");
    for f in fb {
        assert!(
            f.features
                .iter()
                .all(|x| !x.contains(f.excluded[0].as_str())),
            "{f:?}"
        );
        assert!(f.cv.contains_key(&f.model), "chosen by CV: {f:?}");
        assert_eq!(f.validation.n, rep.inputs[0].val_rows);
    }
    // Without T_a its twin T_b stands in; without T_b nothing is lost.
    let main = rep
        .models
        .iter()
        .find(|m| m.name == "mlr")
        .unwrap()
        .channels["dx_um"];
    let without = |s: &str| fb.iter().find(|f| f.excluded[0] == s).unwrap().validation;
    assert!(main.reduction_pct > 99.0, "{main:?}");
    assert!(without("T_a").reduction_pct > 80.0, "{:?}", without("T_a"));
    assert!(without("T_b").reduction_pct > 99.0, "{:?}", without("T_b"));
    // The fit file carries them; JSON round trip.
    let j = serde_json::to_string(&rep.model_file).unwrap();
    let back: ModelFile = serde_json::from_str(&j).unwrap();
    assert_eq!(back.fallbacks.len(), 3);
    assert!(back.fallbacks.iter().all(|f| f.cv_rms_um.is_some()));
    // An old fit file without fallbacks still reads.
    let old: ModelFile = serde_json::from_str(r#"{"mlr":[],"nets":[]}"#).unwrap();
    assert!(old.fallbacks.is_empty());
}

#[test]
fn export_packs_the_fallbacks_and_replay_shows_the_board_with_a_sensor_lost() {
    let (run, rep) = fitted();
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    let float = float_model_from_fit(&rep.model_file, &columns, &ExportOptions::default()).unwrap();
    assert_eq!(float.fallbacks.len(), 3);
    let dir = std::env::temp_dir().join(format!("tcomp-fallback-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let img = dir.join("m.img");
    let summary = tcomp_model::export::export(&float, &img).unwrap();
    assert_eq!(summary.fallbacks, 3);
    let bytes = std::fs::read(&img).unwrap();
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 2, "format v2");
    let model = Model::parse(&bytes).unwrap();

    let mut csv = Vec::new();
    run.write_to(&mut csv).unwrap();
    let csv = String::from_utf8(csv).unwrap();
    let n = run.rows();
    let (a, b) = (n * 6 / 10, n);
    let all = replay_failing(&csv, model.clone(), &[]).unwrap();
    let lost = parse_failure("T_a@60%", &run).unwrap();
    assert_eq!(
        lost,
        SensorFailure {
            channel: 0,
            from_ms: (run.time_s()[a] * 1000.0) as u64
        }
    );
    let failed = replay_failing(&csv, model.clone(), &[lost]).unwrap();
    for (r, f) in all.iter().zip(&failed).take(a) {
        assert_eq!(r.out, f.out, "identical before the loss");
    }
    for f in &failed[a..] {
        assert_eq!(f.out.status & status::DEGRADED, status::DEGRADED);
        let k = usize::from(f.out.active[0]);
        assert!(k >= 1, "a fallback serves");
        assert_eq!(
            model.fallbacks[k - 1].excluded,
            [0, 0xFF],
            "the one without T_a"
        );
        assert_eq!(f.out.active[1], ACTIVE_NONE);
    }
    let r_all = residuals(&run, &all, &model, a, b);
    let r_failed = residuals(&run, &failed, &model, a, b);
    let kept = r_failed[0].reduction_pct / r_all[0].reduction_pct;
    assert!(
        kept > 0.8,
        "kept {kept}: {:?} vs {:?}",
        r_failed[0],
        r_all[0]
    );
    // One-line refusals.
    for bad in ["T_z@10", "T_a", "T_a@x", "T_a@120%"] {
        let e = parse_failure(bad, &run).unwrap_err().to_string();
        assert!(!e.contains('\n') && e.contains("--fail-sensor"), "{e}");
    }
}

#[test]
fn the_image_orders_fallbacks_by_cross_validated_rms() {
    let (run, rep) = fitted();
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    let float = float_model_from_fit(&rep.model_file, &columns, &ExportOptions::default()).unwrap();
    let cv_of = |sensor: u8| {
        let name = &columns[usize::from(float.sensors[usize::from(sensor)].channel)];
        rep.model_file
            .fallbacks
            .iter()
            .find(|f| &f.excluded[0] == name)
            .and_then(|f| f.cv_rms_um)
            .unwrap()
    };
    let cvs: Vec<f64> = float
        .fallbacks
        .iter()
        .map(|f| cv_of(f.excluded[0]))
        .collect();
    assert!(cvs.windows(2).all(|w| w[0] <= w[1]), "{cvs:?}");
}

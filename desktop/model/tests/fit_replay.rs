//! One source of truth for features (issue 11, item 4): `tcomp fit` trains on
//! the math core's feature pipeline, so replaying the training run through
//! the board's fixed-point core reproduces the fit's training residual row
//! by row, within the quantisation of the exported weights.
//!
//! Tolerance per row, |board prediction − fit prediction| (µm), for a linear
//! model exported as a table:
//! - 0.05 µm: the board rounds its prediction to 0.1 µm;
//! - per term, 0.1/512 µm: each coefficient is stored in Q8 of 0.1 µm
//!   (half an LSB), times |x| ≤ 1 for the normalised input;
//! - per term, |coef|·2⁻²³: the input's Q24 normalisation (half an LSB of
//!   Q24, doubled for the gain's rounding) and the term's Q24 product.
//!
//! Nothing else may differ: the features are the same integers on both
//! sides (the fit computes them with `thermocomp_core::features`), so a
//! difference in the reference row, the 1/16 °C rounding, the gap rule or
//! the lag decay would show as errors of 0.1–10 µm, far above this bound.

use tcomp_data::runcsv::Run;
use tcomp_model::export::{float_model_from_fit, parse_choices, ExportOptions};
use tcomp_model::fit::pipeline::{fit_plan, FitConfig, Plan};
use tcomp_model::fit::{Model as _, SeriesCache};

const TRACE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo/trace.csv");

/// The first `rows` data rows of the demo trace (FL_THERMAL, in the repo).
fn demo_text(rows: usize) -> String {
    let text = std::fs::read_to_string(TRACE).expect("demo/trace.csv");
    let mut out = String::new();
    let mut data = 0usize;
    let mut header = false;
    for line in text.lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        if header {
            if data == rows {
                break;
            }
            data += 1;
        }
        header = true;
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[test]
fn replaying_the_training_run_reproduces_the_training_residual() {
    let csv = demo_text(1200); // 5 h: heating at 1,250 rpm and the start of the cooling
    let run = Run::from_reader(std::io::Cursor::new(csv.as_bytes())).unwrap();
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    let plan = Plan::new(vec![run], vec!["demo".into()], 1, Some((0.6, 0.8))).unwrap();
    let cfg = FitConfig {
        channels: Some(vec!["dch3_um".into(), "dch5_um".into()]),
        skip_net: true,
        lags: vec![0.0, 1800.0, 3600.0],
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    let file = &rep.model_file;
    for choice in ["mlr", "mlr-static"] {
        let opts = ExportOptions {
            choices: parse_choices(&format!("dch3_um={choice},dch5_um={choice}")).unwrap(),
            ..ExportOptions::default()
        };
        let float = float_model_from_fit(file, &columns, &opts).unwrap();
        let (model, _) = float.quantize().unwrap();
        let rows = tcomp_model::replay::replay(&csv, model.clone()).unwrap();
        let params = if choice == "mlr" {
            &file.mlr
        } else {
            &file.mlr_static
        };
        for (d, ch) in ["dch3_um", "dch5_um"].iter().enumerate() {
            assert_eq!(
                model.direction_name(d),
                ch.trim_start_matches('d').trim_end_matches("_um")
            );
            let m = params.iter().find(|m| m.channel == *ch).unwrap();
            let table = float
                .tables
                .iter()
                .find(|t| usize::from(t.direction) == d)
                .unwrap();
            let tol = 0.05
                + table
                    .terms
                    .iter()
                    .map(|t| 0.1 / 512.0 + t.coef_um.abs() * 2f64.powi(-23))
                    .sum::<f64>();
            // The fit's training rows and predictions, on its own features.
            let kinds: Vec<_> = m
                .features
                .iter()
                .map(|f| (f.kind.clone(), f.tau_s))
                .collect();
            let cache = SeriesCache::new(&plan.runs, kinds).unwrap();
            let idx: Vec<usize> = (0..m.features.len()).collect();
            let train = cache.samples(&plan.runs, &plan.train, &idx, ch).unwrap();
            assert!(train.y.len() > 600, "{}", train.y.len());
            let (mut worst, mut sq_fit, mut sq_board) = (0.0f64, 0.0, 0.0);
            for ((x, y), &(_, r)) in train.x.iter().zip(&train.y).zip(&train.rows) {
                let fit = m.predict_raw(x);
                let out = rows[r].out;
                assert!(out.status & thermocomp_core::compensator::status::VALID != 0);
                let board = f64::from(out.predicted[d]) / 10.0;
                worst = worst.max((board - fit).abs());
                sq_fit += (y - fit).powi(2);
                sq_board += (y - board).powi(2);
            }
            let n = train.y.len() as f64;
            let (rms_fit, rms_board) = ((sq_fit / n).sqrt(), (sq_board / n).sqrt());
            assert!(
                worst <= tol,
                "{choice} {ch}: worst |board − fit| {worst:.4} µm > {tol:.4} µm"
            );
            assert!(
                (rms_fit - rms_board).abs() <= tol,
                "{choice} {ch}: training RMS fit {rms_fit:.4} vs board {rms_board:.4} µm"
            );
            eprintln!(
                "{choice} {ch}: training RMS fit {rms_fit:.4} µm, board {rms_board:.4} µm, worst row {worst:.4} µm (tolerance {tol:.4})"
            );
        }
    }
}

/// A gap in one sensor makes the board skip the whole step for every input
/// of the image (and catch its filters up afterwards): the fit reports the
/// training rows where that differs from the per-sensor features it trained on.
#[test]
fn gaps_in_another_inputs_sensor_are_counted() {
    use tcomp_model::fit::features::image_gap_rows;
    use tcomp_model::fit::{FeatureKind, Segment};
    let n = 400;
    let t: Vec<Option<f64>> = (0..n).map(|k| Some(k as f64 * 15.0)).collect();
    let ta: Vec<Option<f64>> = (0..n).map(|k| Some(20.0 + k as f64 * 0.1)).collect();
    let mut tb: Vec<Option<f64>> = (0..n).map(|k| Some(21.0 + k as f64 * 0.005)).collect();
    let run = Run {
        meta: vec![],
        columns: vec!["time_s".into(), "T_a".into(), "T_b".into()],
        data: vec![t.clone(), ta.clone(), tb.clone()],
    };
    let kinds = vec![
        (FeatureKind::SensorRise("T_a".into()), Some(1800.0)),
        (FeatureKind::SensorRise("T_b".into()), None),
    ];
    let seg = [Segment {
        run: 0,
        start: 0,
        end: n,
    }];
    let clean = image_gap_rows(std::slice::from_ref(&run), &seg, &kinds).unwrap();
    assert_eq!(clean, Some(0));
    for v in &mut tb[100..103] {
        *v = None;
    }
    let gappy = Run {
        data: vec![t, ta, tb],
        ..run
    };
    let n_gap = image_gap_rows(std::slice::from_ref(&gappy), &seg, &kinds)
        .unwrap()
        .unwrap();
    // The three rows without T_b (T_a's feature exists on its own, not on the
    // board) and the row after them, where T_a's filter catches up over the
    // skipped steps with the newest sample instead of stepping through them.
    assert!(n_gap >= 4, "{n_gap}");
}

//! `replay`'s figures: about the run's reference and about the block's own
//! mean, the never-worse check, and status-flag counts.

use tcomp_data::runcsv::Run;
use tcomp_model::fit::{FeatureKind, FeatureSpec, MlrParams, ModelFile};
use tcomp_model::replay::{flag_counts, residuals, ReplayRow};
use thermocomp_core::compensator::status;
use thermocomp_core::StepOutput;

fn model_dx() -> thermocomp_core::Model {
    let file = ModelFile {
        mlr: vec![MlrParams {
            features: vec![FeatureSpec {
                kind: FeatureKind::SensorRise("T_a".into()),
                tau_s: None,
                min: 0.0,
                max: 5.0,
            }],
            c0: 0.0,
            coef: vec![1.0],
            channel: "dx_um".into(),
        }],
        ..Default::default()
    };
    let fm = tcomp_model::export::float_model_from_fit(
        &file,
        &["T_a".to_string()],
        &tcomp_model::export::ExportOptions::default(),
    )
    .unwrap();
    fm.quantize().unwrap().0
}

fn rows(corr_um: &[f64], flags: &[u16]) -> Vec<ReplayRow> {
    corr_um
        .iter()
        .zip(flags)
        .enumerate()
        .map(|(i, (c, f))| {
            let mut out = StepOutput::default();
            out.corrections[0] = (c * 10.0).round() as i32;
            out.status = *f;
            ReplayRow {
                time_ms: i as u64 * 1000,
                out,
            }
        })
        .collect()
}

fn run(measured: &[f64]) -> Run {
    Run {
        meta: vec![],
        columns: vec!["time_s".into(), "T_a".into(), "dx_um".into()],
        data: vec![
            (0..measured.len()).map(|i| Some(i as f64)).collect(),
            measured.iter().map(|_| Some(20.0)).collect(),
            measured.iter().map(|m| Some(*m)).collect(),
        ],
    }
}

#[test]
fn a_constant_offset_counts_about_the_reference_but_not_about_the_mean() {
    // The machine sits warm at 10 µm ± 1 µm; the board serves 10 µm flat.
    let measured: Vec<f64> = (0..100)
        .map(|i| 10.0 + if i % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let served = vec![10.0; 100];
    let r = &residuals(
        &run(&measured),
        &rows(&served, &[status::VALID; 100]),
        &model_dx(),
        0,
        100,
    )[0];
    assert!((r.rms_um - 1.0).abs() < 1e-9, "{r:?}");
    assert!(
        (r.uncompensated_rms_um - 101f64.sqrt()).abs() < 1e-9,
        "{r:?}"
    );
    assert!(r.reduction_pct > 90.0, "{r:?}");
    // About the block mean nothing was gained: the operator would have re-zeroed the 10 µm.
    assert!((r.rms_about_mean_um - 1.0).abs() < 1e-9, "{r:?}");
    assert!(
        (r.uncompensated_rms_about_mean_um - 1.0).abs() < 1e-9,
        "{r:?}"
    );
    assert!(r.reduction_about_mean_pct.abs() < 1e-6, "{r:?}");
    assert!(r.never_worse);
}

#[test]
fn a_board_that_makes_things_worse_is_reported() {
    let measured = vec![1.0; 50];
    let served = vec![-3.0; 50];
    let r = &residuals(
        &run(&measured),
        &rows(&served, &[status::VALID; 50]),
        &model_dx(),
        0,
        50,
    )[0];
    assert!(!r.never_worse, "{r:?}");
    assert!(r.reduction_pct < 0.0);
}

#[test]
fn status_flags_are_counted_over_the_scored_block_only() {
    let flags: Vec<u16> = (0..10)
        .map(|i| match i {
            0..=2 => status::SENSOR_FAULT,
            3..=5 => status::VALID | status::OUT_OF_ENVELOPE | status::RATE_LIMITED,
            _ => status::VALID | status::CLAMPED,
        })
        .collect();
    let rs = rows(&[0.0; 10], &flags);
    let c = flag_counts(&rs, 2, 9);
    assert_eq!(c.sensor_fault, 1);
    assert_eq!(c.out_of_envelope, 3);
    assert_eq!(c.rate_limited, 3);
    assert_eq!(c.clamped, 3);
    assert_eq!(c.valid, 6);
    assert_eq!(c.stale, 0);
}

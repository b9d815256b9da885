//! The envelope policy `extrapolate` on the desktop side (issue 50 item 3):
//! the fit file's policy name → the image's mode, only for a linear
//! channel; an MLR export under it is a format-4 image whose board serves
//! the linear continuation beyond the envelope; replay names the policy.

use tcomp_data::runcsv::Run;
use tcomp_model::export::envelope_policy::{linear, mode};
use tcomp_model::fit::{FeatureKind, FeatureSpec, MlrParams, ModelFile};
use tcomp_model::replay::{residuals, ReplayRow};
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy};
use thermocomp_core::{Compensator, StepInput};

/// dx = 2 µm per unit of T_a's normalised rise (trained over 0 … 5 °C).
fn mlr_float() -> thermocomp_core::float::FloatModel {
    let file = ModelFile {
        mlr: vec![MlrParams {
            features: vec![FeatureSpec {
                kind: FeatureKind::SensorRise("T_a".into()),
                tau_s: None,
                min: 0.0,
                max: 5.0,
            }],
            c0: 0.0,
            coef: vec![2.0],
            channel: "dx_um".into(),
        }],
        ..Default::default()
    };
    tcomp_model::export::float_model_from_fit(
        &file,
        &["T_a".to_string()],
        &tcomp_model::export::ExportOptions::default(),
    )
    .unwrap()
}

#[test]
fn the_fit_files_policy_names_map_to_the_images_modes() {
    assert_eq!(mode("extrapolate"), EnvelopeMode::Extrapolate);
    assert_eq!(mode("fallback"), EnvelopeMode::Fallback);
    assert_eq!(mode("hold"), EnvelopeMode::Hold);
    assert_eq!(mode("something else"), EnvelopeMode::Hold);
    assert_eq!(EnvelopeMode::Extrapolate.name(), "extrapolate");
}

#[test]
fn only_linear_channels_count_as_linear() {
    assert!(linear(&mlr_float(), 0));
    // The demo: Z and X networks, Y a square term.
    let demo = thermocomp_core::float::demo_model(1);
    assert!((0..3).all(|d| !linear(&demo, d)));
}

#[test]
fn an_mlr_exported_to_extrapolate_continues_beyond_the_envelope_and_replay_names_it() {
    let float = mlr_float();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.img");
    let mut section = [EnvelopePolicy::default(); 6];
    section[0] = EnvelopePolicy {
        mode: EnvelopeMode::Extrapolate,
        margin: 8,
    };
    tcomp_model::export::export_enveloped(&float, (None, None), Some(section), &path, None)
        .unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 4);
    let model = thermocomp_core::Model::parse(&bytes).unwrap();
    assert_eq!(model.envelope.unwrap()[0].mode, EnvelopeMode::Extrapolate);

    // Rises of 0, 2.5, 5, 7.5 °C (the envelope is 0 … 5 °C): beyond it,
    // hold serves the value at 5 °C, extrapolate the line continued.
    let reference = model.sensors[0].ref_temp;
    let mut hold_model = model.clone();
    hold_model.envelope = None;
    let (mut ext, mut hold) = (
        Compensator::new(Some(model.clone())),
        Compensator::new(Some(hold_model)),
    );
    let (mut rows, mut served): (Vec<ReplayRow>, Vec<i32>) = (vec![], vec![]);
    for (i, rise) in [0, 40, 80, 120].into_iter().enumerate() {
        let input = StepInput {
            now_ms: i as u64 * 1000,
            temps: &[Some(reference + rise)],
            spindle_rpm: 0,
            positions: &[],
            stale: false,
        };
        let (e, h) = (ext.step(&input), hold.step(&input));
        if rise == 120 {
            let (at_40, at_80) = (served[1], served[2]);
            assert!((e.predicted[0] - (2 * at_80 - at_40)).abs() <= 1, "{e:?}");
            assert_eq!(h.predicted[0], at_80);
            assert!(e.predicted[0] - at_80 >= 10, "continues: {served:?}");
        } else {
            assert_eq!(e.predicted[0], h.predicted[0]);
        }
        served.push(e.predicted[0]);
        rows.push(ReplayRow {
            time_ms: input.now_ms,
            out: e,
        });
    }
    let run = Run {
        meta: vec![],
        columns: vec!["time_s".into(), "T_a".into(), "dx_um".into()],
        data: vec![
            (0..4).map(|i| Some(f64::from(i))).collect(),
            (0..4).map(|_| Some(20.0)).collect(),
            (0..4).map(|_| Some(0.0)).collect(),
        ],
    };
    let res = residuals(&run, &rows, &model, 0, 4);
    assert_eq!(res[0].envelope_policy, "extrapolate");
    assert_eq!(res[0].envelope_margin_raw, 8);
    assert_eq!(res[0].out_of_envelope_rows, 1);
}

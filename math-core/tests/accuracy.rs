//! Fixed point against the f64 reference over the whole admissible input range.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::float::demo_model;
use thermocomp_core::limits::*;

#[test]
fn fixed_matches_float_within_a_tenth_of_a_micrometre() {
    for seed in [1u64, 2, 3, 7, 42, 1234] {
        let fm = demo_model(seed);
        let (_, report) = fm.quantize().unwrap();
        assert!(report.samples > 20_000);
        for (d, dev) in report.max_deviation_um.iter().enumerate() {
            assert!(
                *dev <= 0.1,
                "seed {seed} direction {d}: {dev} µm at {:?}",
                report.worst_features
            );
        }
        // The check is not vacuous: the outputs do move by many µm across the range.
        let lo = fm.evaluate_um(
            &fm.inputs.iter().map(|i| i.min).collect::<Vec<_>>(),
            &[-100_000.0],
        );
        let hi = fm.evaluate_um(
            &fm.inputs.iter().map(|i| i.max).collect::<Vec<_>>(),
            &[800_000.0],
        );
        assert!(
            lo.iter().zip(&hi).any(|(a, b)| (a - b).abs() > 5.0),
            "{lo:?} {hi:?}"
        );
    }
}

#[test]
fn large_weights_still_quantize_within_a_tenth() {
    let mut fm = demo_model(9);
    for row in fm.nets[0].w1.iter_mut() {
        for w in row.iter_mut() {
            *w *= 30.0; // |W1| up to 90
        }
    }
    let (_, report) = fm.quantize().unwrap();
    assert!(
        report.max_deviation_um[0] <= 0.1,
        "{:?}",
        report.max_deviation_um
    );
}

#[test]
fn inputs_outside_the_envelope_hold_the_edge_value_and_say_so() {
    let (m, _) = demo_model(5).quantize().unwrap();
    let edge: Vec<i32> = m.inputs.iter().map(|i| i.max << 8).collect();
    let far: Vec<i32> = m.inputs.iter().map(|i| (i.max + 5000) << 8).collect();
    let a = m.evaluate(&edge, &[0]);
    let b = m.evaluate(&far, &[0]);
    assert!(!a.out_of_envelope && b.out_of_envelope);
    assert_eq!(a.corrections, b.corrections);
    let far_pos = m.evaluate(&edge, &[5_000_000]);
    assert!(far_pos.out_of_envelope);
    assert_eq!(
        far_pos.corrections[0], a.corrections[0],
        "Z does not depend on X position"
    );
    let _ = MAX_INPUTS;
}

#[test]
fn axis_offset_and_slope_match_the_float_reference() {
    let fm = demo_model(11);
    let (m, _) = fm.quantize().unwrap();
    for k in 0..50 {
        let f: Vec<f64> = fm
            .inputs
            .iter()
            .map(|i| i.min + (i.max - i.min) * f64::from(k) / 49.0)
            .collect();
        let fq: Vec<i32> = f.iter().map(|v| (v * 256.0).round() as i32).collect();
        let e = m.evaluate(&fq, &[0]);
        let (off, slope) = fm.axis_pairs(&f)[0];
        assert!(
            (f64::from(e.axes[0].offset) / 10.0 - off).abs() <= 0.1,
            "offset {} vs {off}",
            e.axes[0].offset
        );
        // slope in 0.01 µm/m
        assert!(
            (f64::from(e.axes[0].slope) / 100.0 - slope).abs() <= 0.02,
            "slope {} vs {slope}",
            e.axes[0].slope
        );
    }
}

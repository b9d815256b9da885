//! The compensator's rules: no model, reference, lags, faults, limits, golden vectors.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::compensator::status::*;
use thermocomp_core::float::demo_model;
use thermocomp_core::golden;
use thermocomp_core::{Compensator, Model, StepInput};

fn model() -> Model {
    demo_model(3).quantize().unwrap().0
}

fn step(
    c: &mut Compensator,
    now_ms: u64,
    temps: &[Option<i32>],
    rpm: i32,
) -> thermocomp_core::StepOutput {
    c.step(&StepInput {
        now_ms,
        temps,
        spindle_rpm: rpm,
        positions: &[0],
        stale: false,
    })
}

fn temps(v: i32) -> Vec<Option<i32>> {
    vec![Some(v); 6]
}

#[test]
fn without_a_model_the_correction_is_zero_and_flagged() {
    let mut c = Compensator::new(None);
    let o = step(&mut c, 1000, &temps(400), 3000);
    assert_eq!(o.status, NO_MODEL);
    assert_eq!(o.corrections, [0; 6]);
}

#[test]
fn reference_is_the_first_valid_sample_and_rises_start_at_zero() {
    let m = model();
    let mut c = Compensator::new(Some(m.clone()));
    let mut bad = temps(400);
    bad[0] = None;
    let o = step(&mut c, 1000, &bad, 0);
    assert_eq!(o.status & (SENSOR_FAULT | VALID), SENSOR_FAULT);
    assert!(
        c.reference().is_none(),
        "no reference from an invalid sample"
    );
    let o = step(&mut c, 2000, &temps(400), 0);
    assert!(o.status & VALID != 0 && o.status & WARMING_UP != 0);
    assert_eq!(c.reference().unwrap(), &[400; 6]);
    // Same temperatures at another absolute level give the same prediction (rises, not levels).
    let mut c2 = Compensator::new(Some(m));
    let o2 = step(&mut c2, 2000, &temps(100), 0);
    assert_eq!(o.predicted, o2.predicted);
}

#[test]
fn sensor_fault_holds_the_served_value_then_recovers() {
    let mut c = Compensator::new(Some(model()));
    let mut t = 320;
    let mut last = [0; 6];
    for s in 1..=600u64 {
        t += 1;
        last = step(&mut c, s * 1000, &temps(t), 6000).corrections;
    }
    let mut bad = temps(t);
    bad[2] = None;
    for s in 601..=620u64 {
        let o = step(&mut c, s * 1000, &bad, 6000);
        assert_eq!(o.corrections, last, "held during the fault");
        assert_eq!(o.status & (VALID | SENSOR_FAULT), SENSOR_FAULT);
    }
    let o = step(&mut c, 621_000, &temps(t), 6000);
    assert!(o.status & VALID != 0 && o.status & SENSOR_FAULT == 0);
}

#[test]
fn clamp_and_rate_limit_set_their_bits_and_bound_the_output() {
    let m = model();
    let max_rate = m.directions[0].max_rate; // 0.1 µm/s
    let mut c = Compensator::new(Some(m));
    c.set_limit_override(0, 5, 1_000_000); // 0.5 µm clamp on Z
    let mut t = 320;
    let mut prev = [0i32; 6];
    let mut clamped = false;
    for s in 1..=3000u64 {
        t += 1;
        let o = step(
            &mut c,
            s * 1000,
            &temps(t.min(700)),
            if s > 100 { 12000 } else { 0 },
        );
        assert!(o.corrections[0].abs() <= 5);
        clamped |= o.status & CLAMPED != 0;
        for d in 1..3 {
            let lim = [0, 10, 50][d];
            assert!(
                (o.corrections[d] - prev[d]).abs() <= lim,
                "rate of direction {d}"
            );
        }
        prev = o.corrections;
    }
    assert!(clamped);
    assert_eq!(max_rate, 20);
}

#[test]
fn lag_filter_follows_a_step_like_a_first_order_system() {
    // A step in spindle speed: the lagged input (tau 2400 s) reaches 63 % after one tau.
    let fm = demo_model(4);
    let (m, _) = fm.quantize().unwrap();
    let tau = fm.inputs[4].tau_s.unwrap();
    let mut c = Compensator::new(Some(m.clone()));
    step(&mut c, 0, &temps(320), 0);
    // Evaluate the model's float reference at the analytic filter output and compare.
    for s in [1u64, 15, 600, 2400, 7200] {
        let mut c = Compensator::new(Some(m.clone()));
        step(&mut c, 0, &temps(320), 0);
        let o = step(&mut c, s * 1000, &temps(320), 12000);
        let lagged = 12000.0 * (1.0 - (-(s as f64) / tau).exp());
        let f = fm.evaluate_um(&[0.0, 0.0, 0.0, 0.0, lagged], &[0.0]);
        assert!(
            (f64::from(o.predicted[0]) / 10.0 - f[0]).abs() <= 0.1,
            "after {s} s: {} vs {}",
            o.predicted[0],
            f[0]
        );
    }
}

#[test]
fn golden_vectors_reproduce_and_a_changed_expectation_is_caught() {
    let g = golden::generate(400, 99).unwrap();
    assert_eq!(golden::check(&g), Ok(400));
    // Flip one bit of the last step's last expected value.
    let mut bad = g.clone();
    let n = bad.len();
    bad[n - 1] ^= 0x01;
    assert!(matches!(
        golden::check(&bad),
        Err(golden::GoldenError::Mismatch { step: 399 })
    ));
    assert_eq!(
        golden::check(&g[..n - 3]),
        Err(golden::GoldenError::Malformed)
    );
}

#[test]
fn a_preset_reference_replaces_the_first_sample_and_one_it_lacks_is_no_reference() {
    let m = model();
    // The board's kept reference: rises against 300, though the first sample reads 400.
    let mut kept = Compensator::new(Some(m.clone()));
    kept.preset_reference(&[Some(300); 6]);
    let o = step(&mut kept, 1000, &temps(400), 0);
    assert!(o.status & VALID != 0);
    assert_eq!(kept.reference().unwrap(), &[300; 6]);
    // Same as an image whose stored (fixed) reference is 300, and the preset wins over it.
    let mut fixed = m.clone();
    fixed.flags |= thermocomp_core::image::FLAG_FIXED_REFERENCE;
    for s in fixed.sensors.iter_mut() {
        s.ref_temp = 300;
    }
    let mut plain = Compensator::new(Some(fixed.clone()));
    let p = step(&mut plain, 1000, &temps(400), 0);
    for s in fixed.sensors.iter_mut() {
        s.ref_temp = 0;
    }
    let mut over = Compensator::new(Some(fixed));
    over.preset_reference(&[Some(300); 6]);
    assert_eq!(step(&mut over, 1000, &temps(400), 0).predicted, p.predicted);
    assert_eq!(o.predicted, p.predicted);
    assert_ne!(o.predicted, [0; 6], "a real rise, not the first sample");
    // A sensor the preset does not cover gets no reference: the main model
    // (every sensor) cannot serve, however valid its reading.
    let mut partial = Compensator::new(Some(m.clone()));
    let mut refs = vec![Some(300); 6];
    refs[2] = None;
    partial.preset_reference(&refs);
    let o = step(&mut partial, 1000, &temps(400), 0);
    assert_eq!(
        o.status & (SENSOR_FAULT | VALID),
        SENSOR_FAULT,
        "{:#x}",
        o.status
    );
    // A re-reference drops the preset: the next sample is the reference.
    partial.rereference();
    let o = step(&mut partial, 2000, &temps(400), 0);
    assert!(o.status & VALID != 0);
    assert_eq!(partial.reference().unwrap(), &[400; 6]);
}

//! Q-format primitives: sigmoid error bound, normalisation, lag decay, overflow.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use proptest::prelude::*;
use thermocomp_core::fixed::*;

fn sigma(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

#[test]
fn sigmoid_error_is_within_the_stated_bound_everywhere() {
    let mut worst = 0.0f64;
    // Every 3rd Q16 value over [-20, 20] (past the ±16 saturation) plus the extremes.
    let mut z = -20i64 << 16;
    while z <= 20 << 16 {
        let e = (f64::from(sigmoid_q17(z)) / 131072.0 - sigma(z as f64 / 65536.0)).abs();
        worst = worst.max(e);
        z += 3;
    }
    for z in [i64::MIN, i64::MAX, -(16 << 16), 16 << 16, 0] {
        let e = (f64::from(sigmoid_q17(z)) / 131072.0 - sigma(z as f64 / 65536.0)).abs();
        worst = worst.max(e);
    }
    assert!(worst <= SIGMOID_MAX_ERROR, "worst sigmoid error {worst:e}");
    assert!(worst > 1e-7, "suspiciously exact: {worst:e}");
}

#[test]
fn sigmoid_is_monotone_and_symmetric() {
    let mut prev = -1;
    for z in (-(17i64 << 16)..(17 << 16)).step_by(97) {
        let s = sigmoid_q17(z);
        assert!(s >= prev, "not monotone at {z}");
        assert_eq!(s + sigmoid_q17(-z), ONE_Q17, "asymmetric at {z}");
        prev = s;
    }
}

#[test]
fn span_maps_the_envelope_onto_minus_one_to_one_and_flags_outside() {
    let sp = Span::new(-16 << 8, 480 << 8).unwrap();
    assert_eq!(sp.normalise(-16 << 8), (-ONE_Q24, false));
    assert_eq!(sp.normalise(480 << 8), (ONE_Q24, false));
    let (mid, out) = sp.normalise(232 << 8);
    assert!(mid.abs() <= 1 && !out);
    assert_eq!(sp.normalise(481 << 8), (ONE_Q24, true));
    assert_eq!(sp.normalise(i32::MIN), (-ONE_Q24, true));
    assert!(Span::new(5, 6).is_none() && Span::new(7, 5).is_none());
    // The widest span, and exactness against the real mapping everywhere.
    let wide = Span::new(i32::MIN, i32::MAX).unwrap();
    assert_eq!(wide.normalise(i32::MAX).0, ONE_Q24);
    for (lo, hi) in [
        (-16i32 << 8, 480 << 8),
        (0, 12_000 << 8),
        (-3, 2),
        (-1_000_000, 3_000_000),
    ] {
        let sp = Span::new(lo, hi).unwrap();
        let step = ((hi as i64 - lo as i64) / 997).max(1);
        let mut v = lo as i64;
        while v <= hi as i64 {
            let want = (2.0 * (v - lo as i64) as f64 / (hi as i64 - lo as i64) as f64 - 1.0)
                * f64::from(ONE_Q24);
            let got = f64::from(sp.normalise(v as i32).0);
            assert!(
                (got - want).abs() <= 1.0,
                "[{lo},{hi}] at {v}: {got} vs {want}"
            );
            v += step;
        }
    }
}

#[test]
fn lag_decay_matches_the_exponential() {
    let tau = 1800.0f64;
    let d = ((-1.0 / tau).exp() * (1u64 << 30) as f64).round() as u32;
    for n in [1u64, 15, 60, 1800, 7200, 86_400, u64::MAX] {
        let got = f64::from(decay_pow_q30(d, n)) / (1u64 << 30) as f64;
        let want = (-(n as f64) / tau).exp();
        assert!(
            (got - want).abs() < 1e-6 * n.min(100_000) as f64 + 1e-8,
            "n={n}: {got} vs {want}"
        );
    }
    assert_eq!(decay_pow_q30(d, 0), 1 << 30);
}

#[test]
fn lag_update_moves_towards_the_input() {
    let y = lag_update(0, 1000 << 16, 1 << 29); // half way
    assert_eq!(y, 500 << 16);
    assert_eq!(lag_update(7 << 16, 3 << 16, 0), 3 << 16);
}

proptest! {
    #[test]
    fn span_never_overflows(v in any::<i32>(), lo in any::<i32>(), hi in any::<i32>()) {
        if let Some(sp) = Span::new(lo.min(hi), lo.max(hi)) {
            let (x, out) = sp.normalise(v);
            prop_assert!((-ONE_Q24..=ONE_Q24).contains(&x));
            prop_assert_eq!(out, v < lo.min(hi) || v > lo.max(hi));
        }
    }

    #[test]
    fn lag_update_stays_between_state_and_input(y in -(1i64 << 47)..(1i64 << 47), u in -(1i64 << 47)..(1i64 << 47), d in 0u32..(1 << 30)) {
        let r = lag_update(y, u, d);
        prop_assert!(r >= y.min(u) - 1 && r <= y.max(u) + 1);
    }

    #[test]
    fn mul_q24_stays_in_range(a in -ONE_Q24..=ONE_Q24, b in -ONE_Q24..=ONE_Q24) {
        prop_assert!(mul_q24(a, b).abs() <= ONE_Q24);
    }
}

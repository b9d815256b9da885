//! The fixed-point sine and cosine (`thermocomp_core::trig`): every input
//! of a turn against f64 within the stated bound, exact values where they
//! must be, and any i32 (reduction, overflow: tests run with overflow
//! checks on) by property.
#![allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use proptest::prelude::*;
use thermocomp_core::trig::*;

fn exact(mdeg: i32) -> (f64, f64) {
    // The reduced angle is exact in f64 (an integer below 2^19).
    let r = f64::from(mdeg.rem_euclid(MDEG_PER_TURN)) * std::f64::consts::PI / 180_000.0;
    (r.sin(), r.cos())
}

fn error_lsb(mdeg: i32) -> f64 {
    let (s, c) = sin_cos_mdeg(mdeg);
    let (es, ec) = exact(mdeg);
    let q = f64::from(ONE_Q30);
    let ds = (f64::from(s) - es * q).abs();
    let dc = (f64::from(c) - ec * q).abs();
    ds.max(dc)
}

#[test]
fn every_input_of_a_turn_is_within_the_stated_bound() {
    let mut worst = (0.0f64, 0);
    let mut sum = 0.0;
    for a in 0..MDEG_PER_TURN {
        let e = error_lsb(a);
        sum += e;
        if e > worst.0 {
            worst = (e, a);
        }
    }
    assert!(
        worst.0 <= SIN_COS_MAX_ERROR,
        "worst {} LSB at {} mdeg (bound {SIN_COS_MAX_ERROR})",
        worst.0,
        worst.1
    );
    // The bound is not loose: the final rounding alone costs up to ½ LSB.
    assert!(worst.0 > 0.45, "worst {}", worst.0);
    let mean = sum / f64::from(MDEG_PER_TURN);
    // The larger of two roundings (sin, cos) alone averages ⅓ LSB.
    assert!(mean < 0.45, "mean error {mean} LSB");
    println!(
        "worst {:.4} LSB at {} mdeg, mean {mean:.4}",
        worst.0, worst.1
    );
}

#[test]
fn exact_where_it_must_be() {
    let one = ONE_Q30;
    assert_eq!(sin_cos_mdeg(0), (0, one));
    assert_eq!(sin_cos_mdeg(90_000), (one, 0));
    assert_eq!(sin_cos_mdeg(180_000), (0, -one));
    assert_eq!(sin_cos_mdeg(270_000), (-one, 0));
    assert_eq!(sin_cos_mdeg(-90_000), (-one, 0));
    assert_eq!(sin_cos_mdeg(360_000), (0, one));
    // 30°: sin = ½ to within the bound.
    let (s, _) = sin_cos_mdeg(30_000);
    assert!((s - one / 2).abs() <= 1, "{s}");
    // Octant symmetry: sin 45° = cos 45°, bit for bit (the same kernel call).
    let (s, c) = sin_cos_mdeg(45_000);
    assert_eq!(s, c);
}

#[test]
fn extremes_of_i32_do_not_overflow() {
    for a in [i32::MIN, i32::MIN + 1, i32::MAX, i32::MAX - 1, -1, 1] {
        let (s, c) = sin_cos_mdeg(a);
        assert!(error_lsb(a) <= SIN_COS_MAX_ERROR, "{a}: {s} {c}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]
    #[test]
    fn any_i32_reduces_onto_its_turn(a in any::<i32>()) {
        let (s, c) = sin_cos_mdeg(a);
        prop_assert_eq!((s, c), sin_cos_mdeg(a.rem_euclid(MDEG_PER_TURN)));
        prop_assert!(error_lsb(a) <= SIN_COS_MAX_ERROR);
        // Odd and even: sin(−a) = −sin a, cos(−a) = cos a, except where the
        // reduction of −a lands on the other side of an octant boundary
        // (never: the kernel is called on the same t).
        if a != i32::MIN {
            let (s2, c2) = sin_cos_mdeg(-a);
            prop_assert_eq!((s2, c2), (-s, c));
        }
        // |s|, |c| ≤ 1 and s² + c² = 1 within rounding.
        prop_assert!(s.abs() <= ONE_Q30 && c.abs() <= ONE_Q30);
        let n = (i64::from(s) * i64::from(s) + i64::from(c) * i64::from(c)) >> 30;
        prop_assert!((n - i64::from(ONE_Q30)).abs() <= 2, "{}", n);
    }
}

//! The reference update at extreme inputs: no overflow (tests run with
//! overflow checks on), every bound held, serialisation round trip.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use proptest::prelude::*;
use thermocomp_core::reference::*;

fn any_params() -> impl Strategy<Value = ReferenceParams> {
    (
        (
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
        ),
        (
            any::<u16>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
        ),
    )
        .prop_map(|((a, b, c, d, e), (f, g, h, i, j))| ReferenceParams {
            sigma_ref_nm: a,
            sigma_bias_nm: b,
            tau_bias_s: c,
            sigma_rate_nm_h: d,
            tau_rate_s: e,
            gate_k_x10: f,
            gate_abs_nm: g,
            max_step_nm: h,
            max_bias_nm: i,
            max_rate_nm_h: j,
        })
}

#[derive(Debug, Clone)]
enum Op {
    Reference(u64, i32, i32),
    Rezero(u64, i32),
    Serve(u64, i32, i32),
}

fn any_op() -> impl Strategy<Value = Op> {
    let t = prop_oneof![any::<u64>(), 0u64..400_000_000u64];
    prop_oneof![
        (t.clone(), any::<i32>(), any::<i32>()).prop_map(|(t, m, r)| Op::Reference(t, m, r)),
        (t.clone(), any::<i32>()).prop_map(|(t, m)| Op::Rezero(t, m)),
        (t, any::<i32>(), any::<i32>()).prop_map(|(t, m, c)| Op::Serve(t, m, c)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn no_overflow_and_bounds_hold(p in any_params(), ops in proptest::collection::vec(any_op(), 1..20)) {
        let q = p.sanitised();
        let mut st = ReferenceState::new(&p);
        let mut t_sorted = 0u64;
        for op in ops {
            match op {
                Op::Reference(t, m, r) => {
                    t_sorted = t_sorted.max(t);
                    let before = st.term_nm(&p, t_sorted);
                    let out = st.reference(&p, t_sorted, m, r);
                    if let ReferenceOutcome::Accepted { .. } = out {
                        // One reference moves the bias by at most max_step (+ its clamp).
                        let after = st.term_nm(&p, t_sorted);
                        prop_assert!((after - before).abs() <= i64::from(q.max_step_nm));
                    }
                }
                Op::Rezero(t, m) => {
                    t_sorted = t_sorted.max(t);
                    st.rezero(&p, t_sorted, m);
                }
                Op::Serve(t, m, c) => {
                    let v = st.serve(&p, t, m, c);
                    prop_assert!(i64::from(v).abs() <= i64::from(c.max(0)));
                }
            }
            prop_assert!(i64::from(st.bias_nm).abs() <= i64::from(q.max_bias_nm));
            prop_assert!(i64::from(st.zero_nm).abs() <= i64::from(MAX_TERM_NM));
            prop_assert!(i64::from(st.rate_nm_h).abs() <= i64::from(q.max_rate_nm_h));
            prop_assert!(st.p[0] >= 0 && st.p[2] >= 0 && st.p[0] <= MAX_VAR && st.p[2] <= MAX_VAR);
            prop_assert_eq!(ReferenceState::from_bytes(&st.to_bytes()), Ok(st));
        }
    }

    #[test]
    fn from_bytes_never_panics(b in proptest::collection::vec(any::<u8>(), 0..80)) {
        if let Ok(st) = ReferenceState::from_bytes(&b) {
            prop_assert_eq!(&st.to_bytes()[..], &b[..]);
        }
    }
}

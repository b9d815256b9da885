//! The reference rule's gate (issue 51): a reading refused by the `k·√S`
//! test and confirmed by the next one is a step in the model's error (a
//! spindle-speed change), not an outlier, and is accepted; an isolated
//! outlier is still refused and never confirms a later reading; the
//! absolute gate is never waived; the flag survives the stored bytes.
#![allow(
    clippy::unwrap_used,
    clippy::panic,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::reference::{ReferenceOutcome, ReferenceParams, ReferenceState};

const H: u64 = 3_600_000;
const S15: u64 = 15_000;

/// A state that has tracked an error of 2 µm for some hours: P is small,
/// so a step of the error by 10 µm falls outside the `k·√S` gate.
fn settled(p: &ReferenceParams) -> ReferenceState {
    let mut st = ReferenceState::new(p);
    for k in 1..=6u64 {
        let out = st.reference(p, k * H, 100, 120);
        assert!(matches!(out, ReferenceOutcome::Accepted { .. }), "{out:?}");
    }
    st
}

#[test]
fn a_step_confirmed_by_the_next_reading_is_accepted() {
    let p = ReferenceParams::DEFAULT;
    let mut st = settled(&p);
    let t = 6 * H + H / 4;
    // The model's error jumps from 2 µm to 12 µm (model 10 µm, probe 22 µm).
    let first = st.reference(&p, t, 100, 220);
    assert!(
        matches!(first, ReferenceOutcome::Refused { .. }),
        "{first:?}"
    );
    assert!(st.last_refused);
    let before = st.serve(&p, t + S15, 100, 100_000);
    // The next sample reads the same error (0.1 µm of probe noise apart).
    let second = st.reference(&p, t + S15, 100, 221);
    let ReferenceOutcome::Accepted { step, .. } = second else {
        panic!("a confirmed step was refused: {second:?}")
    };
    assert!(step > 80, "step {step}");
    assert!(!st.last_refused);
    let after = st.serve(&p, t + S15, 100, 100_000);
    // Most of the way to the reading (the Kalman share P/(P + σ_r²)).
    assert!(before < 130 && after > 200, "served {before} -> {after}");
    assert_eq!(st.refused, 1);
}

#[test]
fn an_isolated_outlier_is_refused_and_confirms_nothing() {
    let p = ReferenceParams::DEFAULT;
    let mut st = settled(&p);
    let t = 6 * H + H / 4;
    // A chip on the gauge: 10 µm too much, then a clean reading of the
    // unchanged error: the clean one is used, the outlier never.
    assert!(matches!(
        st.reference(&p, t, 100, 220),
        ReferenceOutcome::Refused { .. }
    ));
    let clean = st.reference(&p, t + S15, 100, 120);
    assert!(
        matches!(clean, ReferenceOutcome::Accepted { .. }),
        "{clean:?}"
    );
    assert!(!st.last_refused);
    // Two large readings that disagree are both refused.
    assert!(matches!(
        st.reference(&p, t + 2 * S15, 100, 220),
        ReferenceOutcome::Refused { .. }
    ));
    assert!(matches!(
        st.reference(&p, t + 3 * S15, 100, 320),
        ReferenceOutcome::Refused { .. }
    ));
    // A third that agrees with the last refused one is accepted.
    assert!(matches!(
        st.reference(&p, t + 4 * S15, 100, 321),
        ReferenceOutcome::Accepted { .. }
    ));
}

#[test]
fn the_absolute_gate_is_never_waived() {
    let p = ReferenceParams::DEFAULT;
    let mut st = settled(&p);
    let t = 6 * H + H / 4;
    // +50 µm twice in a row (above gate_abs 30 µm): both refused.
    for k in 0..3u64 {
        let out = st.reference(&p, t + k * S15, 100, 620);
        assert!(matches!(out, ReferenceOutcome::Refused { .. }), "{out:?}");
    }
    assert_eq!(st.refused, 3);
}

#[test]
fn the_pending_refusal_survives_the_stored_bytes() {
    let p = ReferenceParams::DEFAULT;
    let mut st = settled(&p);
    let t = 6 * H + H / 4;
    st.reference(&p, t, 100, 220);
    let back = ReferenceState::from_bytes(&st.to_bytes()).unwrap();
    assert_eq!(back, st);
    assert!(back.last_refused);
    let mut again = back;
    assert!(matches!(
        again.reference(&p, t + S15, 100, 221),
        ReferenceOutcome::Accepted { .. }
    ));
    // Flags other than bits 0 and 1 are refused.
    let mut b = st.to_bytes();
    b[1] |= 4;
    assert!(ReferenceState::from_bytes(&b).is_err());
}

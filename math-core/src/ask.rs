//! When the board asks the PLC for a probe reference (issue 51, item 3).
//!
//! A reference teaches the most where the model's error changes: in the
//! hour after a spindle-speed change the served error grows fastest, and a
//! reference taken there is worth several on a clock grid. The board owns
//! the rule (the PLC only probes when asked): it raises "reference wanted"
//! with a reason, and an accepted reference clears it.
//!
//! **The rule** (times in ms since boot, speeds in rpm as the PLC writes
//! them):
//! - *speed change*: the spindle speed moves by at least
//!   `speed_step_rpm` from the speed held at the last change (or at the
//!   first reading); the change time is noted (a later change within the
//!   settling time moves it). `settle_s` after the last change a reference
//!   is wanted (reason [`AskReason::SpeedChange`]), unless one was accepted
//!   after the settling time had passed (a reference taken during the
//!   transient does not answer for the settled state);
//! - *interval*: `max_interval_s` after the last accepted reference (or
//!   after the schedule started), a reference is wanted (reason
//!   [`AskReason::Interval`]);
//! - a request stays raised until a reference is accepted
//!   ([`AskState::referenced`]); a refused one (a chip on the gauge) leaves
//!   it raised, so the PLC tries again at its next chance.
//!
//! A parameter of 0 switches its part off (all 0: the board never asks).
//! `tcomp replay --reference-when-asked` runs this very code, so the
//! desktop's schedule and the board's are the same to the millisecond.
//!
//! **Across a reset** the board has no clock: [`AskState::to_bytes`] keeps
//! the raised reason, the time since the last reference and since the last
//! speed change as ages at the moment of storing; [`AskState::restore`]
//! starts from those ages at boot (the time the board was off, and the
//! time between the last store and the reset, are not counted).
//!
//! Integers only, no panics, no heap. Every time is a `u64` of ms and every
//! difference is taken with `saturating_sub`, so a clock that steps back
//! never underflows.

/// Parameters of the rule (the board's settings; `tcomp replay`'s flags).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AskParams {
    /// Ask this long after the last speed change, s (0: never for a change).
    pub settle_s: u16,
    /// Ask when this long has passed since the last reference, s (0: never).
    pub max_interval_s: u16,
    /// A speed change is a move of at least this, rpm (0: never).
    pub speed_step_rpm: u16,
}

impl AskParams {
    /// The schedule the references issue measured on FL_THERMAL: 15 min
    /// after each speed change, and whenever 70 min have passed.
    pub const SUGGESTED: AskParams = AskParams {
        settle_s: 15 * 60,
        max_interval_s: 70 * 60,
        speed_step_rpm: 500,
    };
}

/// Why a reference is wanted (input register value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum AskReason {
    /// Nothing wanted.
    #[default]
    None = 0,
    /// The settling time after a spindle-speed change has passed.
    SpeedChange = 1,
    /// The longest interval since the last reference has passed.
    Interval = 2,
}

impl AskReason {
    fn from_u8(v: u8) -> AskReason {
        match v {
            1 => AskReason::SpeedChange,
            2 => AskReason::Interval,
            _ => AskReason::None,
        }
    }
}

/// Serialised state length, bytes (version, reason, two ages, held speed).
pub const ASK_STATE_BYTES: usize = 16;
const ASK_STATE_VERSION: u8 = 1;
/// Ages are stored in ms as u32 (≈ 49 days); longer ones are stored as this.
const MAX_AGE_MS: u32 = u32::MAX;
/// The rule's own clock runs this far ahead of uptime, so that a state
/// restored at boot can hold times before boot (ages up to ≈ 35 years).
const EPOCH_MS: u64 = 1 << 40;

fn clock(now_ms: u64) -> u64 {
    now_ms.saturating_add(EPOCH_MS)
}

/// The rule's state: when the schedule last saw a reference and a speed
/// change, the speed held since, and the reason raised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AskState {
    /// Time of the last accepted reference (or the schedule's start), on
    /// the rule's clock ([`EPOCH_MS`] ahead of uptime).
    last_reference_ms: u64,
    /// Time of the last speed change not yet followed by a reference (the
    /// rule's clock).
    change_ms: Option<u64>,
    /// The speed at the last change (`None`: no reading yet).
    held_rpm: Option<i32>,
    wanted: AskReason,
}

impl AskState {
    /// A schedule starting at `now_ms` (nothing wanted, no speed yet).
    pub const fn new(now_ms: u64) -> AskState {
        AskState {
            last_reference_ms: now_ms.saturating_add(EPOCH_MS),
            change_ms: None,
            held_rpm: None,
            wanted: AskReason::None,
        }
    }

    /// The reason raised now ([`AskReason::None`]: nothing wanted).
    pub fn wanted(&self) -> AskReason {
        self.wanted
    }

    /// One look at `now_ms` with the spindle at `rpm` (`None`: not known,
    /// e.g. the PLC has not written it): note a speed change, raise a
    /// request when one is due. Returns `true` when a request was raised by
    /// this look (the board stores the state then).
    pub fn step(&mut self, p: &AskParams, now_ms: u64, rpm: Option<i32>) -> bool {
        let now_ms = clock(now_ms);
        if let Some(rpm) = rpm {
            match self.held_rpm {
                None => self.held_rpm = Some(rpm),
                Some(held) => {
                    let step = i64::from(p.speed_step_rpm);
                    if step > 0 && (i64::from(rpm) - i64::from(held)).abs() >= step {
                        self.held_rpm = Some(rpm);
                        self.change_ms = Some(now_ms);
                    }
                }
            }
        }
        if self.wanted != AskReason::None {
            return false;
        }
        let settle = u64::from(p.settle_s) * 1000;
        let interval = u64::from(p.max_interval_s) * 1000;
        let reason = match self.change_ms {
            Some(t) if p.settle_s > 0 && now_ms.saturating_sub(t) >= settle => {
                AskReason::SpeedChange
            }
            _ if p.max_interval_s > 0
                && now_ms.saturating_sub(self.last_reference_ms) >= interval =>
            {
                AskReason::Interval
            }
            _ => AskReason::None,
        };
        self.wanted = reason;
        reason != AskReason::None
    }

    /// An accepted reference at `now_ms` under `p`: the request is cleared
    /// and the interval starts again from here; a speed change counts as
    /// answered only once its settling time has passed.
    pub fn referenced(&mut self, p: &AskParams, now_ms: u64) {
        let now_ms = clock(now_ms);
        self.last_reference_ms = now_ms;
        let settle = u64::from(p.settle_s) * 1000;
        if self
            .change_ms
            .is_some_and(|t| now_ms.saturating_sub(t) >= settle)
        {
            self.change_ms = None;
        }
        self.wanted = AskReason::None;
    }

    /// The state as ages at `now_ms`, for the settings store.
    pub fn to_bytes(&self, now_ms: u64) -> [u8; ASK_STATE_BYTES] {
        let now_ms = clock(now_ms);
        let age = |t: u64| u32::try_from(now_ms.saturating_sub(t)).unwrap_or(MAX_AGE_MS);
        let change = self.change_ms.map_or(MAX_AGE_MS, age);
        let held = self.held_rpm.unwrap_or(i32::MIN);
        let words = [
            u32::from_le_bytes([ASK_STATE_VERSION, self.wanted as u8, 0, 0]),
            age(self.last_reference_ms),
            change,
            u32::from_le_bytes(held.to_le_bytes()),
        ];
        let mut b = [0u8; ASK_STATE_BYTES];
        for (chunk, w) in b.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// The state stored by [`AskState::to_bytes`], continued from `now_ms`
    /// (boot); `None` for bytes of another version or length.
    pub fn restore(b: &[u8], now_ms: u64) -> Option<AskState> {
        let (&[version, wanted, _, _], rest) = b.split_first_chunk::<4>()?;
        if version != ASK_STATE_VERSION || b.len() != ASK_STATE_BYTES {
            return None;
        }
        let (reference, rest) = rest.split_first_chunk::<4>()?;
        let (change, rest) = rest.split_first_chunk::<4>()?;
        let (held, _) = rest.split_first_chunk::<4>()?;
        let back = |age: u32| clock(now_ms).saturating_sub(u64::from(age));
        let change = u32::from_le_bytes(*change);
        let held = i32::from_le_bytes(*held);
        Some(AskState {
            last_reference_ms: back(u32::from_le_bytes(*reference)),
            change_ms: (change != MAX_AGE_MS).then(|| back(change)),
            held_rpm: (held != i32::MIN).then_some(held),
            wanted: AskReason::from_u8(wanted),
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "tests")]
mod tests {
    use super::*;

    const P: AskParams = AskParams::SUGGESTED;
    const MIN: u64 = 60_000;

    #[test]
    fn asks_once_the_settling_time_after_a_speed_change_has_passed() {
        let mut s = AskState::new(0);
        assert!(!s.step(&P, 0, Some(1000)));
        assert!(!s.step(&P, MIN, Some(3000))); // the change
        assert!(!s.step(&P, 15 * MIN, Some(3000)));
        assert!(s.step(&P, 16 * MIN, Some(3000)));
        assert_eq!(s.wanted(), AskReason::SpeedChange);
        // Raised once; stays raised until a reference is accepted.
        assert!(!s.step(&P, 17 * MIN, Some(3000)));
        assert_eq!(s.wanted(), AskReason::SpeedChange);
        s.referenced(&P, 18 * MIN);
        assert_eq!(s.wanted(), AskReason::None);
        assert!(!s.step(&P, 40 * MIN, Some(3000)));
    }

    #[test]
    fn a_small_move_is_no_change_and_a_later_change_moves_the_time() {
        let mut s = AskState::new(0);
        s.step(&P, 0, Some(1000));
        s.step(&P, MIN, Some(1400)); // < 500 rpm: no change
        assert!(!s.step(&P, 20 * MIN, Some(1400)));
        s.step(&P, 21 * MIN, Some(2000)); // change
        s.step(&P, 30 * MIN, Some(4000)); // another, moves the time
        assert!(!s.step(&P, 44 * MIN, Some(4000)));
        assert!(s.step(&P, 45 * MIN, Some(4000)));
    }

    #[test]
    fn asks_when_the_longest_interval_has_passed_and_counts_from_the_reference() {
        let mut s = AskState::new(0);
        assert!(!s.step(&P, 69 * MIN, Some(1000)));
        assert!(s.step(&P, 70 * MIN, Some(1000)));
        assert_eq!(s.wanted(), AskReason::Interval);
        s.referenced(&P, 72 * MIN);
        assert!(!s.step(&P, 141 * MIN, Some(1000)));
        assert!(s.step(&P, 142 * MIN, Some(1000)));
    }

    #[test]
    fn a_reference_within_the_settling_time_leaves_the_change_to_be_asked() {
        let mut s = AskState::new(0);
        s.step(&P, 0, Some(1000));
        s.step(&P, 60 * MIN, Some(3000)); // a change at 60 min...
        assert!(s.step(&P, 70 * MIN, Some(3000))); // ...and the interval due
        assert_eq!(s.wanted(), AskReason::Interval);
        s.referenced(&P, 71 * MIN); // within the change's settling time
        assert!(s.step(&P, 75 * MIN, Some(3000)));
        assert_eq!(s.wanted(), AskReason::SpeedChange);
        s.referenced(&P, 76 * MIN);
        assert!(!s.step(&P, 140 * MIN, Some(3000)));
        assert!(s.step(&P, 146 * MIN, Some(3000)));
        assert_eq!(s.wanted(), AskReason::Interval);
    }

    #[test]
    fn zero_switches_each_part_off() {
        let off = AskParams::default();
        let mut s = AskState::new(0);
        s.step(&off, 0, Some(0));
        assert!(!s.step(&off, 10 * MIN, Some(9000)));
        assert!(!s.step(&off, 1000 * MIN, Some(0)));
        assert_eq!(s.wanted(), AskReason::None);
    }

    #[test]
    fn the_state_survives_a_reset_as_ages() {
        let mut s = AskState::new(0);
        s.step(&P, 0, Some(1000));
        s.step(&P, 10 * MIN, Some(5000)); // change at 10 min
        let b = s.to_bytes(12 * MIN);
        // Boot: uptime 1 s; the change is 2 min old, the schedule 12 min.
        let mut r = AskState::restore(&b, 1000).unwrap();
        assert!(!r.step(&P, 1000 + 12 * MIN, Some(5000)));
        assert!(r.step(&P, 1000 + 13 * MIN, Some(5000)));
        assert_eq!(r.wanted(), AskReason::SpeedChange);
        // A raised request survives too.
        let b = r.to_bytes(1000 + 13 * MIN);
        let r2 = AskState::restore(&b, 500).unwrap();
        assert_eq!(r2.wanted(), AskReason::SpeedChange);
        assert!(AskState::restore(&b[..8], 0).is_none());
        let mut bad = b;
        bad[0] = 9;
        assert!(AskState::restore(&bad, 0).is_none());
    }

    #[test]
    fn no_speed_reading_leaves_the_interval_rule_alone() {
        let mut s = AskState::new(5 * MIN);
        assert!(!s.step(&P, 74 * MIN, None));
        assert!(s.step(&P, 75 * MIN, None));
    }
}

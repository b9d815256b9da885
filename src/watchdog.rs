//! When the watchdog may be fed: only when both activities made progress.
//!
//! The measurement loop must have completed a cycle since the last feed; the
//! Modbus task must have completed a request since then or be idle (waiting
//! for a frame is not a stall: a bus without a master is legitimate). A task
//! stuck anywhere else — a measurement loop that never comes back, a reply
//! that never leaves — stops the feeding, and the hardware watchdog resets
//! the board. Each board states its watchdog timeout next to its longest
//! legitimate operation.

/// Counters the two activities advance (kept in [`crate::app::App`]).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// Measurement cycles completed.
    pub cycles: u32,
    /// Modbus requests completed (reply sent or deliberately none).
    pub requests: u32,
    /// The Modbus task is between receiving a frame and finishing it.
    pub modbus_busy: bool,
}

/// Which activity has not made progress since the last feed (the detail
/// word of a watchdog fault record).
pub mod stalled {
    pub const MEASUREMENT: u32 = 1 << 0;
    pub const MODBUS: u32 = 1 << 1;
}

#[derive(Debug, Default, Clone, Copy)]
pub struct Feeder {
    last: Progress,
}

impl Feeder {
    pub fn new(now: &Progress) -> Self {
        Feeder { last: *now }
    }

    /// `Ok(())`: feed the watchdog now. `Err(bits)`: not yet; `bits` say
    /// which activity has not made progress since the last feed.
    pub fn check(&mut self, now: &Progress) -> Result<(), u32> {
        let mut bits = 0;
        if now.cycles == self.last.cycles {
            bits |= stalled::MEASUREMENT;
        }
        if now.modbus_busy && now.requests == self.last.requests {
            bits |= stalled::MODBUS;
        }
        if bits == 0 {
            self.last = *now;
            Ok(())
        } else {
            Err(bits)
        }
    }
}

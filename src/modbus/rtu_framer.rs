//! Modbus RTU framing by line timing, written once for every board
//! (Modbus over serial line V1.02, §2.5.1.1):
//! - a silence of at least 3.5 characters (t3.5) ends a frame;
//! - a silence of more than 1.5 characters (t1.5) inside a frame marks it
//!   broken: it is discarded whole when it ends;
//! - a frame longer than 256 bytes is discarded whole when it ends.
//!
//! A frame is what lies between two silences, never part of it: a valid
//! request inside another unit's frame (frame-in-frame) is not a frame, and
//! bytes that follow garbage with no silence belong to the garbage.
//!
//! The framer is pure: the board feeds it every received byte with its
//! arrival time (µs, on any clock that does not go backwards: the time the
//! byte's stop bit was received) and tells it when the line has been silent
//! until now ([`RtuFramer::idle`], best at [`RtuFramer::deadline_us`]). The
//! silence before a byte is its arrival time minus the previous byte's,
//! minus one character (the byte's own time on the line). Character times
//! count 11 bits (start, 8 data, parity or second stop, stop), as the spec
//! does; above 19,200 baud the spec's fixed 750 µs and 1,750 µs apply.

use thermocomp_protocol::rtu::MAX_FRAME;

/// The two silences of the RTU rule at one baud rate, µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Timing {
    /// A longer silence inside a frame breaks it (t1.5).
    pub t15_us: u64,
    /// A silence this long ends a frame (t3.5).
    pub t35_us: u64,
    /// One character on the line (11 bits).
    pub char_us: u64,
}

impl Timing {
    /// The spec's timing at `baud`: 1.5 and 3.5 characters of 11 bits,
    /// rounded up; fixed 750 µs and 1,750 µs above 19,200 baud.
    pub const fn for_baud(baud: u32) -> Timing {
        if baud > 19_200 {
            return Timing {
                t15_us: 750,
                t35_us: 1_750,
                char_us: 11_000_000_u64.div_ceil(baud as u64),
            };
        }
        let baud = if baud == 0 { 1 } else { baud as u64 };
        // 1.5 × 11 bits = 16.5 bit times, 3.5 × 11 = 38.5 bit times.
        Timing {
            t15_us: 16_500_000_u64.div_ceil(baud),
            t35_us: 38_500_000_u64.div_ceil(baud),
            char_us: 11_000_000_u64.div_ceil(baud),
        }
    }
}

/// How a frame ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Outcome {
    /// Ended by a t3.5 silence: its bytes are [`RtuFramer::frame`].
    Frame,
    /// Discarded: a silence longer than t1.5 inside it.
    Broken,
    /// Discarded: longer than 256 bytes.
    Oversize,
}

/// Frames out of timed bytes: see the module documentation.
pub struct RtuFramer {
    timing: Timing,
    buf: [u8; MAX_FRAME],
    /// Bytes of the frame in progress (or the finished frame) in `buf`.
    len: usize,
    oversize: bool,
    broken: bool,
    /// Arrival time of the newest byte of the frame in progress (None: no
    /// frame in progress).
    last_us: Option<u64>,
    /// `buf[..len]` is a finished frame, readable until the next call.
    finished: bool,
    /// The byte whose arrival ended the previous frame: the first byte of
    /// the next one, taken in at the next call.
    held: Option<(u8, u64)>,
}

impl RtuFramer {
    pub const fn new(timing: Timing) -> Self {
        RtuFramer {
            timing,
            buf: [0; MAX_FRAME],
            len: 0,
            oversize: false,
            broken: false,
            last_us: None,
            finished: false,
            held: None,
        }
    }

    pub fn timing(&self) -> Timing {
        self.timing
    }

    /// New line timing (a baud change): applies to the frames after the
    /// one in progress, which is dropped (it was sent at the old rate).
    pub fn set_timing(&mut self, timing: Timing) {
        self.timing = timing;
        self.reset();
    }

    /// Forget everything received (the line was reconfigured, or the
    /// receiver lost bytes): the next byte starts a frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.oversize = false;
        self.broken = false;
        self.last_us = None;
        self.finished = false;
        self.held = None;
    }

    /// The frame [`Outcome::Frame`] announced, until the next call that
    /// feeds the framer; empty otherwise.
    pub fn frame(&self) -> &[u8] {
        if self.finished {
            self.buf.get(..self.len).unwrap_or(&[])
        } else {
            &[]
        }
    }

    /// The time at which the frame in progress ends if no byte comes
    /// before it (the newest byte + t3.5); `None` when no frame is in
    /// progress.
    pub fn deadline_us(&self) -> Option<u64> {
        let last = match self.held {
            Some((_, at)) => Some(at),
            None if self.finished => None,
            None => self.last_us,
        };
        last.map(|t| t.saturating_add(self.timing.t35_us))
    }

    /// One byte received at `at_us`. When a silence of t3.5 or more came
    /// before it, the frame before it has ended: its outcome is returned (a
    /// good frame's bytes in [`Self::frame`]) and this byte starts the next
    /// frame.
    pub fn push(&mut self, byte: u8, at_us: u64) -> Option<Outcome> {
        self.settle();
        if let Some(last) = self.last_us {
            let gap = at_us
                .saturating_sub(last)
                .saturating_sub(self.timing.char_us);
            if gap >= self.timing.t35_us {
                self.held = Some((byte, at_us));
                return Some(self.finish());
            }
            if gap > self.timing.t15_us {
                self.broken = true;
            }
        }
        self.store(byte, at_us);
        None
    }

    /// No byte came until `now_us`: the frame in progress has ended if its
    /// newest byte is t3.5 or more ago.
    pub fn idle(&mut self, now_us: u64) -> Option<Outcome> {
        self.settle();
        let last = self.last_us?;
        (now_us.saturating_sub(last) >= self.timing.t35_us).then(|| self.finish())
    }

    /// Drop a finished frame; a held byte starts the next one.
    fn settle(&mut self) {
        if self.finished {
            self.len = 0;
            self.oversize = false;
            self.broken = false;
            self.finished = false;
        }
        if let Some((byte, at)) = self.held.take() {
            self.store(byte, at);
        }
    }

    fn store(&mut self, byte: u8, at_us: u64) {
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
            }
            None => self.oversize = true,
        }
        self.last_us = Some(at_us);
    }

    fn finish(&mut self) -> Outcome {
        let outcome = if self.oversize {
            Outcome::Oversize
        } else if self.broken {
            Outcome::Broken
        } else {
            Outcome::Frame
        };
        if outcome != Outcome::Frame {
            self.len = 0;
        }
        self.finished = true;
        self.last_us = None;
        outcome
    }
}

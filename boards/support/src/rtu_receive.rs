//! The RTU receive loop of both boards: received bytes with their arrival
//! times into the application's one framer
//! ([`thermocomp::modbus::rtu_framer`]), an idle check whenever the frame in
//! progress reaches its deadline with no byte, and the framer's outcome
//! turned into the `RtuPort::read_frame` result.
//!
//! Where the bytes come from is the board's ([`ByteSource`]): the NUCLEO's
//! DMA ring, stamped back from the idle-line hand-over; the bench board's
//! RX-interrupt queue, stamped as each byte lands. So is the line timing the
//! board gives the framer (the bench's floors on the two silences).

use thermocomp::hal::serial::Overrun;
use thermocomp::modbus::rtu_framer::{Outcome, RtuFramer, Timing};

/// A board's receiver as the loop sees it.
#[allow(async_fn_in_trait)] // both boards run single-threaded executors: no Send bound
pub trait ByteSource {
    /// The next received byte and its arrival time (µs, on the clock of
    /// [`Self::now_us`]), waiting at most until `deadline_us` (`None`:
    /// without limit); `Ok(None)` when no byte came before it. `char_us` is
    /// one character on the line at the current rate, for a source that
    /// stamps its bytes after the fact. `Err` when the receiver lost or
    /// garbled bytes (overrun, framing, noise).
    async fn next_byte(
        &mut self,
        deadline_us: Option<u64>,
        char_us: u64,
    ) -> Result<Option<(u8, u64)>, Overrun>;

    /// Now, µs.
    fn now_us(&self) -> u64;

    /// Whether a frame is being received, after every byte and idle check
    /// (the NUCLEO keeps a flash erase off the line meanwhile).
    fn receiving(&mut self, _in_frame: bool) {}
}

/// The framer and the receive loop around it.
pub struct RtuReceiver {
    framer: RtuFramer,
    broken: u32,
}

impl RtuReceiver {
    pub const fn new(timing: Timing) -> Self {
        RtuReceiver {
            framer: RtuFramer::new(timing),
            broken: 0,
        }
    }

    /// New line timing (a baud change); the frame in progress is dropped.
    pub fn set_timing(&mut self, timing: Timing) {
        self.framer.set_timing(timing);
    }

    /// Frames discarded for a silence inside them, since boot.
    pub fn broken(&self) -> u32 {
        self.broken
    }

    /// The next frame from `source` into `buf` (its length); `Err` for a
    /// frame longer than 256 bytes or than `buf`, or bytes the receiver
    /// lost (the frame in progress is dropped, reception starts afresh).
    pub async fn read_frame<S: ByteSource>(
        &mut self,
        source: &mut S,
        buf: &mut [u8],
    ) -> Result<usize, Overrun> {
        loop {
            let next = source
                .next_byte(self.framer.deadline_us(), self.framer.timing().char_us)
                .await;
            let outcome = match next {
                Ok(Some((byte, at))) => self.framer.push(byte, at),
                Ok(None) => self.framer.idle(source.now_us()),
                Err(e) => {
                    self.framer.reset();
                    source.receiving(false);
                    return Err(e);
                }
            };
            source.receiving(self.framer.deadline_us().is_some());
            match outcome {
                Some(Outcome::Frame) => {
                    let frame = self.framer.frame();
                    let n = frame.len();
                    return match buf.get_mut(..n) {
                        Some(dst) => {
                            dst.copy_from_slice(frame);
                            Ok(n)
                        }
                        None => Err(Overrun),
                    };
                }
                Some(Outcome::Oversize) => return Err(Overrun),
                Some(Outcome::Broken) => self.broken = self.broken.wrapping_add(1),
                None => {}
            }
        }
    }
}

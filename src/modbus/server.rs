//! One Modbus RTU request in, at most one reply out.
//!
//! Order of checks (Modbus over serial line spec, §2.4 and the application
//! protocol's exception rules):
//! 1. shorter than 4 bytes, longer than 256, or a wrong CRC-16 → discarded
//!    silently (a corrupted frame may not even be for us);
//! 2. another unit's address → ignored; broadcast (0) → writes to the PLC's
//!    registers done, every other write refused (`holding::Addressing`), no reply;
//! 3. unknown function → exception 01; count 0 or above the limit (reads
//!    125, FC16 123), or a byte count that does not match → 03; an address outside the map → 02; a
//!    protected write while locked → 01 (wrong state); a refused model → 04.
//!
//! `rmodbus` parses the request and builds replies and exceptions. Two
//! pre-checks keep it away from u8 overflows found by the proptest below
//! (host-tests/tests/modbus_server.rs): its `7 + bytes` sum for FC15/16 and
//! `function + 0x80` for request function codes ≥ 0x80.

use heapless::Vec;
use rmodbus::server::{ModbusFrame, Read, Write};
use rmodbus::{ErrorKind, ModbusProto};

use thermocomp_protocol::rtu::{crc16, MAX_FRAME, MAX_WRITE_REGISTERS};

use super::holding::{Addressing, At, Command, Holding, WriteError};
use crate::snapshot::Snapshot;
use crate::staging::{ParseCandidate, ParseOnStack};
use crate::state::AppState;

/// What the application must do after handling a request.
pub type Action = Command;

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    pub frames: u32,
    pub crc_errors: u32,
    pub broken: u32,
    pub exceptions: u32,
    pub replies: u32,
}

/// The frame handler and the unlock rule; what the registers show and set
/// is the application's ([`AppState`], [`Snapshot`]).
pub struct Server {
    holding: Holding,
    counters: Counters,
}

impl Default for Server {
    fn default() -> Self {
        Self::new()
    }
}

impl Server {
    pub fn new() -> Self {
        Server {
            holding: Holding::new(),
            counters: Counters::default(),
        }
    }

    /// Frames seen, CRC errors, broken frames, exceptions, replies.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Is the board unlocked at `now_ms`?
    pub fn unlocked(&self, now_ms: u64) -> bool {
        self.holding.unlocked(now_ms)
    }

    /// Handle one received frame: reads encode `snapshot` (input registers)
    /// and `state` (holding registers), writes decode into `state` and
    /// return what the application must do. `reply` is cleared and, when the request
    /// deserves an answer, filled with the complete RTU reply (CRC included).
    ///
    /// A write request to this unit (FC05, 06, 15, 16) answered with an
    /// exception locks the board, whichever check refused it (a malformed
    /// count here, a refused value or model in [`Holding::write`]); busy
    /// (06: "retransmit later") does not.
    pub fn handle(
        &mut self,
        frame: &[u8],
        now_ms: u64,
        snapshot: &Snapshot,
        state: &mut AppState,
        reply: &mut Vec<u8, MAX_FRAME>,
    ) -> Action {
        self.handle_lending(frame, now_ms, snapshot, state, reply, &mut ParseOnStack)
    }

    /// [`Server::handle`] with the commit check parsing candidates through
    /// `parser` (the application lends its compensator's model: no second
    /// model on the Modbus task's stack).
    pub fn handle_lending(
        &mut self,
        frame: &[u8],
        now_ms: u64,
        snapshot: &Snapshot,
        state: &mut AppState,
        reply: &mut Vec<u8, MAX_FRAME>,
        parser: &mut impl ParseCandidate,
    ) -> Action {
        let action = self.dispatch(frame, now_ms, snapshot, state, reply, parser);
        let is_exception =
            reply.get(1).is_some_and(|f| f & 0x80 != 0) && reply.get(2) != Some(&0x06);
        let is_write = frame
            .get(1)
            .is_some_and(|f| matches!(f, 0x05 | 0x06 | 0x0F | 0x10));
        if is_exception && is_write {
            self.holding.lock();
        }
        action
    }

    fn dispatch(
        &mut self,
        frame: &[u8],
        now_ms: u64,
        snapshot: &Snapshot,
        state: &mut AppState,
        reply: &mut Vec<u8, MAX_FRAME>,
        parser: &mut impl ParseCandidate,
    ) -> Action {
        reply.clear();
        self.counters.frames = self.counters.frames.wrapping_add(1);
        let n = frame.len();
        if !(4..=MAX_FRAME).contains(&n) {
            self.counters.broken += 1;
            return Action::None;
        }
        // The length check above leaves at least the address, the function
        // and the CRC; the `else` arms only keep a short frame from panicking.
        let Some((body, crc)) = frame.split_last_chunk::<2>() else {
            self.counters.broken += 1;
            return Action::None;
        };
        if crc16(body) != u16::from_le_bytes(*crc) {
            self.counters.crc_errors += 1;
            return Action::None;
        }
        let &[address, function, ..] = body else {
            self.counters.broken += 1;
            return Action::None;
        };
        let unit = state.settings.unit;
        let addressed = address == unit || address == 0;
        if !addressed {
            return Action::None;
        }
        // A function code with the high bit set is never a request; rmodbus
        // would add 0x80 to it in a u8 (overflow), so answer it here.
        if function & 0x80 != 0 {
            if address != 0 {
                exception(address, function, 0x01, reply);
                self.counters.exceptions += 1;
            }
            return Action::None;
        }
        // FC15/16: the byte count must match the frame; FC16's register count
        // must be 1..=123 (spec §6.12) and match the byte count. The product is
        // formed in usize: a count >= 0x8000 would wrap `u16 * 2`.
        if matches!(function, 0x0F | 0x10) {
            let consistent = match *body {
                [_, _, _, _, count_high, count_low, bytes, ..] => {
                    usize::from(bytes) + 9 == n
                        && (function != 0x10 || {
                            let count = usize::from(u16::from_be_bytes([count_high, count_low]));
                            (1..=MAX_WRITE_REGISTERS).contains(&count)
                                && count * 2 == usize::from(bytes)
                        })
                }
                _ => false,
            };
            if !consistent {
                if address != 0 {
                    exception(address, function, 0x03, reply);
                    self.counters.exceptions += 1;
                }
                return Action::None;
            }
        }
        // Count 0 is not a valid read (rmodbus only checks the upper limit).
        if matches!((function, body), (0x01..=0x04, [_, _, _, _, 0, 0])) {
            if address != 0 {
                exception(address, function, 0x03, reply);
                self.counters.exceptions += 1;
            }
            return Action::None;
        }
        let mut action = Action::None;
        let mut mf = ModbusFrame::new(unit, frame, ModbusProto::Rtu, reply);
        if mf.parse().is_err() {
            self.counters.broken += 1;
            mf.response.clear();
            return Action::None;
        }
        if mf.processing_required {
            let processed = if mf.readonly {
                let func = mf.func;
                let result = match mf.get_external_read() {
                    Ok(Read::Words(w)) => {
                        let input = func == rmodbus::consts::ModbusFunction::GetInputs;
                        fill_words(w.address, w.count, w.buf, |a| {
                            if input {
                                snapshot.input_register(a)
                            } else {
                                self.holding.read(a, now_ms, state)
                            }
                        })
                    }
                    Ok(Read::Bits(_)) => Err(ErrorKind::IllegalFunction),
                    Err(e) => Err(e),
                };
                mf.process_external_read(result)
            } else {
                let result = match mf.get_external_write() {
                    Ok(Write::Words(w)) => {
                        let mut values: Vec<u16, 125> = Vec::new();
                        for pair in w.data.chunks_exact(2) {
                            if let &[high, low] = pair {
                                let _ = values.push(u16::from_be_bytes([high, low]));
                            }
                        }
                        let addressing = if address == 0 {
                            Addressing::Broadcast
                        } else {
                            Addressing::Unit
                        };
                        let at = At {
                            now_ms,
                            running_version: snapshot.model_version,
                        };
                        self.holding
                            .write(w.address, &values, at, addressing, state, parser)
                            .map(|c| action = c)
                            .map_err(exception_of)
                    }
                    Ok(Write::Bits(_)) => Err(ErrorKind::IllegalFunction),
                    Err(e) => Err(e),
                };
                mf.process_external_write(result)
            };
            if processed.is_err() {
                // Only a full reply buffer gets here; say so rather than send half a reply.
                let _ = mf.set_modbus_error_if_unset(&ErrorKind::SlaveDeviceFailure);
            }
        }
        if mf.response_required {
            if mf.error.is_some() {
                self.counters.exceptions += 1;
            }
            if mf.finalize_response().is_err() {
                mf.response.clear();
            } else {
                self.counters.replies += 1;
            }
        } else {
            mf.response.clear();
        }
        action
    }
}

/// The Modbus exception answering a refused write.
fn exception_of(e: WriteError) -> ErrorKind {
    match e {
        WriteError::Address => ErrorKind::IllegalDataAddress,
        WriteError::Value => ErrorKind::IllegalDataValue,
        WriteError::Locked => ErrorKind::IllegalFunction,
        WriteError::ModelRefused => ErrorKind::SlaveDeviceFailure,
        WriteError::Busy => ErrorKind::SlaveDeviceBusy,
    }
}

/// Fill a read reply's data area; an address outside the map refuses the
/// whole request (ILLEGAL DATA ADDRESS), as the specification asks.
fn fill_words(
    start: u16,
    count: u16,
    buf: &mut [u8],
    value: impl Fn(u16) -> Option<u16>,
) -> Result<(), ErrorKind> {
    for (i, out) in buf.chunks_exact_mut(2).take(usize::from(count)).enumerate() {
        let a = u16::try_from(i)
            .ok()
            .and_then(|i| start.checked_add(i))
            .ok_or(ErrorKind::IllegalDataAddress)?;
        let v = value(a).ok_or(ErrorKind::IllegalDataAddress)?;
        out.copy_from_slice(&v.to_be_bytes());
    }
    Ok(())
}

/// An exception reply built here (before rmodbus parses) for malformed counts.
fn exception(address: u8, function: u8, code: u8, reply: &mut Vec<u8, MAX_FRAME>) {
    reply.clear();
    let _ = reply.extend_from_slice(&[address, function | 0x80, code]);
    let crc = crc16(reply);
    let _ = reply.extend_from_slice(&crc.to_le_bytes());
}

//! thermocomp-protocol: the board's wire contract, everything a program on
//! the other end of the cable or the file must agree on with the firmware.
//!
//! - [`registers`]: the input registers (FC04) a PLC or `tcomp` reads.
//! - [`holding`]: the holding registers (FC03/06/16), the unlock code,
//!   command numbers ([`holding::Command`]) and result codes
//!   ([`holding::ResultCode`]).
//! - [`states`]: channel and probe state codes as the registers carry them.
//! - [`rtu`]: Modbus RTU framing limits and the CRC-16.
//! - [`trace`]: the run-CSV replay format (the bench board's sensor input).
//! - [`image`]: the model-image format. It lives in the math core, whose
//!   parser builds the evaluator's types; it is re-exported here so that
//!   every format the board speaks is reachable from this one crate.
//!
//! The firmware (`thermocomp`), the boards, the desktop `tcomp`, the host
//! tests and the fuzz targets import these definitions, so both ends of the
//! link cannot disagree on an address or a code. No hardware, no heap.
#![no_std]

pub mod holding;
pub mod registers;
pub mod rtu;
pub mod states;
pub mod trace;

pub use thermocomp_core::image;

/// Most temperature channels on one board (seed 000 uses 20 DS18B20 sensors):
/// the size of the per-channel register blocks and of a trace row.
pub const MAX_CHANNELS: usize = 20;

//! Modbus RTU server: the register map (documented in docs/register-map.md), holding
//! registers with the unlock rule and the model staging area, and the frame
//! handler. Framing, CRC-16 and exception replies come from `rmodbus`; this
//! module decides what each register means.

pub mod holding;
pub mod keys;
pub mod registers;
pub mod rtu_framer;
pub mod server;

pub use holding::Holding;
pub use registers::Snapshot;
pub use rtu_framer::{Outcome as FrameOutcome, RtuFramer, Timing as FrameTiming};
pub use server::{Action, Server};

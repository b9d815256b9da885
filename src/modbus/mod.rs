//! Modbus RTU at the application's edge: a codec between the register map
//! (documented in docs/register-map.md) and the application's typed state.
//! Input registers encode the [`Snapshot`] ([`crate::snapshot`]); holding
//! registers encode and decode [`crate::state::AppState`] under the unlock
//! rule, a write giving the [`crate::state::Command`] the application
//! carries out; the frame handler and the RTU framer. Framing, CRC-16 and
//! exception replies come from `rmodbus`; this module decides what each
//! register means. No module outside it (but `app.rs`, its caller, and the
//! runtime's Modbus task) knows a register.

pub mod holding;
pub mod registers;
pub mod rtu_framer;
pub mod server;

pub use holding::Holding;
pub use registers::Snapshot;
pub use rtu_framer::{Outcome as FrameOutcome, RtuFramer, Timing as FrameTiming};
pub use server::{Action, Server};

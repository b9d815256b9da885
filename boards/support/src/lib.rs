//! board-support: code both board crates need that is about the Cortex-M
//! and its runtime, not about the application (which never touches raw
//! memory: `src/` forbids unsafe code) nor about one board's peripherals.
#![no_std]

pub mod fault_entry;
pub mod fault_record;
pub mod rtu_receive;
pub mod stack;

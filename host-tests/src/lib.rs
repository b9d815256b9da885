//! Test doubles for the board application: they implement the same narrow
//! hardware traits the boards implement, so the real application code runs here.

pub mod mock_flash;
pub mod onewire_emu;
pub mod qemu;

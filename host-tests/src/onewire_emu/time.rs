//! The emulator's clock unit: nanoseconds.

pub const US: u64 = 1_000;
pub const MS: u64 = 1_000_000;

//! The keys the tests give their boards.

/// The unlock key the tests give their boards at commissioning (a fresh
/// board takes the factory code for commissioning only).
pub const TEST_UNLOCK_KEY: u16 = 0x7E57;

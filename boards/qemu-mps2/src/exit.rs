//! How the bench firmware ends: its exit codes (the host tests check
//! them) and the end of a one-shot mode.

use crate::semihost::{self, log};
use board_support::stack;

/// Exit codes of the bench firmware (the host tests check them).
pub mod exit_code {
    pub const OK: u32 = 0;
    pub const SELFTEST_FAILED: u32 = 1;
    pub const BAD_COMMAND_LINE: u32 = 2;
    pub const TRACE_ERROR: u32 = 3;
    pub const PANIC: u32 = 101;
}

/// The end of a one-shot mode (selftest, replay, bench): the stack's
/// high-water mark (`scripts/size.sh` reads it), then QEMU exits with `code`.
pub fn finish(code: u32) -> ! {
    log!("stack high-water: {} B", stack::high_water());
    semihost::exit(code)
}

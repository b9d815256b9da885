//! The fault record's RAM words, for both boards' `FaultBoard::load` and
//! `FaultBoard::store`.
//!
//! Each board's `board-memory.x` reserves the words at `__fault_record`, in
//! a NOINIT region outside every section: cortex-m-rt's startup neither
//! loads nor zeroes them, so they keep their contents over a system or
//! watchdog reset (not over a power cycle). Only these two functions touch
//! them, word by word with volatile accesses, so they work from any context
//! (a panic, a HardFault, an NMI) without a lock.

use core::ptr::{addr_of_mut, read_volatile, write_volatile};

extern "C" {
    /// The first reserved word (board-memory.x; the application's
    /// `thermocomp::fault::WORDS` of them).
    static mut __fault_record: u32;
}

/// The `N` reserved words as they are.
pub fn load<const N: usize>() -> [u32; N] {
    let mut words = [0u32; N];
    let base = addr_of_mut!(__fault_record) as *const u32;
    for (i, w) in words.iter_mut().enumerate() {
        // SAFETY: `base + i` is one of the words board-memory.x reserves
        // (the board's record is `N` words long): plain RAM that no section
        // and no other code uses, read as a word.
        *w = unsafe { read_volatile(base.add(i)) };
    }
    words
}

/// Write the `N` reserved words.
pub fn store<const N: usize>(words: &[u32; N]) {
    let base = addr_of_mut!(__fault_record);
    for (i, w) in words.iter().enumerate() {
        // SAFETY: as in `load`.
        unsafe { write_volatile(base.add(i), *w) };
    }
}

//! Stack high-water mark. Before RAM is initialised (`__pre_init`, below)
//! the whole stack region — from the end of `.bss`/`.uninit`
//! (`_stack_end`) up to the stack pointer at reset — is painted with a
//! pattern; the lowest word that no longer holds it is as deep as the stack
//! has ever gone ([`high_water`]).

use core::ptr::{addr_of, read_volatile};

/// The paint: a word the stack is unlikely to hold by chance.
const PAINT: u32 = 0x5354_4B50; // "STKP"

// Called by cortex-m-rt's reset handler before .data/.bss are set up, on
// the reset stack pointer (the top of RAM): nothing in Rust runs yet, so
// this is assembly, and it touches only r0-r2 (caller-saved) and the
// memory below the stack pointer, which no one uses yet.
core::arch::global_asm!(
    ".section .text.__pre_init,\"ax\",%progbits",
    ".global __pre_init",
    ".type __pre_init,%function",
    ".thumb_func",
    "__pre_init:",
    "ldr r0, =_stack_end",
    "mov r1, sp",
    "ldr r2, ={paint}",
    "1:",
    "cmp r0, r1",
    "bhs 2f",
    "str r2, [r0], #4",
    "b 1b",
    "2:",
    "bx lr",
    ".ltorg",
    paint = const PAINT,
);

extern "C" {
    /// Lowest address of the stack region (cortex-m-rt's link.x).
    static _stack_end: u32;
    /// Top of the stack region, the reset stack pointer (cortex-m-rt's link.x).
    static _stack_start: u32;
}

/// Bytes of stack used at the deepest so far.
pub fn high_water() -> u32 {
    let top = addr_of!(_stack_start) as usize;
    let mut p: *const u32 = addr_of!(_stack_end);
    // SAFETY: `p` walks word by word from the bottom of the stack region
    // towards its top and stops at the first word that is not the paint,
    // which is at most as deep as the live stack: every read is of RAM in
    // the region, volatile, and only of words no live frame owns (the one
    // it stops at is read, never kept).
    unsafe {
        while (p as usize) < top && read_volatile(p) == PAINT {
            p = p.add(1);
        }
    }
    (top - p as usize) as u32
}

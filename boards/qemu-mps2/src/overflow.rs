//! `overflow` mode: the stack-overflow check of the bench board
//! (host-tests/tests/qemu_overflow.rs). With flip-link the stack sits at
//! the bottom of RAM; a recursion that runs off it must fault into the
//! fault record and reset the board, never write over `.bss`.

use core::sync::atomic::Ordering;

use crate::exit::exit_code;
use crate::safety;
use crate::semihost::{self, log};
use thermocomp::fault;

/// Print a fault record left by the previous run and exit 0; without one,
/// field mode on (a fault resets, as on a field board) and recurse until
/// the stack overflows. A canary in `.bss` shows whether anything wrote
/// over the statics on the way down.
pub fn run() -> ! {
    static CANARY: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
    if let Some(r) = fault::recorded::<safety::Bench>() {
        log!(
            "fault record: kind={} ({}) pc={:#010x} detail={:#010x} count={} canary={:#010x}",
            r.kind,
            fault::kind::name(r.kind),
            r.pc,
            r.detail,
            r.count,
            CANARY.load(Ordering::Relaxed)
        );
        semihost::exit(exit_code::OK)
    }
    CANARY.store(0xC0FF_EE00, Ordering::Relaxed);
    safety::FIELD_MODE.store(true, Ordering::Relaxed);
    let depth = deeper(0);
    // Not reached: the recursion has no end short of the stack's.
    log!("recursion returned at depth {}: no overflow", depth);
    semihost::exit(exit_code::SELFTEST_FAILED)
}

/// One KiB of stack per level, kept live across the call.
#[inline(never)]
fn deeper(n: u32) -> u32 {
    let mut frame = [0u8; 1024];
    if let Some(b) = frame.get_mut(n as usize % 1024) {
        *b = n as u8;
    }
    core::hint::black_box(&mut frame);
    if n == u32::MAX {
        return n;
    }
    deeper(n + 1).wrapping_add(u32::from(frame[0]))
}

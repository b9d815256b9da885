//! Instruction counts of a piece of code, measured under QEMU.
//!
//! QEMU models neither the Cortex-M4 pipeline nor the DWT cycle counter. With
//! `-icount shift=0` its virtual clock advances exactly 1 ns per executed
//! instruction, and SysTick (clocked at the board's 25 MHz, 40 ns per count)
//! counts that virtual time: one SysTick count = 40 instructions. We read the
//! SysTick current value around each call with interrupts masked, subtract the
//! cost of an empty call, and average over many calls, which brings the 40-
//! instruction quantum well below one instruction (the call's phase against
//! the counter varies from call to call). The result is instructions, not
//! cycles: on real Cortex-M4 silicon most instructions take one cycle, loads
//! and multiplies with dependencies two, taken branches 2–4, and flash wait
//! states (5 at 168 MHz, hidden mostly by the ART accelerator) add more.

use cortex_m::peripheral::SYST;

/// QEMU's virtual nanoseconds per SysTick count at 25 MHz; with
/// `-icount shift=0` that is also instructions per count.
pub const INSTRUCTIONS_PER_COUNT: u64 = 40;

fn elapsed_counts(start: u32, end: u32) -> u64 {
    // SysTick counts down and reloads at 24_999: one wrap at most per call.
    let reload = u64::from(SYST::get_reload()) + 1;
    (u64::from(start) + reload - u64::from(end)) % reload
}

/// Average instructions per call of `f` over `runs` calls (call overhead
/// removed), in hundredths of an instruction.
pub fn instructions_x100(runs: u32, mut f: impl FnMut()) -> u64 {
    let mut total = 0u64;
    let mut empty = 0u64;
    for _ in 0..runs {
        total += measure(&mut f);
        empty += measure(&mut || {});
    }
    let net = total.saturating_sub(empty);
    net * INSTRUCTIONS_PER_COUNT * 100 / u64::from(runs.max(1))
}

#[inline(never)]
fn measure(f: &mut dyn FnMut()) -> u64 {
    cortex_m::interrupt::free(|_| {
        let start = SYST::get_current();
        f();
        let end = SYST::get_current();
        elapsed_counts(start, end)
    })
}

/// A loop of exactly 1000 iterations of (nop, subs, bne): 3000 instructions
/// plus a few for setup; it calibrates the counting method itself.
#[inline(never)]
pub fn known_loop() {
    // SAFETY: only a register counter and nops.
    unsafe {
        core::arch::asm!(
            "2:",
            "nop",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) 1000u32 => _,
            options(nomem, nostack),
        );
    }
}

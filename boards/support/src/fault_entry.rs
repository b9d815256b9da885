//! The HardFault entry of both boards, made to survive a stack overflow.
//!
//! With flip-link the stack sits at the bottom of RAM, so an overflow runs
//! into unmapped memory and faults instead of silently corrupting `.bss`.
//! But the exception's own frame could not be pushed there, and cortex-m-rt's
//! trampoline hands the handler that stack pointer: the handler's first push
//! would fault again (a lockup, no fault record). So this entry, in assembly
//! before any Rust runs, takes the stack pointer at the fault, moves MSP back
//! to the top of the stack region (we never return: the handler records the
//! fault and resets) and calls the board's `board_hard_fault(sp)`.
//!
//! Both boards run everything on MSP (embassy's executors use no process
//! stack), so MSP is the stack the fault happened on.

core::arch::global_asm!(
    ".section .HardFault.user,\"ax\",%progbits",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "mrs r0, MSP",
    "ldr r1, =_stack_start",
    "msr MSP, r1",
    "b board_hard_fault",
    ".ltorg",
);

extern "C" {
    /// Lowest address of the stack region (cortex-m-rt's link.x; flip-link
    /// sets it to the start of RAM).
    static _stack_end: u32;
    /// Top of the stack region.
    static _stack_start: u32;
}

/// The faulting code's PC from the exception frame at `sp`, when the frame
/// lies inside the stack region (`None`: the stack had overflowed, no frame
/// was pushed).
pub fn frame_pc(sp: u32) -> Option<u32> {
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let sp = sp as usize;
    // The frame: r0-r3, r12, lr, pc, xpsr (8 words); pc at +24.
    if sp < bottom || sp.checked_add(32)? > top || !sp.is_multiple_of(4) {
        return None;
    }
    // SAFETY: `sp + 24` is a word-aligned address inside the stack region
    // (checked above), where the core pushed the exception frame.
    Some(unsafe { core::ptr::read_volatile((sp + 24) as *const u32) })
}

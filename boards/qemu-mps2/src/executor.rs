//! A thread-mode embassy executor that sleeps with WFI. The stock cortex-m
//! thread executor sleeps with WFE, which QEMU treats as a no-op, so it would
//! spin a host core at 100 % for the whole bench run.

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{raw, Spawner};

static WORK_PENDING: AtomicBool = AtomicBool::new(true);

// Called by embassy when a task is woken (possibly from an interrupt).
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK_PENDING.store(true, Ordering::Release);
}

pub struct Executor {
    inner: raw::Executor,
}

impl Executor {
    pub fn new() -> Self {
        Self {
            inner: raw::Executor::new(core::ptr::null_mut()),
        }
    }

    /// Run forever: `init` spawns the tasks, then poll whenever work is pending
    /// and sleep in WFI otherwise.
    pub fn run(&'static mut self, init: impl FnOnce(Spawner)) -> ! {
        init(self.inner.spawner());
        loop {
            // SAFETY: poll is never called re-entrantly: only this loop calls it.
            unsafe { self.inner.poll() };
            // Check-then-sleep with interrupts masked: an interrupt that sets
            // the flag after the check still ends WFI (pending IRQs wake the
            // core even with PRIMASK set) and runs once they are unmasked.
            cortex_m::interrupt::disable();
            if !WORK_PENDING.swap(false, Ordering::AcqRel) {
                cortex_m::asm::wfi();
            }
            // SAFETY: re-enabling after our own short masked section.
            unsafe { cortex_m::interrupt::enable() };
        }
    }
}

//! embassy-time driver on the Cortex-M SysTick: a 1 kHz tick (tick-hz-1_000),
//! because the MPS2 has no RTC-style timer embassy supports and SysTick is what
//! QEMU emulates for every Cortex-M machine. One global timer queue
//! (embassy-time-queue-utils) is served from the SysTick exception.

use core::cell::{Cell, RefCell};
use core::task::Waker;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::exception;
use critical_section::Mutex;
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

/// MPS2-AN386 core clock (QEMU models the board's 25 MHz SYSCLK).
pub const CORE_CLOCK_HZ: u32 = 25_000_000;
const TICK_HZ: u32 = 1_000;

struct SysTickDriver {
    ticks: Mutex<Cell<u64>>,
    alarm_at: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ticks: Mutex::new(Cell::new(0)),
    alarm_at: Mutex::new(Cell::new(u64::MAX)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

/// Start SysTick at 1 kHz. Call once, before the executor runs.
pub fn init(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CORE_CLOCK_HZ / TICK_HZ - 1);
    syst.clear_current();
    syst.enable_interrupt();
    // SysTick keeps running for the life of the firmware; the SYST token
    // is dropped here (it owns nothing that stops the counter).
    syst.enable_counter();
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.ticks.borrow(cs).get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut queue = self.queue.borrow(cs).borrow_mut();
            if queue.schedule_wake(at, waker) {
                let now = self.ticks.borrow(cs).get();
                // Expired timers are woken inside next_expiration; the next one
                // still pending becomes the alarm the SysTick handler checks.
                let next = queue.next_expiration(now);
                self.alarm_at.borrow(cs).set(next);
            }
        });
    }
}

impl SysTickDriver {
    fn on_tick(&self) {
        critical_section::with(|cs| {
            let ticks = self.ticks.borrow(cs);
            let now = ticks.get().wrapping_add(1);
            ticks.set(now);
            let alarm = self.alarm_at.borrow(cs);
            if now >= alarm.get() {
                let next = self.queue.borrow(cs).borrow_mut().next_expiration(now);
                alarm.set(next);
            }
        });
    }
}

#[exception]
fn SysTick() {
    DRIVER.on_tick();
}

/// Microseconds since boot, to the SysTick count (40 ns): the counted ms
/// ticks plus the SysTick counts elapsed in the current one. The RTU
/// framer times each received byte with it (the 1 kHz embassy tick is too
/// coarse for the 750 µs break rule).
pub fn now_us() -> u64 {
    critical_section::with(|cs| {
        let mut ms = DRIVER.ticks.borrow(cs).get();
        let mut val = SYST::get_current();
        // The counter wrapped, but its tick is not counted yet (the SysTick
        // exception waits for this critical section): count it, and read
        // the counter again after the wrap.
        if cortex_m::peripheral::SCB::is_pendst_pending() {
            ms = ms.wrapping_add(1);
            val = SYST::get_current();
        }
        let reload = SYST::get_reload();
        let counts = u64::from(reload.saturating_sub(val));
        let per_ms = u64::from(reload) + 1;
        ms.wrapping_mul(1000).wrapping_add(counts * 1000 / per_ms)
    })
}

/// Milliseconds since boot, as the application reads them.
pub struct Uptime;

impl thermocomp::hal::clock::Clock for Uptime {
    fn now_ms(&self) -> u64 {
        embassy_time::Instant::now().as_millis()
    }
}

//! The bench board's fault path and watchdog (the application's
//! [`thermocomp::fault`] and [`thermocomp::watchdog`] on mps2-an386).
//!
//! - Fault record: 8 words at the top of RAM (`__fault_record`, reserved in
//!   `board-memory.x` outside every section, so neither cortex-m-rt's startup
//!   nor QEMU's reload of the ELF on a system reset touches them), read and
//!   written by [`board_support::fault_record`].
//! - Safe state: UART0 transmitter off (the bench has no RS-485 driver-enable
//!   pin; switching the transmitter off is the same "release the bus" step).
//! - Reset: SCB AIRCR.SYSRESETREQ, which QEMU turns into a machine reset
//!   (without `-no-reboot`): the ELF is loaded again and the board boots.
//! - Watchdog: the CMSDK APB watchdog QEMU models at 0x4000_8000, clocked at
//!   the 25 MHz SYSCLK. It counts LOAD down to 0 and raises its interrupt —
//!   wired to NMI on this machine — then, if not fed, resets the machine at
//!   the second expiry. The NMI handler writes the fault record (kind
//!   watchdog, the interrupted PC, which activity stalled) and resets at once;
//!   the second expiry stays as the backstop if the handler itself hangs.

use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use thermocomp::fault::{self, FaultBoard, WORDS};
use thermocomp::hal::watchdog::Watchdog;

pub struct Bench;

impl FaultBoard for Bench {
    fn safe_state() {
        // SAFETY: one MMIO write to UART0's control register; it only stops
        // the transmitter and receiver (the task that owned the UART never
        // runs again: a reset follows).
        unsafe { write_volatile(0x4000_4008 as *mut u32, 0) };
    }

    fn uptime_ms() -> u64 {
        embassy_time::Instant::now().as_millis()
    }

    fn load() -> [u32; WORDS] {
        board_support::fault_record::load()
    }

    fn store(words: &[u32; WORDS]) {
        board_support::fault_record::store(words)
    }

    fn reset() -> ! {
        cortex_m::peripheral::SCB::sys_reset()
    }
}

/// True once the board serves (the `serve` mode): faults then reset the
/// board as in the field. In the one-shot modes (selftest, replay, bench) a
/// fault ends QEMU with exit status 101 so that the host test sees it.
pub static FIELD_MODE: AtomicBool = AtomicBool::new(false);

/// Which activity the feeder last saw without progress (the detail word of
/// a watchdog record).
pub static STALLED: AtomicU32 = AtomicU32::new(0);

/// Watchdog timeout of the bench board (first expiry, NMI): 4 s. The
/// longest legitimate pause of either activity on the bench is well below:
/// a measurement cycle is the trace pace (30–100 ms in the tests) plus the
/// emulated 750 ms conversion; a model commit on the RAM "flash" takes
/// microseconds (slice 4 adds the real erase time: 1–2 s of a 128 KiB
/// sector, done outside the lock). 4 s also covers a loaded 2-core host
/// slowing QEMU down by 2–3x.
pub const WATCHDOG_TIMEOUT_MS: u32 = 4_000;

mod wdog {
    pub const BASE: usize = 0x4000_8000;
    pub const LOAD: *mut u32 = BASE as *mut u32;
    pub const CONTROL: *mut u32 = (BASE + 0x08) as *mut u32;
    pub const INTCLR: *mut u32 = (BASE + 0x0C) as *mut u32;
    pub const LOCK: *mut u32 = (BASE + 0xC00) as *mut u32;
    pub const UNLOCK_KEY: u32 = 0x1ACC_E551;
    pub const INTEN: u32 = 1 << 0;
    pub const RESEN: u32 = 1 << 1;
}

/// The CMSDK watchdog as the application's feeder sees it.
pub struct CmsdkWatchdog;

impl CmsdkWatchdog {
    /// Start it ([`WATCHDOG_TIMEOUT_MS`]).
    pub fn start() -> Self {
        watchdog_start();
        CmsdkWatchdog
    }
}

impl Watchdog for CmsdkWatchdog {
    fn pet(&mut self) {
        watchdog_feed();
    }

    fn note_stalled(&mut self, bits: u32) {
        STALLED.store(bits, Ordering::Relaxed);
    }
}

/// Start the watchdog (interrupt and reset enabled), then lock its registers.
fn watchdog_start() {
    let ticks = WATCHDOG_TIMEOUT_MS * (crate::time_driver::CORE_CLOCK_HZ / 1000);
    // SAFETY: MMIO writes to the CMSDK watchdog, used by this module alone.
    unsafe {
        write_volatile(wdog::LOCK, wdog::UNLOCK_KEY);
        write_volatile(wdog::LOAD, ticks);
        write_volatile(wdog::CONTROL, wdog::INTEN | wdog::RESEN);
        write_volatile(wdog::LOCK, 0);
    }
}

/// Feed: clear the interrupt and reload the counter.
fn watchdog_feed() {
    // SAFETY: as in `watchdog_start`.
    unsafe {
        write_volatile(wdog::LOCK, wdog::UNLOCK_KEY);
        write_volatile(wdog::INTCLR, 1);
        write_volatile(wdog::LOCK, 0);
    }
}

// NMI entry: hand the stacked exception frame (MSP or PSP, by EXC_RETURN bit
// 2) to the Rust handler, which reads the interrupted PC from it.
core::arch::global_asm!(
    ".section .text.NonMaskableInt,\"ax\",%progbits",
    ".global NonMaskableInt",
    ".type NonMaskableInt,%function",
    ".thumb_func",
    "NonMaskableInt:",
    "tst lr, #4",
    "ite eq",
    "mrseq r0, msp",
    "mrsne r0, psp",
    "b {handler}",
    handler = sym watchdog_nmi,
);

/// The watchdog's first expiry.
///
/// # Safety
/// Called only by the NMI entry above, with the stacked exception frame.
unsafe extern "C" fn watchdog_nmi(frame: *const u32) -> ! {
    // SAFETY: an exception frame is 8 words; the PC is word 6.
    let pc = unsafe { read_volatile(frame.add(6)) };
    // The bus first (the UART off), then the log.
    <Bench as FaultBoard>::safe_state();
    crate::semihost::log!(
        "watchdog expired at pc={:#010x} (stalled: {:#x}); fault recorded, resetting",
        pc,
        STALLED.load(Ordering::Relaxed)
    );
    fault::fault::<Bench>(fault::kind::WATCHDOG, pc, STALLED.load(Ordering::Relaxed))
}

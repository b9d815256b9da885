//! The NUCLEO's fault path and watchdog ([`thermocomp::fault`] and
//! [`thermocomp::watchdog`] on the STM32F446RE).
//!
//! - Safe state: PA8, the RS-485 transceiver's driver enable, driven low
//!   through GPIOA's BSRR (one write, no lock, valid from any context), so a
//!   fault during a reply never leaves the bus jammed.
//! - Fault record: 8 words at the top of SRAM (`__fault_record`, reserved
//!   in `board-memory.x` outside every section; SRAM keeps its contents over
//!   a system or watchdog reset, not over a power cycle), read and written
//!   by [`board_support::fault_record`].
//! - Reset: SCB AIRCR.SYSRESETREQ.
//! - Watchdog: the IWDG (LSI clock), which resets without an interrupt
//!   first: after a watchdog reset the boot code finds RCC_CSR.IWDGRSTF and
//!   records a fault of kind watchdog with PC 0 (unknown) and, as detail,
//!   which activity the feeder last saw stalled (a NOINIT word it keeps).

use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{pac, peripherals, Peri};
use thermocomp::fault::{self, FaultBoard, WORDS};
use thermocomp::hal::watchdog::Watchdog;

extern "C" {
    /// One word after the record (NOINIT): the feeder's last stall bits.
    static mut __watchdog_hint: u32;
}

/// The IWDG as the application's feeder sees it.
pub struct Iwdg(IndependentWatchdog<'static, peripherals::IWDG>);

impl Iwdg {
    /// Start the IWDG ([`WATCHDOG_TIMEOUT_US`]); it cannot be stopped again.
    pub fn start(iwdg: Peri<'static, peripherals::IWDG>) -> Self {
        let mut watchdog = IndependentWatchdog::new(iwdg, WATCHDOG_TIMEOUT_US);
        watchdog.unleash();
        Iwdg(watchdog)
    }
}

impl Watchdog for Iwdg {
    fn pet(&mut self) {
        self.0.pet();
    }

    /// Kept over the IWDG's reset, which gives no interrupt to record it in.
    fn note_stalled(&mut self, bits: u32) {
        // SAFETY: a word of NOINIT RAM only this module touches.
        unsafe { write_volatile(addr_of_mut!(__watchdog_hint), bits) };
    }
}

/// IWDG timeout: 10 s nominal. The longest legitimate gap between two feeds
/// is one measurement cycle (1 s; 20 sensors take 0.96 s on the bus) plus a
/// model commit that erases a 128 KiB sector with the CPU stalled on flash
/// (RM0390 / datasheet: 1 s typical, 2 s max at x32 parallelism, 4 s max at
/// x8): 5 s at worst. The LSI runs at 17–47 kHz over temperature and parts
/// (datasheet), so 10 s nominal is between 6.8 s and 18.8 s: always longer
/// than 5 s, and a stall is still caught within 20 s.
pub const WATCHDOG_TIMEOUT_US: u32 = 10_000_000;

pub struct Nucleo;

impl FaultBoard for Nucleo {
    fn safe_state() {
        // PA8 low: BSRR bit 16 + 8 resets the pin (atomic, no read-modify-write).
        pac::GPIOA.bsrr().write(|w| w.set_br(8, true));
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

/// At boot: was the last reset the IWDG's? Then record it (a watchdog reset
/// leaves no time for the fault path) and clear the reset flags.
pub fn note_watchdog_reset() {
    let csr = pac::RCC.csr().read();
    if csr.wdgrstf() {
        // SAFETY: as in `Iwdg::note_stalled`; only the two stall bits count
        // (the word is power-on garbage until the feeder's first look).
        let hint = unsafe { read_volatile(addr_of_mut!(__watchdog_hint)) } & 0b11;
        fault::record::<Nucleo>(fault::kind::WATCHDOG, 0, hint);
    }
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
}

/// HardFault, called by `board_support::fault_entry` on a valid stack with
/// the stack pointer at the fault: a frame inside the stack region gives
/// the PC (kind HardFault, detail the CFSR); none means the stack overflowed
/// (flip-link: into the bottom of RAM; kind stack overflow, detail the SP).
#[no_mangle]
unsafe extern "C" fn board_hard_fault(sp: u32) -> ! {
    // SAFETY: a read of the SCB's configurable fault status register.
    let cfsr = unsafe { (*cortex_m::peripheral::SCB::PTR).cfsr.read() };
    match board_support::fault_entry::frame_pc(sp) {
        Some(pc) => fault::fault::<Nucleo>(fault::kind::HARD_FAULT, pc, cfsr),
        None => fault::fault::<Nucleo>(fault::kind::STACK_OVERFLOW, 0, sp),
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // The bus first, then the log (a probe may not be attached).
    Nucleo::safe_state();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    let line = info.location().map_or(0, |l| l.line());
    fault::fault::<Nucleo>(fault::kind::PANIC, 0, line)
}

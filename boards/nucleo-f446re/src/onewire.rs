//! 1-Wire master for the DS18B20 bus on PC7 (D9): open-drain GPIO with the
//! external 4.7 kΩ pull-up, bit-banged with the slot timing of
//! `thermocomp::acquisition::bitbang` and timed by the DWT cycle counter.
//!
//! Why not `embassy_time::Delay`: it busy-waits on the time driver's tick,
//! which cannot time a 2 µs or 10 µs step reliably (at a 32.768 kHz tick a
//! 6 µs delay becomes ~31 µs). The cycle counter at 168 MHz resolves 6 ns.
//! The timed part of each slot (≤ 60 µs: the low pulse, and release → sample
//! of a read slot) runs with interrupts masked; the rest of the slot and the
//! 500 µs reset low phase do not. The 750 ms conversion is awaited by the
//! acquisition on `embassy_time::Delay` (async), so the executor keeps
//! serving Modbus. Receive the Modbus UART by DMA/ring buffer so a 60 µs
//! masked section cannot overrun it.
//!
//! Construction (in `main`, after `embassy_stm32::init`):
//! ```ignore
//! let bus = onewire::new_bus(p.PC7, 168_000_000);
//! let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), stored_map);
//! acq.discover(&mut bus).await?;            // new sensors → free channels
//! acq.configure(&mut bus).await?;           // 12-bit on every sensor
//! loop {
//!     let report = acq.cycle(&mut bus, &mut embassy_time::Delay, now_ms).await;
//!     // acq.value(ch, now_ms) → process image; acq.map().to_bytes() → flash
//! }
//! ```

use embassy_stm32::gpio::{Flex, Pin, Speed};
use embassy_stm32::Peri;
use thermocomp::acquisition::bitbang::{BitBangBus, BusyDelay, OpenDrainPin, SlotTiming};
use thermocomp::hal::onewire::BusError;

/// The DQ line: open drain; push-pull high only as a strong pull-up.
pub struct DqPin<'d> {
    pin: Flex<'d>,
    strong: bool,
}

impl<'d> DqPin<'d> {
    pub fn new(pin: Peri<'d, impl Pin>) -> Self {
        let mut pin = Flex::new(pin);
        pin.set_high(); // released
        pin.set_as_input_output(Speed::Medium);
        DqPin { pin, strong: false }
    }
}

impl OpenDrainPin for DqPin<'_> {
    fn set_low(&mut self) {
        if self.strong {
            self.release();
        }
        self.pin.set_low();
    }

    fn release(&mut self) {
        self.pin.set_high();
        if self.strong {
            self.pin.set_as_input_output(Speed::Medium);
            self.strong = false;
        }
    }

    fn is_high(&mut self) -> bool {
        self.pin.is_high()
    }

    fn drive_high(&mut self) -> Result<(), BusError> {
        // Parasite power: push-pull high for the conversion.
        self.pin.set_high();
        self.pin.set_as_output(Speed::Medium);
        self.strong = true;
        Ok(())
    }

    fn critical<R>(&mut self, f: impl FnOnce(&mut Self) -> R) -> R {
        cortex_m::interrupt::free(|_| f(self))
    }
}

/// Busy-wait on the DWT cycle counter.
pub struct CycleDelay {
    cycles_per_us: u32,
}

impl CycleDelay {
    /// Enables the cycle counter (DCB trace enable + DWT CYCCNT).
    pub fn new(sysclk_hz: u32) -> Self {
        // SAFETY: only the trace-enable bit of DCB and the cycle-counter
        // enable of DWT are written; nothing else in the firmware uses them.
        let mut cp = unsafe { cortex_m::Peripherals::steal() };
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();
        CycleDelay {
            cycles_per_us: (sysclk_hz / 1_000_000).max(1),
        }
    }
}

impl BusyDelay for CycleDelay {
    fn delay_us(&mut self, us: u32) {
        let start = cortex_m::peripheral::DWT::cycle_count();
        let cycles = us.saturating_mul(self.cycles_per_us);
        while cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) < cycles {}
    }
}

/// The board's 1-Wire bus on `pin` (PC7), standard slot timing.
pub fn new_bus<'d>(pin: Peri<'d, impl Pin>, sysclk_hz: u32) -> BitBangBus<DqPin<'d>, CycleDelay> {
    BitBangBus::new(
        DqPin::new(pin),
        CycleDelay::new(sysclk_hz),
        SlotTiming::STANDARD,
    )
}

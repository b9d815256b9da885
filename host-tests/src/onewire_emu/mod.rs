//! Pin-level 1-Wire emulator: an open-drain wired-AND line, a virtual clock
//! advanced only by delays, and DS18B20s that react to the master's edges
//! with the datasheet's timing windows: the protocol is the shared model
//! (`boards/ds18b20-model`, which the QEMU board's slot-level bus runs too),
//! the timing, parasite power and faults are [`Ds18b20`]'s.
//!
//! The master side is [`EmuPin`] + [`EmuDelay`]: they implement the board's
//! `OpenDrainPin`/`BusyDelay` (so the real `BitBangBus` runs here), the async
//! `DelayNs` used for the conversion wait, and embedded-hal 0.2 pin/delay
//! traits (so the `one-wire-bus`/`ds18b20` crates can be run for comparison).
//!
//! Timing model (datasheet DS18B20, "1-Wire signaling"):
//! - a low pulse ≥ 480 µs is a reset; devices answer 30 µs after the rising
//!   edge with a 120 µs presence pulse;
//! - a write slot: the device samples 30 µs after the falling edge (window
//!   15–60 µs); a low pulse ≤ 15 µs is a clean 1, 60–120 µs a clean 0,
//!   anything between is a timing violation (counted; the 30 µs sample
//!   decides the bit);
//! - a read slot: a device sending 0 holds the line low from the falling edge
//!   for exactly t_RDV = 15 µs; a master sampling later sees the pull-up (1),
//!   so a late read corrupts the data as on real hardware, and the sample is
//!   counted as a violation;
//! - slots shorter than 60 µs or a recovery under 1 µs are violations.

mod device;
pub mod replay;
mod time;

pub use device::{Ds18b20, Fault};

use std::cell::RefCell;
use std::rc::Rc;
use thermocomp::acquisition::bitbang::{BusyDelay, OpenDrainPin};

pub use time::{MS, US};

/// Timing violations seen by the devices, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Violations {
    /// Read slot sampled more than 15 µs after its falling edge.
    pub late_read: u64,
    /// Write slot low between 15 and 60 µs, or over 120 µs (not a reset).
    pub ambiguous_write: u64,
    /// Slot (fall to next fall) shorter than 60 µs.
    pub short_slot: u64,
    /// Recovery (rise to next fall) shorter than 1 µs.
    pub short_recovery: u64,
}

impl Violations {
    pub fn total(&self) -> u64 {
        self.late_read + self.ambiguous_write + self.short_slot + self.short_recovery
    }
}

/// When a scheduled [`LineEvent`] fires: checked at every falling edge,
/// before the devices see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trigger {
    /// After this many more falling edges (slots and resets).
    AfterFalls(u64),
    /// When `device` is about to send scratchpad bit `bit` (0..72).
    ReadBit { device: usize, bit: u8 },
    /// When `device` is about to receive Match ROM bit `bit` (0..64).
    MatchBit { device: usize, bit: u8 },
}

/// A fault injected in the middle of whatever the master is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineEvent {
    /// Line shorted to ground for the next `falls` falling edges.
    Short { falls: u64 },
    /// Cable cut (no device sees the master) for the next `falls` edges.
    Open { falls: u64 },
    /// Device brownout: power-on contents, transaction lost.
    PowerOnReset(usize),
    /// Sets a device fault.
    SetFault(usize, Fault),
}

/// Line statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Time spent in busy-wait delays (the CPU held), ns.
    pub busy_ns: u64,
    pub resets: u64,
    pub slots: u64,
    pub violations: Violations,
}

pub(crate) struct Line {
    pub now_ns: u64,
    master_low: bool,
    fall_ns: Option<u64>,
    rise_ns: Option<u64>,
    /// The current low pulse is a read slot being sampled (for the check).
    pub devices: Vec<Ds18b20>,
    /// Every device gone (cut cable): no presence.
    pub open: bool,
    /// Line shorted to ground.
    pub short: bool,
    /// Added to every busy delay (models code overhead / a coarse timer).
    pub delay_overhead_ns: u64,
    /// The strong pull-up is on.
    pub strong_pullup: bool,
    pub stats: Stats,
    /// Falling edges so far (the clock of [`Trigger::AfterFalls`]).
    falls: u64,
    /// Scheduled faults; `AfterFalls` already made absolute.
    events: Vec<(Trigger, LineEvent)>,
    /// Transient short / open until this fall count.
    short_until: u64,
    open_until: u64,
}

impl Line {
    fn is_shorted(&self) -> bool {
        self.short || self.falls < self.short_until
    }

    fn is_open(&self) -> bool {
        self.open || self.falls < self.open_until
    }

    /// Fires the scheduled events due at this falling edge.
    fn fire_events(&mut self) {
        let mut i = 0;
        while i < self.events.len() {
            let (trigger, event) = self.events[i];
            let due = match trigger {
                Trigger::AfterFalls(at) => self.falls >= at,
                Trigger::ReadBit { device, bit } => self
                    .devices
                    .get(device)
                    .is_some_and(|d| d.sending_bit() == Some(bit)),
                Trigger::MatchBit { device, bit } => self
                    .devices
                    .get(device)
                    .is_some_and(|d| d.matching_bit() == Some(bit)),
            };
            if !due {
                i += 1;
                continue;
            }
            self.events.remove(i);
            match event {
                LineEvent::Short { falls } => self.short_until = self.falls + falls,
                LineEvent::Open { falls } => self.open_until = self.falls + falls,
                LineEvent::PowerOnReset(d) => {
                    if let Some(d) = self.devices.get_mut(d) {
                        d.power_on_reset();
                    }
                }
                LineEvent::SetFault(d, f) => {
                    if let Some(d) = self.devices.get_mut(d) {
                        d.set_fault(f);
                    }
                }
            }
        }
    }

    fn drive_low(&mut self) {
        if self.master_low {
            return;
        }
        self.fire_events();
        self.falls += 1;
        let now = self.now_ns;
        if let Some(f) = self.fall_ns {
            if now - f < 60 * US {
                self.stats.violations.short_slot += 1;
            }
        }
        if let Some(r) = self.rise_ns {
            if now - r < US {
                self.stats.violations.short_recovery += 1;
            }
        }
        self.master_low = true;
        self.fall_ns = Some(now);
        if !self.is_open() {
            for d in &mut self.devices {
                d.on_fall(now);
            }
        }
    }

    fn set_strong(&mut self, on: bool) {
        if self.strong_pullup == on {
            return;
        }
        self.strong_pullup = on;
        let now = self.now_ns;
        for d in &mut self.devices {
            d.on_strong_pullup(now, on);
        }
    }

    fn release(&mut self) {
        self.set_strong(false);
        if !self.master_low {
            return;
        }
        let now = self.now_ns;
        self.master_low = false;
        self.rise_ns = Some(now);
        let low = now - self.fall_ns.unwrap_or(now);
        if low >= 480 * US {
            self.stats.resets += 1;
            // A reset ends any slot sequence: the next fall starts fresh.
            self.fall_ns = None;
        } else {
            self.stats.slots += 1;
        }
        if !self.is_open() {
            let mut ambiguous = 0;
            for d in &mut self.devices {
                if d.on_rise(now, low) {
                    ambiguous += 1;
                }
            }
            if ambiguous > 0 {
                self.stats.violations.ambiguous_write += 1;
            }
        }
    }

    fn is_high(&mut self) -> bool {
        let now = self.now_ns;
        if self.master_low || self.is_shorted() {
            return false;
        }
        if let Some(f) = self.fall_ns {
            // Sampling a read slot: must be within t_RDV of the fall.
            let since = now - f;
            if since > 15 * US && since < 60 * US {
                self.stats.violations.late_read += 1;
            }
        }
        if self.is_open() {
            return true;
        }
        !self.devices.iter().any(|d| d.pulls_low(now))
    }
}

/// The emulated bus: devices plus the line. Cheap handles share it.
#[derive(Clone)]
pub struct Bus {
    line: Rc<RefCell<Line>>,
}

impl Default for Bus {
    fn default() -> Self {
        Self::new()
    }
}

impl Bus {
    pub fn new() -> Bus {
        Bus {
            line: Rc::new(RefCell::new(Line {
                now_ns: 0,
                master_low: false,
                fall_ns: None,
                rise_ns: None,
                devices: Vec::new(),
                open: false,
                short: false,
                delay_overhead_ns: 0,
                strong_pullup: false,
                stats: Stats::default(),
                falls: 0,
                events: Vec::new(),
                short_until: 0,
                open_until: 0,
            })),
        }
    }

    /// Adds a device; returns its index.
    pub fn attach(&self, device: Ds18b20) -> usize {
        let mut l = self.line.borrow_mut();
        l.devices.push(device);
        l.devices.len() - 1
    }

    /// Access to device `i` (set its temperature, inject faults).
    pub fn with_device<R>(&self, i: usize, f: impl FnOnce(&mut Ds18b20) -> R) -> Option<R> {
        self.line.borrow_mut().devices.get_mut(i).map(f)
    }

    pub fn device_count(&self) -> usize {
        self.line.borrow().devices.len()
    }

    /// Cut the bus (no device answers) or restore it.
    pub fn set_open(&self, open: bool) {
        let mut l = self.line.borrow_mut();
        l.open = open;
        if !open {
            l.open_until = 0;
        }
    }

    /// Schedules a fault for the moment `trigger` describes.
    pub fn schedule(&self, trigger: Trigger, event: LineEvent) {
        let mut l = self.line.borrow_mut();
        let trigger = match trigger {
            Trigger::AfterFalls(n) => Trigger::AfterFalls(l.falls + n),
            t => t,
        };
        l.events.push((trigger, event));
    }

    /// Scheduled events that have not fired yet.
    pub fn pending_events(&self) -> usize {
        self.line.borrow().events.len()
    }

    /// Takes device `i` off the bus (it sees and drives nothing).
    pub fn unplug(&self, i: usize) {
        self.with_device(i, |d| d.set_fault(Fault::Silent));
    }

    /// Plugs device `i` back in: it powers up (85.0 °C, EEPROM
    /// configuration) as a real sensor does.
    pub fn plug(&self, i: usize) {
        self.with_device(i, |d| {
            d.set_fault(Fault::None);
            d.power_on_reset();
        });
    }

    /// Short the line to ground or remove the short (a scheduled one too).
    pub fn set_short(&self, short: bool) {
        let mut l = self.line.borrow_mut();
        l.short = short;
        if !short {
            l.short_until = 0;
        }
    }

    pub fn set_delay_overhead_ns(&self, ns: u64) {
        self.line.borrow_mut().delay_overhead_ns = ns;
    }

    pub fn now_ns(&self) -> u64 {
        self.line.borrow().now_ns
    }

    pub fn now_ms(&self) -> u64 {
        self.now_ns() / MS
    }

    /// Let time pass with the line idle (between cycles).
    pub fn advance_ns(&self, ns: u64) {
        self.line.borrow_mut().now_ns += ns;
    }

    pub fn stats(&self) -> Stats {
        self.line.borrow().stats
    }

    pub fn reset_stats(&self) {
        self.line.borrow_mut().stats = Stats::default();
    }

    pub fn pin(&self) -> EmuPin {
        EmuPin { bus: self.clone() }
    }

    pub fn delay(&self) -> EmuDelay {
        EmuDelay { bus: self.clone() }
    }
}

/// The master's open-drain pin.
#[derive(Clone)]
pub struct EmuPin {
    bus: Bus,
}

/// Busy and async delays: both advance the virtual clock.
#[derive(Clone)]
pub struct EmuDelay {
    bus: Bus,
}

impl EmuDelay {
    fn busy_ns(&mut self, ns: u64) {
        let mut l = self.bus.line.borrow_mut();
        let overhead = l.delay_overhead_ns;
        l.now_ns += ns + overhead;
        l.stats.busy_ns += ns + overhead;
    }
}

impl OpenDrainPin for EmuPin {
    fn set_low(&mut self) {
        self.bus.line.borrow_mut().drive_low();
    }
    fn release(&mut self) {
        self.bus.line.borrow_mut().release();
    }
    fn is_high(&mut self) -> bool {
        self.bus.line.borrow_mut().is_high()
    }
    fn drive_high(&mut self) -> Result<(), thermocomp::hal::onewire::BusError> {
        let mut l = self.bus.line.borrow_mut();
        l.release();
        l.set_strong(true);
        Ok(())
    }
}

impl BusyDelay for EmuDelay {
    fn delay_us(&mut self, us: u32) {
        self.busy_ns(u64::from(us) * US);
    }
}

impl embedded_hal_async::delay::DelayNs for EmuDelay {
    async fn delay_ns(&mut self, ns: u32) {
        // A real timer suspends the task: other tasks run, the line idles.
        self.bus.advance_ns(u64::from(ns));
        thermocomp::acquisition::bitbang::yield_now().await;
    }
}

/// Which clock the acquisition sees: the bus's virtual time.
impl thermocomp::hal::clock::Clock for Bus {
    fn now_ms(&self) -> u64 {
        Bus::now_ms(self)
    }
}

// embedded-hal 0.2 traits, for running `one-wire-bus` 0.1.1 on the emulator.
impl embedded_hal_02::digital::v2::OutputPin for EmuPin {
    type Error = core::convert::Infallible;
    fn set_low(&mut self) -> Result<(), Self::Error> {
        OpenDrainPin::set_low(self);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        OpenDrainPin::release(self);
        Ok(())
    }
}

impl embedded_hal_02::digital::v2::InputPin for EmuPin {
    type Error = core::convert::Infallible;
    fn is_high(&self) -> Result<bool, Self::Error> {
        Ok(self.bus.line.borrow_mut().is_high())
    }
    fn is_low(&self) -> Result<bool, Self::Error> {
        Ok(!self.bus.line.borrow_mut().is_high())
    }
}

impl embedded_hal_02::blocking::delay::DelayUs<u16> for EmuDelay {
    fn delay_us(&mut self, us: u16) {
        self.busy_ns(u64::from(us) * US);
    }
}

impl embedded_hal_02::blocking::delay::DelayMs<u16> for EmuDelay {
    fn delay_ms(&mut self, ms: u16) {
        self.busy_ns(u64::from(ms) * MS);
    }
}

/// Runs a future that never waits on anything external (every emulator
/// operation completes at once) to completion.
pub fn block_on<F: core::future::Future>(f: F) -> F::Output {
    let mut f = core::pin::pin!(f);
    let mut cx = core::task::Context::from_waker(core::task::Waker::noop());
    loop {
        if let core::task::Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// A bus with `n` DS18B20s at `temperature` (1/16 °C), their serial numbers
/// drawn from a fixed-seed generator (real-format ROM codes, valid CRCs).
pub fn bus_with_sensors(n: usize, seed: u64, temperature: i16) -> Bus {
    let bus = Bus::new();
    let mut x = seed | 1;
    for _ in 0..n {
        // xorshift64*
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        let serial = x.wrapping_mul(0x2545_F491_4F6C_DD1D) & 0xFFFF_FFFF_FFFF;
        bus.attach(Ds18b20::new(Ds18b20::rom_for(serial), temperature));
    }
    bus
}

/// The board's bit-banged master on the emulated line, standard timing.
pub fn master(bus: &Bus) -> thermocomp::acquisition::bitbang::BitBangBus<EmuPin, EmuDelay> {
    thermocomp::acquisition::bitbang::BitBangBus::new(
        bus.pin(),
        bus.delay(),
        thermocomp::acquisition::bitbang::SlotTiming::STANDARD,
    )
}

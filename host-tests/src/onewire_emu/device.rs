//! One emulated DS18B20 on the pin-level line: the shared protocol model
//! ([`ds18b20_model`], also the QEMU bench board's) with the line's timing
//! (presence pulse, t_RDV, the write slot's sample point), parasite power
//! and the faults a test injects laid over it.

use std::ops::{Deref, DerefMut};

use super::time::{MS, US};
use ds18b20_model::{Command, Ds18b20Model};
use thermocomp::acquisition::rom::RomCode;

/// Faults a test can inject into one device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    None,
    /// Wire broken to this sensor: no presence pulse, never pulls the line
    /// (reads as all ones).
    Silent,
    /// The next `n` scratchpad transmissions have one bit flipped
    /// (`u32::MAX`: every one).
    CorruptScratchpad(u32),
    /// Pulls every read slot low: nine zero bytes (which pass the CRC).
    AllZero,
    /// Browning out continuously: every read shows the power-on contents
    /// (85.0 °C, TH/TL/configuration from EEPROM) and Convert T is not
    /// executed.
    PowerOn,
    /// The converter stopped: the temperature register keeps its value.
    Stuck,
    /// The next `n` Convert T commands are missed (the device was busy or
    /// the command was lost); the register keeps its contents.
    MissConvert(u32),
    /// Answers every command but sends no presence pulse (too weak or too
    /// late for the master's sample): unnoticed while another device
    /// answers the reset.
    NoPresencePulse,
    /// Intermittent data contact counted in resets: connected for `on`
    /// resets, silent for the next `off`, and so on. The supply stays, so
    /// the scratchpad survives.
    FlappingResets {
        on: u32,
        off: u32,
    },
    /// Intermittent data contact in time: connected `on_ms`, silent
    /// `off_ms`; a contact opening mid-transaction cuts it.
    FlappingMs {
        on_ms: u64,
        off_ms: u64,
    },
    /// Every scratchpad transmission stops after `bits` bits; the rest reads
    /// as ones (the pull-up).
    CutRead {
        bits: u8,
    },
    /// The next `n` ROM searches see ROM bit 13 inverted by this device (a
    /// burst on its branch): the master assembles a code with a bad CRC.
    SearchCorrupt(u32),
    /// In the next `n` ROM searches this device drops out after bit 20.
    SearchDropout(u32),
}

/// ROM bit the [`Fault::SearchCorrupt`] burst inverts.
const SEARCH_CORRUPT_BIT: u8 = 13;
/// ROM bit from which a [`Fault::SearchDropout`] device stays silent.
const SEARCH_DROPOUT_BIT: u8 = 20;

/// A DS18B20 on the emulated line: the protocol model (its ROM code,
/// temperature, EEPROM and counters read through `Deref`) and what the
/// line adds to it.
#[derive(Clone, Debug)]
pub struct Ds18b20 {
    model: Ds18b20Model,
    /// Scale of the conversion time (1.0 = datasheet maximum 750 ms at 12 bit;
    /// real parts are usually faster).
    pub conversion_scale_permille: u32,
    pub fault: Fault,
    /// Parasite-powered (V_DD grounded): a conversion needs the strong
    /// pull-up within 10 µs of Convert T and until it ends, else the device
    /// browns out (power-on contents, 85.0 °C).
    pub parasite: bool,
    /// Strong pull-up since (ns), if on.
    strong_since: Option<u64>,
    /// The running conversion lost its supply.
    starved: bool,
    pulldown: Option<(u64, u64)>,
    /// Reset pulses seen (connected or not), for [`Fault::FlappingResets`].
    resets_seen: u64,
    /// Disconnected since the last reset ([`Fault::FlappingResets`]).
    detached: bool,
    /// The running search loses this device at [`SEARCH_DROPOUT_BIT`].
    search_drop: bool,
}

impl Deref for Ds18b20 {
    type Target = Ds18b20Model;
    fn deref(&self) -> &Ds18b20Model {
        &self.model
    }
}

impl DerefMut for Ds18b20 {
    fn deref_mut(&mut self) -> &mut Ds18b20Model {
        &mut self.model
    }
}

impl Ds18b20 {
    /// A device at power-on: register 85.0 °C, 12-bit.
    pub fn new(rom: RomCode, temperature: i16) -> Ds18b20 {
        Ds18b20 {
            model: Ds18b20Model::new(rom, temperature),
            conversion_scale_permille: 1000,
            fault: Fault::None,
            parasite: false,
            strong_since: None,
            starved: false,
            pulldown: None,
            resets_seen: 0,
            detached: false,
            search_drop: false,
        }
    }

    /// A DS18B20 ROM code (family 0x28) from a serial number, valid CRC.
    pub fn rom_for(serial: u64) -> RomCode {
        let s = serial.to_le_bytes();
        Ds18b20Model::rom_for([s[0], s[1], s[2], s[3], s[4], s[5]])
    }

    pub fn set_fault(&mut self, fault: Fault) {
        self.fault = fault;
        if fault == Fault::PowerOn {
            self.power_on_reset();
        }
    }

    /// What a brownout or a reconnection does: the temperature register
    /// back at 85.0 °C, TH/TL/configuration reloaded from EEPROM, any
    /// conversion and transaction lost.
    pub fn power_on_reset(&mut self) {
        self.model.power_on_reset();
        self.starved = false;
        self.pulldown = None;
    }

    fn settle(&mut self, now: u64) {
        if let Some(value) = self.model.take_conversion(now) {
            if self.parasite && self.starved {
                // The supply collapsed: a full power-on reset.
                self.power_on_reset();
                return;
            } else if self.fault != Fault::Stuck {
                self.model.set_register(value);
            }
            self.starved = false;
        }
    }

    /// The master switched the strong pull-up.
    pub(crate) fn on_strong_pullup(&mut self, now: u64, on: bool) {
        if on {
            self.strong_since = Some(now);
            if let Some(end) = self.model.conversion_end() {
                // Too late: more than 10 µs after Convert T started.
                let start = end.saturating_sub(self.conversion_ns());
                self.starved = now > start + 10 * US;
            }
        } else {
            self.settle(now);
            self.strong_since = None;
            if self.model.conversion_end().is_some() {
                self.starved = true;
            }
        }
    }

    fn conversion_ns(&self) -> u64 {
        let t = u64::from(self.resolution().conversion_time_us()) * US;
        t * u64::from(self.conversion_scale_permille) / 1000
    }

    /// Not connected to the line at `now` (it sees no edge, drives nothing).
    fn silent(&self, now: u64) -> bool {
        match self.fault {
            Fault::Silent => true,
            Fault::FlappingResets { .. } => self.detached,
            Fault::FlappingMs { on_ms, off_ms } => (now / MS) % (on_ms + off_ms).max(1) >= on_ms,
            _ => false,
        }
    }

    /// The bit this device sends in the current slot, if it is sending: the
    /// model's, unless a fault bends the scratchpad.
    fn tx_bit(&self, now: u64) -> Option<bool> {
        if let Some(n) = self.model.sending_bit() {
            if matches!(self.fault, Fault::CutRead { bits } if n >= bits) {
                return Some(true);
            }
            if self.fault == Fault::AllZero {
                return Some(false);
            }
        }
        self.model.tx_bit(now)
    }

    pub(crate) fn pulls_low(&self, now: u64) -> bool {
        matches!(self.pulldown, Some((a, b)) if now >= a && now <= b)
    }

    pub(crate) fn on_fall(&mut self, now: u64) {
        self.settle(now);
        if self.parasite && self.model.conversion_end().is_some() {
            // Line pulled low mid-conversion: no supply.
            self.starved = true;
        }
        self.pulldown = None;
        if self.silent(now) {
            return;
        }
        if self.search_drop
            && self
                .model
                .search_position()
                .is_some_and(|bit| bit >= SEARCH_DROPOUT_BIT)
        {
            self.model.go_idle();
        }
        if self.tx_bit(now) == Some(false) {
            // t_RDV: data valid for 15 µs after the falling edge.
            self.pulldown = Some((now, now + 15 * US));
        }
    }

    /// Returns true if this was an ambiguous write slot.
    pub(crate) fn on_rise(&mut self, now: u64, low_ns: u64) -> bool {
        self.settle(now);
        if low_ns >= 480 * US {
            self.resets_seen += 1;
            if let Fault::FlappingResets { on, off } = self.fault {
                let period = u64::from(on) + u64::from(off);
                self.detached = (self.resets_seen - 1) % period.max(1) >= u64::from(on);
            }
        }
        if self.silent(now) {
            self.model.go_idle();
            return false;
        }
        if low_ns >= 480 * US {
            self.model.reset_pulse();
            self.search_drop = false;
            if self.fault != Fault::NoPresencePulse {
                self.pulldown = Some((now + 30 * US, now + 150 * US));
            }
            return false;
        }
        if self.tx_bit(now).is_some() {
            // The pull-down scheduled at the fall lasts its 15 µs.
            self.model.read_slot();
            return false;
        }
        // Receive: the device samples 30 µs after the fall.
        let ambiguous = low_ns > 15 * US && !(60 * US..=120 * US).contains(&low_ns);
        let bit = low_ns <= 30 * US;
        if self.model.is_idle() {
            return false;
        }
        match self.model.write_slot(bit) {
            Some(Command::SearchRom) => self.start_search(),
            Some(Command::ConvertT) => self.convert(now),
            Some(Command::ReadScratchpad) => self.bend_scratchpad(),
            None => {}
        }
        ambiguous
    }

    /// A Search ROM begins: a pending search fault takes effect for it.
    fn start_search(&mut self) {
        match self.fault {
            Fault::SearchCorrupt(n) if n > 0 => {
                self.model.invert_search_bit(SEARCH_CORRUPT_BIT);
                self.fault = Fault::SearchCorrupt(n - 1);
            }
            Fault::SearchDropout(n) if n > 0 => {
                self.search_drop = true;
                self.fault = Fault::SearchDropout(n - 1);
            }
            _ => {}
        }
    }

    /// Convert T taken at `now`, unless a fault keeps the device from it.
    fn convert(&mut self, now: u64) {
        if self.fault == Fault::PowerOn {
            return;
        }
        if let Fault::MissConvert(n) = self.fault {
            self.fault = if n > 1 {
                Fault::MissConvert(n - 1)
            } else {
                Fault::None
            };
            return;
        }
        let end = now + self.conversion_ns();
        self.model.start_conversion(end);
        // Parasite: starved unless the strong pull-up comes in time.
        self.starved = self.parasite;
    }

    /// Read Scratchpad taken: a browning-out device sends the power-on
    /// contents, a corrupting one flips a bit the CRC then catches.
    fn bend_scratchpad(&mut self) {
        if self.fault == Fault::PowerOn {
            // Power-on contents: 50 05, then TH TL config from EEPROM.
            let power_on = self.model.power_on_scratchpad();
            *self.model.sending_mut() = power_on;
        }
        if let Fault::CorruptScratchpad(n) = self.fault {
            if n > 0 {
                self.model.sending_mut()[1] ^= 0x10;
                if n != u32::MAX {
                    self.fault = Fault::CorruptScratchpad(n - 1);
                }
            }
        }
    }

    /// Milliseconds left in a running conversion (for tests).
    pub fn converting_ms(&self, now_ns: u64) -> u64 {
        self.model
            .conversion_end()
            .map_or(0, |end| end.saturating_sub(now_ns) / MS)
    }
}

//! One emulated DS18B20, the protocol only (datasheet DS18B20, "1-Wire ROM
//! commands" and "DS18B20 function commands"): the ROM commands (Search,
//! Match, Read, Skip), the function commands (Convert T, Read Scratchpad
//! with its CRC, Write Scratchpad), the configuration and its resolution,
//! the conversion and the 85.0 °C power-on contents.
//!
//! Two layers run it, each slot by slot:
//! - the QEMU bench board's slot-level bus (`boards/qemu-mps2/src/
//!   emulated_bus.rs`): no timing, conversions done at once;
//! - the host's pin-level emulator (`host-tests/src/onewire_emu`): the
//!   datasheet's timing windows, parasite power and injected faults, which
//!   it lays over the model through the hooks below ([`Command`],
//!   [`Ds18b20Model::sending_mut`], [`Ds18b20Model::invert_search_bit`],
//!   [`Ds18b20Model::take_conversion`]).
//!
//! A slot is one bit either way. Before the slot the layer asks
//! [`Ds18b20Model::tx_bit`]: `Some(bit)` means the device is sending (it
//! pulls the line low for a 0) and the slot ends with
//! [`Ds18b20Model::read_slot`]; `None` means it listens, and the master's
//! bit goes to [`Ds18b20Model::write_slot`]. Times are in the layer's own
//! unit (the host's nanoseconds; the bench passes 0): the model only
//! compares them.
#![no_std]

use thermocomp::acquisition::ds18b20::{self, Resolution, POWER_ON_RAW};
use thermocomp::acquisition::rom::{RomCode, MATCH_ROM, READ_ROM, SEARCH_ROM, SKIP_ROM};

/// TH, TL and configuration as they leave the factory (12 bit).
pub const FACTORY_EEPROM: [u8; 3] = [0x4B, 0x46, 0x7F];

/// Scratchpad bits a Read Scratchpad sends (9 bytes, the last the CRC).
const SCRATCHPAD_BITS: u8 = 72;

/// A command byte the device has just taken that the layer above may
/// shape: the model has done its part when [`Ds18b20Model::write_slot`]
/// returns it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// Search ROM: the search runs from ROM bit 0.
    SearchRom,
    /// Convert T: the device is idle until the layer calls
    /// [`Ds18b20Model::start_conversion`] (a device that misses the
    /// command never does).
    ConvertT,
    /// Read Scratchpad: [`Ds18b20Model::sending_mut`] holds the nine bytes
    /// about to be sent.
    ReadScratchpad,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Deselected or done: ignores slots until a reset.
    Idle,
    /// Collecting the 8 bits of a ROM command.
    RomCommand { byte: u8, n: u8 },
    /// Match ROM: comparing 64 address bits.
    MatchRom { n: u8 },
    /// Search ROM at `bit`: step 0 sends the bit, 1 its complement, 2
    /// takes the master's choice.
    Search { bit: u8, step: u8 },
    /// Read ROM: sending 64 bits.
    ReadRom { n: u8 },
    /// Collecting the 8 bits of a function command.
    Function { byte: u8, n: u8 },
    /// Read Scratchpad: sending bit `n` of the 72.
    Sending { n: u8 },
    /// Write Scratchpad: collecting TH, TL, configuration (24 bits).
    WriteScratchpad { n: u8 },
    /// After Convert T: read slots answer 0 until the conversion is done.
    Converting,
}

/// One DS18B20's protocol state.
#[derive(Clone, Debug)]
pub struct Ds18b20Model {
    pub rom: RomCode,
    /// The physical temperature, 1/16 °C: what the next conversion measures.
    pub temperature: i16,
    /// TH, TL, configuration in EEPROM: what a power-on reset loads into
    /// the scratchpad.
    pub eeprom: [u8; 3],
    /// Scratchpad reads completed (all 72 bits sent).
    pub scratchpad_reads: u64,
    /// Conversions started.
    pub conversions: u64,
    register: i16,
    th: u8,
    tl: u8,
    config: u8,
    /// The running conversion: when it ends, and the value it latches.
    conversion: Option<(u64, i16)>,
    phase: Phase,
    /// The scratchpad being sent.
    tx: [u8; 9],
    /// A ROM bit the running search sees inverted.
    search_flip: Option<u8>,
}

impl Ds18b20Model {
    /// A device at power-on: register 85.0 °C, factory EEPROM (12 bit).
    pub fn new(rom: RomCode, temperature: i16) -> Ds18b20Model {
        let [th, tl, config] = FACTORY_EEPROM;
        Ds18b20Model {
            rom,
            temperature,
            eeprom: FACTORY_EEPROM,
            scratchpad_reads: 0,
            conversions: 0,
            register: POWER_ON_RAW,
            th,
            tl,
            config,
            conversion: None,
            phase: Phase::Idle,
            tx: [0xFF; 9],
            search_flip: None,
        }
    }

    /// A DS18B20 ROM code (family 0x28) from a 48-bit serial, valid CRC.
    pub fn rom_for(serial: [u8; 6]) -> RomCode {
        RomCode::from_serial(ds18b20::FAMILY, serial)
    }

    pub fn resolution(&self) -> Resolution {
        Resolution::from_config(self.config)
    }

    /// What a brownout or a reconnection does: the temperature register
    /// back at 85.0 °C, TH/TL/configuration reloaded from EEPROM, any
    /// conversion and transaction lost.
    pub fn power_on_reset(&mut self) {
        self.register = POWER_ON_RAW;
        [self.th, self.tl, self.config] = self.eeprom;
        self.conversion = None;
        self.phase = Phase::Idle;
    }

    /// The scratchpad's TH, TL and configuration bytes.
    pub fn scratchpad_config(&self) -> [u8; 3] {
        [self.th, self.tl, self.config]
    }

    /// Overwrites the scratchpad's TH, TL and configuration bytes.
    pub fn set_scratchpad_config(&mut self, bytes: [u8; 3]) {
        [self.th, self.tl, self.config] = bytes;
    }

    /// The temperature register (what Read Scratchpad sends).
    pub fn register(&self) -> i16 {
        self.register
    }

    pub fn set_register(&mut self, raw: i16) {
        self.register = raw;
    }

    /// The nine bytes the power-on contents send: 85.0 °C, then TH, TL and
    /// configuration from EEPROM, and the CRC.
    pub fn power_on_scratchpad(&self) -> [u8; 9] {
        let [th, tl, config] = self.eeprom;
        ds18b20::encode(POWER_ON_RAW, th, tl, Resolution::from_config(config))
    }

    /// A reset pulse: a ROM command follows.
    pub fn reset_pulse(&mut self) {
        self.phase = Phase::RomCommand { byte: 0, n: 0 };
        self.search_flip = None;
    }

    /// Off the transaction until the next reset (deselected, disconnected).
    pub fn go_idle(&mut self) {
        self.phase = Phase::Idle;
    }

    pub fn is_idle(&self) -> bool {
        self.phase == Phase::Idle
    }

    /// The scratchpad bit about to be sent (0..72), while sending it.
    pub fn sending_bit(&self) -> Option<u8> {
        match self.phase {
            Phase::Sending { n } if n < SCRATCHPAD_BITS => Some(n),
            _ => None,
        }
    }

    /// The Match ROM bit about to be compared (0..64).
    pub fn matching_bit(&self) -> Option<u8> {
        match self.phase {
            Phase::MatchRom { n } => Some(n),
            _ => None,
        }
    }

    /// The ROM bit the running search is at (0..64).
    pub fn search_position(&self) -> Option<u8> {
        match self.phase {
            Phase::Search { bit, .. } => Some(bit),
            _ => None,
        }
    }

    /// The running search sees ROM bit `bit` inverted (until the next reset).
    pub fn invert_search_bit(&mut self, bit: u8) {
        self.search_flip = Some(bit);
    }

    /// The scratchpad bytes a Read Scratchpad is sending.
    pub fn sending_mut(&mut self) -> &mut [u8; 9] {
        &mut self.tx
    }

    /// When the running conversion ends.
    pub fn conversion_end(&self) -> Option<u64> {
        self.conversion.map(|(end, _)| end)
    }

    /// Convert T taken (after [`Command::ConvertT`]): measures
    /// [`Self::temperature`] at the configured resolution, done at `end`.
    pub fn start_conversion(&mut self, end: u64) {
        let value = self.temperature & self.resolution().raw_mask();
        self.conversion = Some((end, value));
        self.conversions += 1;
        self.phase = Phase::Converting;
    }

    /// The value of a conversion done by `now`, taken: the layer latches it
    /// ([`Self::set_register`]) or not (a stuck converter, a starved one).
    pub fn take_conversion(&mut self, now: u64) -> Option<i16> {
        match self.conversion {
            Some((end, value)) if now >= end => {
                self.conversion = None;
                Some(value)
            }
            _ => None,
        }
    }

    fn rom_bit(&self, i: u8) -> bool {
        bit_of(&self.rom.0, i)
    }

    /// ROM bit as this device takes part in the running search.
    fn search_bit(&self, i: u8) -> bool {
        self.rom_bit(i) ^ (self.search_flip == Some(i))
    }

    /// The bit this device sends in the next slot (`None`: it listens).
    pub fn tx_bit(&self, now: u64) -> Option<bool> {
        match self.phase {
            Phase::Search { bit, step: 0 } => Some(self.search_bit(bit)),
            Phase::Search { bit, step: 1 } => Some(!self.search_bit(bit)),
            Phase::ReadRom { n } => Some(self.rom_bit(n)),
            Phase::Sending { n } => Some(n >= SCRATCHPAD_BITS || bit_of(&self.tx, n)),
            Phase::Converting => Some(self.conversion.is_none_or(|(end, _)| now >= end)),
            _ => None,
        }
    }

    /// A slot in which this device sent ([`Self::tx_bit`] was `Some`) is over.
    pub fn read_slot(&mut self) {
        self.phase = match self.phase {
            Phase::Search { bit, step } => Phase::Search {
                bit,
                step: step + 1,
            },
            Phase::ReadRom { n } if n + 1 >= 64 => Phase::Function { byte: 0, n: 0 },
            Phase::ReadRom { n } => Phase::ReadRom { n: n + 1 },
            Phase::Sending { n } => {
                if n + 1 == SCRATCHPAD_BITS {
                    self.scratchpad_reads += 1;
                }
                Phase::Sending {
                    n: n.saturating_add(1).min(SCRATCHPAD_BITS),
                }
            }
            p => p,
        };
    }

    /// The master's bit in a slot in which this device listened; a command
    /// byte completed by it may come back for the layer above.
    pub fn write_slot(&mut self, bit: bool) -> Option<Command> {
        let mut command = None;
        self.phase = match self.phase {
            Phase::RomCommand { byte, n } => {
                let byte = byte | (u8::from(bit) << n);
                if n < 7 {
                    Phase::RomCommand { byte, n: n + 1 }
                } else {
                    match byte {
                        READ_ROM => Phase::ReadRom { n: 0 },
                        MATCH_ROM => Phase::MatchRom { n: 0 },
                        SKIP_ROM => Phase::Function { byte: 0, n: 0 },
                        SEARCH_ROM => {
                            command = Some(Command::SearchRom);
                            Phase::Search { bit: 0, step: 0 }
                        }
                        _ => Phase::Idle,
                    }
                }
            }
            Phase::MatchRom { n } => {
                if bit != self.rom_bit(n) {
                    Phase::Idle
                } else if n == 63 {
                    Phase::Function { byte: 0, n: 0 }
                } else {
                    Phase::MatchRom { n: n + 1 }
                }
            }
            Phase::Search { bit: b, step: 2 } => {
                if bit != self.search_bit(b) {
                    Phase::Idle
                } else if b == 63 {
                    Phase::Function { byte: 0, n: 0 }
                } else {
                    Phase::Search {
                        bit: b + 1,
                        step: 0,
                    }
                }
            }
            Phase::Function { byte, n } => {
                let byte = byte | (u8::from(bit) << n);
                if n < 7 {
                    Phase::Function { byte, n: n + 1 }
                } else {
                    self.function(byte, &mut command)
                }
            }
            Phase::WriteScratchpad { n } => {
                let target = match n / 8 {
                    0 => &mut self.th,
                    1 => &mut self.tl,
                    _ => &mut self.config,
                };
                if n % 8 == 0 {
                    *target = 0;
                }
                *target |= u8::from(bit) << (n % 8);
                if n == 23 {
                    // Only the resolution bits are writable; the rest read 1
                    // (bit 7 reads 0).
                    self.config = (self.config & 0x60) | 0x1F;
                    Phase::Idle
                } else {
                    Phase::WriteScratchpad { n: n + 1 }
                }
            }
            p => p,
        };
        command
    }

    fn function(&mut self, byte: u8, command: &mut Option<Command>) -> Phase {
        match byte {
            ds18b20::CONVERT_T => {
                *command = Some(Command::ConvertT);
                Phase::Idle
            }
            ds18b20::READ_SCRATCHPAD => {
                self.tx = ds18b20::encode(self.register, self.th, self.tl, self.resolution());
                *command = Some(Command::ReadScratchpad);
                Phase::Sending { n: 0 }
            }
            ds18b20::WRITE_SCRATCHPAD => Phase::WriteScratchpad { n: 0 },
            _ => Phase::Idle,
        }
    }
}

/// Bit `i` of `bytes`, least significant bit of byte 0 first (the wire's
/// order); 0 past the end.
fn bit_of(bytes: &[u8], i: u8) -> bool {
    bytes
        .get(usize::from(i / 8))
        .is_some_and(|b| b & (1 << (i % 8)) != 0)
}

//! One emulated DS18B20.

use super::time::{MS, US};
use thermocomp::acquisition::ds18b20::{self, Resolution, POWER_ON_RAW};
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

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Deselected or idle: ignores slots until a reset.
    Idle,
    RomCommand {
        byte: u8,
        n: u8,
    },
    MatchRom {
        n: u8,
    },
    Search {
        bit: u8,
        step: u8,
    },
    ReadRom {
        n: u8,
    },
    Function {
        byte: u8,
        n: u8,
    },
    /// Sending bits of `tx` (Read Scratchpad).
    Sending {
        n: u8,
    },
    WriteScratchpad {
        n: u8,
    },
    /// After Convert T: read slots return 0 while converting.
    Converting,
}

/// A DS18B20 on the emulated line.
#[derive(Clone, Debug)]
pub struct Ds18b20 {
    pub rom: RomCode,
    /// The physical temperature, 1/16 °C (what the next conversion measures).
    pub temperature: i16,
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
    register: i16,
    th: u8,
    tl: u8,
    config: u8,
    /// TH, TL, configuration in EEPROM: what a power-on reset loads into
    /// the scratchpad (factory values 0x4B, 0x46, 12 bit).
    pub eeprom: [u8; 3],
    conversion: Option<(u64, i16)>,
    phase: Phase,
    tx: [u8; 9],
    pulldown: Option<(u64, u64)>,
    /// Reads of the scratchpad completed (for tests).
    pub scratchpad_reads: u64,
    pub conversions: u64,
    /// Reset pulses seen (connected or not), for [`Fault::FlappingResets`].
    resets_seen: u64,
    /// Disconnected since the last reset ([`Fault::FlappingResets`]).
    detached: bool,
    /// The running search sees [`SEARCH_CORRUPT_BIT`] inverted.
    search_flip: bool,
    /// The running search loses this device at [`SEARCH_DROPOUT_BIT`].
    search_drop: bool,
}

impl Ds18b20 {
    /// A device at power-on: register 85.0 °C, 12-bit.
    pub fn new(rom: RomCode, temperature: i16) -> Ds18b20 {
        Ds18b20 {
            rom,
            temperature,
            conversion_scale_permille: 1000,
            fault: Fault::None,
            parasite: false,
            strong_since: None,
            starved: false,
            register: POWER_ON_RAW,
            th: 0x4B,
            tl: 0x46,
            config: 0x7F,
            eeprom: [0x4B, 0x46, 0x7F],
            conversion: None,
            phase: Phase::Idle,
            tx: [0xFF; 9],
            pulldown: None,
            scratchpad_reads: 0,
            conversions: 0,
            resets_seen: 0,
            detached: false,
            search_flip: false,
            search_drop: false,
        }
    }

    /// A DS18B20 ROM code (family 0x28) from a serial number, valid CRC.
    pub fn rom_for(serial: u64) -> RomCode {
        let s = serial.to_le_bytes();
        RomCode::from_serial(ds18b20::FAMILY, [s[0], s[1], s[2], s[3], s[4], s[5]])
    }

    pub fn resolution(&self) -> Resolution {
        Resolution::from_config(self.config)
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
        self.register = POWER_ON_RAW;
        let [th, tl, config] = self.eeprom;
        self.th = th;
        self.tl = tl;
        self.config = config;
        self.conversion = None;
        self.starved = false;
        self.phase = Phase::Idle;
        self.pulldown = None;
    }

    /// The scratchpad's TH, TL and configuration bytes.
    pub fn scratchpad_config(&self) -> [u8; 3] {
        [self.th, self.tl, self.config]
    }

    /// Overwrites the scratchpad's TH, TL and configuration bytes (a bit
    /// upset the CRC cannot see: the device computes the CRC over it).
    pub fn set_scratchpad_config(&mut self, bytes: [u8; 3]) {
        [self.th, self.tl, self.config] = bytes;
    }

    /// The temperature register (what Read Scratchpad sends).
    pub fn register(&self) -> i16 {
        self.register
    }

    fn settle(&mut self, now: u64) {
        if let Some((end, value)) = self.conversion {
            if now >= end {
                if self.parasite && self.starved {
                    // The supply collapsed: a full power-on reset.
                    self.power_on_reset();
                    return;
                } else if self.fault != Fault::Stuck {
                    self.register = value;
                }
                self.conversion = None;
                self.starved = false;
            }
        }
    }

    /// The master switched the strong pull-up.
    pub(crate) fn on_strong_pullup(&mut self, now: u64, on: bool) {
        if on {
            self.strong_since = Some(now);
            if let Some((end, _)) = self.conversion {
                // Too late: more than 10 µs after Convert T started.
                let start = end.saturating_sub(self.conversion_ns());
                self.starved = now > start + 10 * US;
            }
        } else {
            self.settle(now);
            self.strong_since = None;
            if self.conversion.is_some() {
                self.starved = true;
            }
        }
    }

    fn conversion_ns(&self) -> u64 {
        let t = u64::from(self.resolution().conversion_time_us()) * US;
        t * u64::from(self.conversion_scale_permille) / 1000
    }

    fn rom_bit(&self, i: u8) -> bool {
        self.rom.0[usize::from(i / 8)] & (1 << (i % 8)) != 0
    }

    /// ROM bit as this device takes part in the running search.
    fn search_bit(&self, i: u8) -> bool {
        self.rom_bit(i) ^ (self.search_flip && i == SEARCH_CORRUPT_BIT)
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

    /// The scratchpad bit about to be sent, while sending (line events).
    pub(crate) fn sending_bit(&self) -> Option<u8> {
        match self.phase {
            Phase::Sending { n } if n < 72 => Some(n),
            _ => None,
        }
    }

    /// The Match ROM bit about to be received (line events).
    pub(crate) fn matching_bit(&self) -> Option<u8> {
        match self.phase {
            Phase::MatchRom { n } => Some(n),
            _ => None,
        }
    }

    /// The bit this device sends in the current slot, if it is sending.
    fn tx_bit(&self, now: u64) -> Option<bool> {
        match self.phase {
            Phase::Search { bit, step: 0 } => Some(self.search_bit(bit)),
            Phase::Search { bit, step: 1 } => Some(!self.search_bit(bit)),
            Phase::ReadRom { n } => Some(self.rom_bit(n)),
            Phase::Sending { n } => {
                if n >= 72 || matches!(self.fault, Fault::CutRead { bits } if n >= bits) {
                    Some(true)
                } else if self.fault == Fault::AllZero {
                    Some(false)
                } else {
                    Some(self.tx[usize::from(n / 8)] & (1 << (n % 8)) != 0)
                }
            }
            Phase::Converting => Some(match self.conversion {
                Some((end, _)) => now >= end,
                None => true,
            }),
            _ => None,
        }
    }

    pub(crate) fn pulls_low(&self, now: u64) -> bool {
        matches!(self.pulldown, Some((a, b)) if now >= a && now <= b)
    }

    pub(crate) fn on_fall(&mut self, now: u64) {
        self.settle(now);
        if self.parasite && self.conversion.is_some() {
            // Line pulled low mid-conversion: no supply.
            self.starved = true;
        }
        self.pulldown = None;
        if self.silent(now) {
            return;
        }
        if matches!(self.phase, Phase::Search { bit, .. } if self.search_drop && bit >= SEARCH_DROPOUT_BIT)
        {
            self.phase = Phase::Idle;
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
            self.phase = Phase::Idle;
            return false;
        }
        if low_ns >= 480 * US {
            self.phase = Phase::RomCommand { byte: 0, n: 0 };
            self.search_flip = false;
            self.search_drop = false;
            if self.fault != Fault::NoPresencePulse {
                self.pulldown = Some((now + 30 * US, now + 150 * US));
            }
            return false;
        }
        let sending = self.tx_bit(now).is_some();
        if sending {
            // The pull-down scheduled at the fall lasts its 15 µs.
            self.advance_tx();
            return false;
        }
        // Receive: the device samples 30 µs after the fall.
        let ambiguous = low_ns > 15 * US && !(60 * US..=120 * US).contains(&low_ns);
        let bit = low_ns <= 30 * US;
        if !matches!(self.phase, Phase::Idle) {
            self.receive(bit, now);
            return ambiguous;
        }
        false
    }

    fn advance_tx(&mut self) {
        self.phase = match self.phase {
            Phase::Search { bit, step } => Phase::Search {
                bit,
                step: step + 1,
            },
            Phase::ReadRom { n } if n + 1 >= 64 => Phase::Function { byte: 0, n: 0 },
            Phase::ReadRom { n } => Phase::ReadRom { n: n + 1 },
            Phase::Sending { n } => {
                if n + 1 == 72 {
                    self.scratchpad_reads += 1;
                }
                Phase::Sending {
                    n: n.saturating_add(1).min(72),
                }
            }
            p => p,
        };
    }

    fn receive(&mut self, bit: bool, now: u64) {
        self.phase = match self.phase {
            Phase::RomCommand { byte, n } => {
                let byte = byte | (u8::from(bit) << n);
                if n < 7 {
                    Phase::RomCommand { byte, n: n + 1 }
                } else {
                    match byte {
                        0x33 => Phase::ReadRom { n: 0 },
                        0x55 => Phase::MatchRom { n: 0 },
                        0xCC => Phase::Function { byte: 0, n: 0 },
                        0xF0 => {
                            self.start_search();
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
                    self.function(byte, now)
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
                    self.config = (self.config & 0x60) | 0x1F;
                    Phase::Idle
                } else {
                    Phase::WriteScratchpad { n: n + 1 }
                }
            }
            p => p,
        };
    }

    /// A Search ROM begins: a pending search fault takes effect for it.
    fn start_search(&mut self) {
        match self.fault {
            Fault::SearchCorrupt(n) if n > 0 => {
                self.search_flip = true;
                self.fault = Fault::SearchCorrupt(n - 1);
            }
            Fault::SearchDropout(n) if n > 0 => {
                self.search_drop = true;
                self.fault = Fault::SearchDropout(n - 1);
            }
            _ => {}
        }
    }

    fn function(&mut self, command: u8, now: u64) -> Phase {
        match command {
            ds18b20::CONVERT_T => {
                if self.fault == Fault::PowerOn {
                    return Phase::Idle;
                }
                if let Fault::MissConvert(n) = self.fault {
                    self.fault = if n > 1 {
                        Fault::MissConvert(n - 1)
                    } else {
                        Fault::None
                    };
                    return Phase::Idle;
                }
                let res = self.resolution();
                let t = self.conversion_ns();
                let value = self.temperature & res.raw_mask();
                self.conversion = Some((now + t, value));
                // Parasite: starved unless the strong pull-up comes in time.
                self.starved = self.parasite;
                self.conversions += 1;
                Phase::Converting
            }
            ds18b20::READ_SCRATCHPAD => {
                let res = self.resolution();
                self.tx = ds18b20::encode(self.register, self.th, self.tl, res);
                if self.fault == Fault::PowerOn {
                    // Power-on contents: 50 05, then TH TL config from EEPROM.
                    let [th, tl, config] = self.eeprom;
                    self.tx =
                        ds18b20::encode(POWER_ON_RAW, th, tl, Resolution::from_config(config));
                }
                if let Fault::CorruptScratchpad(n) = self.fault {
                    if n > 0 {
                        self.tx[1] ^= 0x10;
                        if n != u32::MAX {
                            self.fault = Fault::CorruptScratchpad(n - 1);
                        }
                    }
                }
                Phase::Sending { n: 0 }
            }
            ds18b20::WRITE_SCRATCHPAD => Phase::WriteScratchpad { n: 0 },
            _ => Phase::Idle,
        }
    }

    /// Milliseconds left in a running conversion (for tests).
    pub fn converting_ms(&self, now_ns: u64) -> u64 {
        self.conversion
            .map_or(0, |(end, _)| end.saturating_sub(now_ns) / MS)
    }
}

//! The bench board's DS18B20s: a slot-level 1-Wire bus with emulated devices,
//! so the application's real acquisition code (ROM search, Match ROM, CRC and
//! fault checks, hold and recovery) runs on the bench board too. The
//! temperatures come from the replayed trace. Slot timing is not modelled here
//! (QEMU has no pins); that is the pin-level emulator's job in host-tests.
//! Conversions complete at the first poll, so one bench cycle takes
//! milliseconds instead of 750 ms.
//!
//! Hand-written: no crate emulates 1-Wire devices on a no_std target.

use thermocomp::acquisition::ds18b20::{self, Resolution};
use thermocomp::acquisition::rom::{RomCode, MATCH_ROM, READ_ROM, SEARCH_ROM, SKIP_ROM};
use thermocomp::hal::onewire::{BusError, OneWireBus};
use thermocomp_core::crc::crc8_maxim;
use thermocomp_protocol::MAX_CHANNELS;

struct Device {
    rom: RomCode,
    /// Temperature the next conversion latches, 1/16 °C; None = the sensor
    /// is absent from the bus (the trace has no value for it).
    present: bool,
    next_raw: i16,
    /// Latched scratchpad temperature (85 °C power-on value until converted).
    latched_raw: i16,
    config: u8,
    th: u8,
    tl: u8,
    selected: bool,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// After a reset: collecting the 8 bits of a ROM command.
    RomCommand,
    /// Match ROM: collecting 64 address bits.
    Match(u8),
    /// Search ROM at bit `n`: step 0 = send bit, 1 = send complement, 2 = take the master's bit.
    Search(u8, u8),
    /// Read ROM: sending 64 bits.
    ReadRom(u8),
    /// Collecting the 8 bits of a function command.
    Function,
    /// Sending the 72 scratchpad bits.
    ReadScratchpad(u8),
    /// Collecting TH, TL, config (24 bits).
    WriteScratchpad(u8),
    /// Converting: read slots answer 1 (done).
    Converting,
    /// Nothing more until the next reset.
    Idle,
}

pub struct EmulatedBus {
    devices: heapless::Vec<Device, MAX_CHANNELS>,
    phase: Phase,
    shift: u32,
    bits: u8,
    /// Bits of the master's write collected for the current Write Scratchpad.
    write_buf: u32,
}

impl EmulatedBus {
    /// `count` DS18B20s with serials 1..=count (valid ROM CRCs).
    pub fn new(count: usize) -> EmulatedBus {
        let mut devices = heapless::Vec::new();
        for i in 0..count.min(MAX_CHANNELS) {
            let serial = [i as u8 + 1, 0x5A, 0x17, 0x0C, 0x00, 0x00];
            let _ = devices.push(Device {
                rom: RomCode::from_serial(ds18b20::FAMILY, serial),
                present: true,
                next_raw: ds18b20::POWER_ON_RAW,
                latched_raw: ds18b20::POWER_ON_RAW,
                config: Resolution::Bits12.config_byte(),
                th: 0x4B,
                tl: 0x46,
                selected: false,
            });
        }
        EmulatedBus {
            devices,
            phase: Phase::Idle,
            shift: 0,
            bits: 0,
            write_buf: 0,
        }
    }

    pub fn rom(&self, index: usize) -> Option<RomCode> {
        self.devices.get(index).map(|d| d.rom)
    }

    /// Replace device `index` by a new DS18B20 (another ROM code, power-on
    /// scratchpad): what a technician swapping a sensor does.
    pub fn replace(&mut self, index: usize) {
        if let Some(d) = self.devices.get_mut(index) {
            let serial = [index as u8 + 1, 0xA5, 0x17, 0x0C, 0x00, 0x01];
            d.rom = RomCode::from_serial(ds18b20::FAMILY, serial);
            d.next_raw = ds18b20::POWER_ON_RAW;
            d.latched_raw = ds18b20::POWER_ON_RAW;
            d.config = Resolution::Bits12.config_byte();
            d.th = 0x4B;
            d.tl = 0x46;
        }
    }

    /// Set what device `index` will measure at the next Convert T; `None`
    /// takes it off the bus (no presence, reads float high).
    pub fn set_temperature(&mut self, index: usize, raw: Option<i16>) {
        if let Some(d) = self.devices.get_mut(index) {
            d.present = raw.is_some();
            if let Some(r) = raw {
                d.next_raw = r;
            }
        }
    }

    fn selected(&mut self) -> impl Iterator<Item = &mut Device> {
        self.devices.iter_mut().filter(|d| d.present && d.selected)
    }

    fn scratchpad(d: &Device) -> [u8; 9] {
        let t = d.latched_raw.to_le_bytes();
        let mut s = [t[0], t[1], d.th, d.tl, d.config, 0xFF, 0x0C, 0x10, 0];
        s[8] = crc8_maxim(&s[..8]);
        s
    }

    fn start_function(&mut self, cmd: u8) {
        self.phase = match cmd {
            ds18b20::CONVERT_T => {
                for d in self.devices.iter_mut().filter(|d| d.present && d.selected) {
                    d.latched_raw = d.next_raw;
                }
                Phase::Converting
            }
            ds18b20::READ_SCRATCHPAD => Phase::ReadScratchpad(0),
            ds18b20::WRITE_SCRATCHPAD => {
                self.write_buf = 0;
                Phase::WriteScratchpad(0)
            }
            _ => Phase::Idle,
        };
    }
}

impl OneWireBus for EmulatedBus {
    async fn reset(&mut self) -> Result<bool, BusError> {
        let mut any = false;
        for d in self.devices.iter_mut() {
            d.selected = d.present;
            any |= d.present;
        }
        self.phase = Phase::RomCommand;
        self.shift = 0;
        self.bits = 0;
        Ok(any)
    }

    async fn write_bit(&mut self, bit: bool) -> Result<(), BusError> {
        match self.phase {
            Phase::RomCommand | Phase::Function => {
                self.shift |= u32::from(bit) << self.bits;
                self.bits += 1;
                if self.bits == 8 {
                    let cmd = self.shift as u8;
                    self.shift = 0;
                    self.bits = 0;
                    if self.phase == Phase::Function {
                        self.start_function(cmd);
                    } else {
                        self.phase = match cmd {
                            SKIP_ROM => Phase::Function,
                            MATCH_ROM => Phase::Match(0),
                            SEARCH_ROM => Phase::Search(0, 0),
                            READ_ROM => Phase::ReadRom(0),
                            _ => Phase::Idle,
                        };
                    }
                }
            }
            Phase::Match(n) => {
                for d in self.selected() {
                    if rom_bit(&d.rom, n) != bit {
                        d.selected = false;
                    }
                }
                self.phase = if n == 63 {
                    Phase::Function
                } else {
                    Phase::Match(n + 1)
                };
            }
            Phase::Search(n, 2) => {
                for d in self.selected() {
                    if rom_bit(&d.rom, n) != bit {
                        d.selected = false;
                    }
                }
                self.phase = if n == 63 {
                    Phase::Function
                } else {
                    Phase::Search(n + 1, 0)
                };
            }
            Phase::WriteScratchpad(n) => {
                self.write_buf |= u32::from(bit) << n;
                if n == 23 {
                    let [th, tl, config, _] = self.write_buf.to_le_bytes();
                    for d in self.selected() {
                        d.th = th;
                        d.tl = tl;
                        d.config = config;
                    }
                    self.phase = Phase::Idle;
                } else {
                    self.phase = Phase::WriteScratchpad(n + 1);
                }
            }
            _ => {}
        }
        Ok(())
    }

    async fn read_bit(&mut self) -> Result<bool, BusError> {
        // Wired-AND: the line reads 0 when any selected device pulls it low.
        let mut line = true;
        match self.phase {
            Phase::Search(n, step @ (0 | 1)) => {
                for d in self.selected() {
                    let b = rom_bit(&d.rom, n);
                    line &= if step == 0 { b } else { !b };
                }
                self.phase = Phase::Search(n, step + 1);
            }
            Phase::ReadRom(n) => {
                for d in self.selected() {
                    line &= rom_bit(&d.rom, n);
                }
                self.phase = if n == 63 {
                    Phase::Function
                } else {
                    Phase::ReadRom(n + 1)
                };
            }
            Phase::ReadScratchpad(n) => {
                for d in self.selected() {
                    let s = EmulatedBus::scratchpad(d);
                    line &= s[usize::from(n / 8)] & (1 << (n % 8)) != 0;
                }
                self.phase = if n == 71 {
                    Phase::Idle
                } else {
                    Phase::ReadScratchpad(n + 1)
                };
            }
            // Conversion done at the first poll; other slots read the pull-up.
            _ => {}
        }
        Ok(line)
    }
}

fn rom_bit(rom: &RomCode, n: u8) -> bool {
    rom.0[usize::from(n / 8)] & (1 << (n % 8)) != 0
}

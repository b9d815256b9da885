//! The bench board's DS18B20s: a slot-level 1-Wire bus with emulated devices,
//! so the application's real acquisition code (ROM search, Match ROM, CRC and
//! fault checks, hold and recovery) runs on the bench board too. The
//! temperatures come from the replayed trace. Each device is the one
//! DS18B20 model the host's pin-level emulator runs too ([`ds18b20_model`]);
//! this bus only adds the wired-AND of a slot. Slot timing is not modelled
//! here (QEMU has no pins); that is the pin-level emulator's job in
//! host-tests. Conversions complete at once, so one bench cycle takes
//! milliseconds instead of 750 ms.

use ds18b20_model::{Command, Ds18b20Model};
use thermocomp::acquisition::ds18b20;
use thermocomp::acquisition::rom::RomCode;
use thermocomp::hal::onewire::{BusError, OneWireBus};
use thermocomp_protocol::MAX_CHANNELS;

/// Model time on this bus: always 0, and conversions last 0.
const NOW: u64 = 0;

struct Device {
    model: Ds18b20Model,
    /// On the bus (the trace has a value for it); an absent device sees no
    /// slot and drives nothing.
    present: bool,
}

pub struct EmulatedBus {
    devices: heapless::Vec<Device, MAX_CHANNELS>,
}

impl EmulatedBus {
    /// `count` DS18B20s with serials 1..=count (valid ROM CRCs).
    pub fn new(count: usize) -> EmulatedBus {
        let mut devices = heapless::Vec::new();
        for i in 0..count.min(MAX_CHANNELS) {
            let rom = Ds18b20Model::rom_for([i as u8 + 1, 0x5A, 0x17, 0x0C, 0x00, 0x00]);
            let _ = devices.push(Device {
                model: Ds18b20Model::new(rom, ds18b20::POWER_ON_RAW),
                present: true,
            });
        }
        EmulatedBus { devices }
    }

    pub fn rom(&self, index: usize) -> Option<RomCode> {
        self.devices.get(index).map(|d| d.model.rom)
    }

    /// Replace device `index` by a new DS18B20 (another ROM code, power-on
    /// scratchpad): what a technician swapping a sensor does.
    pub fn replace(&mut self, index: usize) {
        if let Some(d) = self.devices.get_mut(index) {
            let rom = Ds18b20Model::rom_for([index as u8 + 1, 0xA5, 0x17, 0x0C, 0x00, 0x01]);
            d.model = Ds18b20Model::new(rom, ds18b20::POWER_ON_RAW);
        }
    }

    /// Set what device `index` will measure at the next Convert T; `None`
    /// takes it off the bus (no presence, reads float high).
    pub fn set_temperature(&mut self, index: usize, raw: Option<i16>) {
        if let Some(d) = self.devices.get_mut(index) {
            d.present = raw.is_some();
            if let Some(r) = raw {
                d.model.temperature = r;
            }
        }
    }

    /// One slot: the master writes `bit` (a read slot writes 1), every
    /// present device sends or listens; the line is their wired-AND.
    fn slot(&mut self, bit: bool) -> bool {
        let mut line = bit;
        for d in self.devices.iter_mut().filter(|d| d.present) {
            let m = &mut d.model;
            match m.tx_bit(NOW) {
                Some(sent) => {
                    line &= sent;
                    m.read_slot();
                }
                None => {
                    if m.write_slot(bit) == Some(Command::ConvertT) {
                        m.start_conversion(NOW);
                        if let Some(value) = m.take_conversion(NOW) {
                            m.set_register(value);
                        }
                    }
                }
            }
        }
        line
    }
}

impl OneWireBus for EmulatedBus {
    async fn reset(&mut self) -> Result<bool, BusError> {
        let mut any = false;
        for d in self.devices.iter_mut() {
            if d.present {
                d.model.reset_pulse();
                any = true;
            } else {
                d.model.go_idle();
            }
        }
        Ok(any)
    }

    async fn write_bit(&mut self, bit: bool) -> Result<(), BusError> {
        self.slot(bit);
        Ok(())
    }

    async fn read_bit(&mut self) -> Result<bool, BusError> {
        Ok(self.slot(true))
    }
}

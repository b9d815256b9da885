//! 64-bit ROM codes and the ROM search (Maxim application note 187).

use crate::hal::onewire::{BusError, OneWireBus};
use thermocomp_core::crc::crc8_maxim;

/// Search ROM.
pub const SEARCH_ROM: u8 = 0xF0;
/// Match ROM: the next 64 bits select one device.
pub const MATCH_ROM: u8 = 0x55;
/// Skip ROM: the next function command goes to every device.
pub const SKIP_ROM: u8 = 0xCC;
/// Read ROM (one device on the bus only).
pub const READ_ROM: u8 = 0x33;

/// A device's 64-bit ROM code: family code, 48-bit serial, CRC-8, in bus
/// order (byte 0 is sent first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RomCode(pub [u8; 8]);

impl RomCode {
    /// A ROM code whose CRC byte matches and which is not all zero (zeros
    /// pass the CRC but are what a shorted line reads).
    pub fn is_valid(&self) -> bool {
        self.0 != [0; 8] && crc8_maxim(&self.0) == 0
    }

    /// The family code (0x28 for DS18B20).
    pub fn family(&self) -> u8 {
        self.0[0]
    }

    /// Builds a ROM code with a valid CRC from a family code and serial.
    pub const fn from_serial(family: u8, serial: [u8; 6]) -> RomCode {
        let [s0, s1, s2, s3, s4, s5] = serial;
        let crc = crc8_maxim(&[family, s0, s1, s2, s3, s4, s5]);
        RomCode([family, s0, s1, s2, s3, s4, s5, crc])
    }

    /// Bit `i` (0..64) in bus order.
    fn bit(&self, i: usize) -> bool {
        match self.0.get(i / 8) {
            Some(byte) => byte & (1 << (i % 8)) != 0,
            None => false,
        }
    }

    fn set_bit(&mut self, i: usize, v: bool) {
        if let Some(byte) = self.0.get_mut(i / 8) {
            if v {
                *byte |= 1 << (i % 8);
            } else {
                *byte &= !(1 << (i % 8));
            }
        }
    }
}

/// Why a search did not complete.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SearchError {
    /// No presence pulse: nothing on the bus.
    NoPresence,
    /// Both a bit and its complement read 1: the devices left mid-search.
    NoResponse,
    /// A discovered ROM code failed its CRC (noise on the line).
    Crc,
    /// More devices than the output holds.
    TooMany,
    /// Bus failure.
    Bus(BusError),
}

impl From<BusError> for SearchError {
    fn from(e: BusError) -> Self {
        SearchError::Bus(e)
    }
}

/// Finds every device on the bus, in search order, into `out` (cleared first).
/// Returns the number found. Bounded: at most `N` passes of 64 bits.
pub async fn search<B: OneWireBus, const N: usize>(
    bus: &mut B,
    out: &mut heapless::Vec<RomCode, N>,
) -> Result<usize, SearchError> {
    out.clear();
    let mut rom = RomCode([0; 8]);
    // 1-based bit index of the last branch where 0 was taken; 0 = none.
    let mut last_discrepancy = 0usize;
    loop {
        if !bus.reset().await? {
            return Err(SearchError::NoPresence);
        }
        bus.write_byte(SEARCH_ROM).await?;
        let mut last_zero = 0usize;
        for n in 1..=64usize {
            let id_bit = bus.read_bit().await?;
            let cmp_bit = bus.read_bit().await?;
            let dir = match (id_bit, cmp_bit) {
                (true, true) => return Err(SearchError::NoResponse),
                (a, b) if a != b => a,
                _ => {
                    let d = if n < last_discrepancy {
                        rom.bit(n - 1)
                    } else {
                        n == last_discrepancy
                    };
                    if !d {
                        last_zero = n;
                    }
                    d
                }
            };
            rom.set_bit(n - 1, dir);
            bus.write_bit(dir).await?;
            if n % 8 == 0 {
                // ~1.5 ms of slots per 8 bits: let other tasks run.
                super::bitbang::yield_now().await;
            }
        }
        if !rom.is_valid() {
            return Err(SearchError::Crc);
        }
        out.push(rom).map_err(|_| SearchError::TooMany)?;
        last_discrepancy = last_zero;
        if last_discrepancy == 0 {
            return Ok(out.len());
        }
    }
}

/// Reset + Match ROM: selects one device. `Ok(false)` if nothing answered
/// the reset.
pub async fn select<B: OneWireBus>(bus: &mut B, rom: &RomCode) -> Result<bool, BusError> {
    if !bus.reset().await? {
        return Ok(false);
    }
    bus.write_byte(MATCH_ROM).await?;
    for b in rom.0 {
        bus.write_byte(b).await?;
    }
    Ok(true)
}

/// Reset + Skip ROM: addresses every device. `Ok(false)` if nothing answered.
pub async fn select_all<B: OneWireBus>(bus: &mut B) -> Result<bool, BusError> {
    if !bus.reset().await? {
        return Ok(false);
    }
    bus.write_byte(SKIP_ROM).await?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_serial_gives_valid_rom() {
        let r = RomCode::from_serial(0x28, [1, 2, 3, 4, 5, 6]);
        assert!(r.is_valid());
        assert_eq!(r.family(), 0x28);
        assert!(!RomCode([0; 8]).is_valid());
    }
}

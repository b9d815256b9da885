//! DS18B20 function commands and scratchpad decoding.
//!
//! The temperature register is a signed 16-bit value in 1/16 °C at every
//! resolution; below 12 bits the lowest bits are undefined and are masked
//! here (not divided again, the `ds18b20` 0.1.1 defect).

use thermocomp_core::crc::crc8_maxim;
use thermocomp_protocol::states::ChannelState;

/// DS18B20 family code.
pub const FAMILY: u8 = 0x28;
/// Convert T.
pub const CONVERT_T: u8 = 0x44;
/// Read Scratchpad (9 bytes, the last is the CRC).
pub const READ_SCRATCHPAD: u8 = 0xBE;
/// Write Scratchpad (TH, TL, configuration).
pub const WRITE_SCRATCHPAD: u8 = 0x4E;
/// Raw value of the 85.0 °C power-on reset contents.
pub const POWER_ON_RAW: i16 = 0x0550;

/// Conversion resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Resolution {
    Bits9,
    Bits10,
    Bits11,
    Bits12,
}

impl Resolution {
    /// Bits 6..5 of the configuration register.
    pub const fn config_byte(self) -> u8 {
        (self.index() << 5) | 0x1F
    }

    const fn index(self) -> u8 {
        match self {
            Resolution::Bits9 => 0,
            Resolution::Bits10 => 1,
            Resolution::Bits11 => 2,
            Resolution::Bits12 => 3,
        }
    }

    /// From a configuration register value.
    pub const fn from_config(config: u8) -> Resolution {
        match (config >> 5) & 3 {
            0 => Resolution::Bits9,
            1 => Resolution::Bits10,
            2 => Resolution::Bits11,
            _ => Resolution::Bits12,
        }
    }

    /// Maximum conversion time from the datasheet (t_CONV), µs.
    pub const fn conversion_time_us(self) -> u32 {
        93_750 << self.index()
    }

    /// Mask of the defined bits of the temperature register.
    pub const fn raw_mask(self) -> i16 {
        !((1i16 << (3 - self.index())) - 1)
    }
}

/// A decoded, CRC-checked scratchpad.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scratchpad {
    /// Temperature, 1/16 °C, undefined low bits cleared.
    pub raw: i16,
    pub resolution: Resolution,
    /// Alarm bytes TH, TL: reloaded from EEPROM by a power-on reset, so the
    /// acquisition keeps its own marker in them (see
    /// [`super::temperature`]).
    pub th: u8,
    pub tl: u8,
}

impl Scratchpad {
    /// The temperature register holds the 85.0 °C power-on value. Whether it
    /// is that value or a genuine 85.0 °C reading only the scratchpad's
    /// history can tell (the acquisition decides).
    pub const fn reads_power_on_value(&self) -> bool {
        self.raw == POWER_ON_RAW
    }
}

/// Checks and decodes the nine scratchpad bytes. The order of the checks
/// matters: all-ones and all-zeros are named before the CRC (all zeros pass
/// it). 85.0 °C decodes as a value: it is also a real temperature.
pub fn decode(bytes: &[u8; 9]) -> Result<Scratchpad, ChannelState> {
    if bytes.iter().all(|&b| b == 0xFF) {
        return Err(ChannelState::Disconnected);
    }
    if bytes.iter().all(|&b| b == 0) {
        return Err(ChannelState::AllZero);
    }
    if crc8_maxim(bytes) != 0 {
        return Err(ChannelState::CrcError);
    }
    let resolution = Resolution::from_config(bytes[4]);
    let raw = i16::from_le_bytes([bytes[0], bytes[1]]) & resolution.raw_mask();
    Ok(Scratchpad {
        raw,
        resolution,
        th: bytes[2],
        tl: bytes[3],
    })
}

/// Encodes a scratchpad as a DS18B20 would send it (used by emulators).
pub fn encode(raw: i16, th: u8, tl: u8, resolution: Resolution) -> [u8; 9] {
    let t = raw.to_le_bytes();
    let mut b = [
        t[0],
        t[1],
        th,
        tl,
        resolution.config_byte(),
        0xFF,
        0x0C,
        0x10,
        0,
    ];
    let mut head = [0u8; 8];
    head.copy_from_slice(&b[..8]);
    b[8] = crc8_maxim(&head);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_and_low_resolution() {
        // −10.125 °C = 0xFF5E (datasheet table 1).
        let sp = encode(-162, 0x4B, 0x46, Resolution::Bits12);
        assert_eq!(sp[0], 0x5E);
        assert_eq!(sp[1], 0xFF);
        assert_eq!(decode(&sp).map(|s| s.raw), Ok(-162));
        // 23.5 °C at 9 bits: still 1/16 °C units.
        let sp = encode(376, 0x4B, 0x46, Resolution::Bits9);
        assert_eq!(decode(&sp).map(|s| s.raw), Ok(376));
        // undefined low bits masked
        let sp = encode(377, 0x4B, 0x46, Resolution::Bits9);
        assert_eq!(decode(&sp).map(|s| s.raw), Ok(376));
    }

    #[test]
    fn faults_named() {
        assert_eq!(decode(&[0; 9]), Err(ChannelState::AllZero));
        assert_eq!(decode(&[0xFF; 9]), Err(ChannelState::Disconnected));
        let mut sp = encode(400, 0, 0, Resolution::Bits12);
        sp[0] ^= 1;
        assert_eq!(decode(&sp), Err(ChannelState::CrcError));
        // Power-on contents: 50 05 4B 46 7F FF 0C 10 1C (datasheet).
        let sp = encode(POWER_ON_RAW, 0x4B, 0x46, Resolution::Bits12);
        assert_eq!(sp, [0x50, 0x05, 0x4B, 0x46, 0x7F, 0xFF, 0x0C, 0x10, 0x1C]);
        let decoded = decode(&sp).map(|s| (s.reads_power_on_value(), s.th, s.tl));
        assert_eq!(decoded, Ok((true, 0x4B, 0x46)));
    }

    #[test]
    fn conversion_times() {
        assert_eq!(Resolution::Bits12.conversion_time_us(), 750_000);
        assert_eq!(Resolution::Bits9.conversion_time_us(), 93_750);
    }
}

//! The checksums shared by the board and the desktop, from the `crc`
//! crate's catalogue (const tables, no_std): CRC-32/ISO-HDLC of model
//! images and stored records, and the Dallas/Maxim CRC-8 of 1-Wire ROM
//! codes, DS18B20 scratchpads and the stored channel map.

use crc::{Crc, CRC_32_ISO_HDLC, CRC_8_MAXIM_DOW};

const ISO_HDLC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
/// x⁸ + x⁵ + x⁴ + 1, reflected, init 0 (Maxim application note 27).
const DALLAS_MAXIM: Crc<u8> = Crc::<u8>::new(&CRC_8_MAXIM_DOW);

/// CRC-32 (the zip/Ethernet polynomial) of a byte string: the model
/// image's checksum, also shown over Modbus.
pub const fn crc32(bytes: &[u8]) -> u32 {
    ISO_HDLC.checksum(bytes)
}

/// Dallas/Maxim CRC-8 of `data`. A ROM code's eighth byte is the CRC-8 of
/// its first seven; a block followed by its CRC byte gives 0.
pub const fn crc8_maxim(data: &[u8]) -> u8 {
    DALLAS_MAXIM.checksum(data)
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::cast_possible_truncation)]
mod tests {
    use super::crc8_maxim;

    /// The shift-register form of AN27, bit by bit: the reference the
    /// catalogue entry is checked against.
    fn crc8_bitwise(data: &[u8]) -> u8 {
        let mut crc = 0u8;
        for &byte in data {
            let mut b = byte;
            for _ in 0..8 {
                let mix = (crc ^ b) & 1;
                crc >>= 1;
                if mix != 0 {
                    crc ^= 0x8C;
                }
                b >>= 1;
            }
        }
        crc
    }

    #[test]
    fn maxim_application_note_example() {
        // AN27 example ROM code: 02 1C B8 01 00 00 00 A2
        assert_eq!(
            crc8_maxim(&[0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00]),
            0xA2
        );
        assert_eq!(
            crc8_maxim(&[0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00, 0xA2]),
            0
        );
    }

    #[test]
    fn datasheet_power_on_scratchpad() {
        // DS18B20 power-on scratchpad (85 °C, TH 75, TL 70, 12 bit): CRC 0x1C
        // as real sensors report it.
        let head = [0x50, 0x05, 0x4B, 0x46, 0x7F, 0xFF, 0x0C, 0x10];
        assert_eq!(crc8_maxim(&head), 0x1C);
    }

    #[test]
    fn check_value_of_the_catalogue() {
        assert_eq!(crc8_maxim(b"123456789"), 0xA1);
    }

    #[test]
    fn zeros_pass_the_crc() {
        // The defect the all-zero check exists for.
        assert_eq!(crc8_maxim(&[0u8; 8]), 0);
    }

    #[test]
    fn the_catalogue_entry_is_the_an27_shift_register() {
        // Family 0x28 ROM codes (serial from an LCG) and scratchpads over the
        // DS18B20's whole range at every resolution, as the sensors send them.
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        for _ in 0..2000 {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            let mut rom = [0u8; 8];
            rom[0] = 0x28;
            rom[1..7].copy_from_slice(&x.to_le_bytes()[..6]);
            rom[7] = crc8_bitwise(&rom[..7]);
            assert_eq!(crc8_maxim(&rom[..7]), rom[7]);
            assert_eq!(crc8_maxim(&rom), 0);
        }
        for raw in (-55 * 16..=125 * 16).step_by(7) {
            for config in [0x1Fu8, 0x3F, 0x5F, 0x7F] {
                let [lsb, msb] = (raw as i16).to_le_bytes();
                let sp = [lsb, msb, 0x4B, 0x46, config, 0xFF, 0x0C, 0x10];
                assert_eq!(crc8_maxim(&sp), crc8_bitwise(&sp));
            }
        }
    }
}

//! Dallas/Maxim CRC-8 (polynomial x⁸ + x⁵ + x⁴ + 1, reflected, init 0), the
//! check of every 1-Wire ROM code and DS18B20 scratchpad, from the `crc`
//! crate's catalogue (`CRC_8_MAXIM_DOW`).

use crc::{Crc, CRC_8_MAXIM_DOW};

const DALLAS_MAXIM: Crc<u8> = Crc::<u8>::new(&CRC_8_MAXIM_DOW);

/// CRC-8 of `data`. A block followed by its CRC byte gives 0.
pub const fn crc8(data: &[u8]) -> u8 {
    DALLAS_MAXIM.checksum(data)
}

#[cfg(test)]
mod tests {
    use super::crc8;

    #[test]
    fn maxim_application_note_example() {
        // AN27 example ROM code: 02 1C B8 01 00 00 00 A2
        assert_eq!(crc8(&[0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00]), 0xA2);
        assert_eq!(crc8(&[0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00, 0xA2]), 0);
    }

    #[test]
    fn datasheet_power_on_scratchpad() {
        // DS18B20 power-on scratchpad (85 °C, TH 75, TL 70, 12 bit): CRC 0x1C
        // as real sensors report it.
        let head = [0x50, 0x05, 0x4B, 0x46, 0x7F, 0xFF, 0x0C, 0x10];
        assert_eq!(crc8(&head), 0x1C);
    }

    #[test]
    fn check_value_of_the_catalogue() {
        assert_eq!(crc8(b"123456789"), 0xA1);
    }

    #[test]
    fn zeros_pass_the_crc() {
        // The defect the all-zero check exists for.
        assert_eq!(crc8(&[0u8; 8]), 0);
    }
}

//! The checksums shared by the board and the desktop: CRC-32/ISO-HDLC of
//! model images and stored records, the Dallas/Maxim CRC-8 of 1-Wire ROM
//! codes, DS18B20 scratchpads and the stored channel map, and the
//! CRC-16/MODBUS of an RTU frame (`thermocomp_protocol::rtu::crc16`).
//!
//! All three are reflected CRCs, computed here four bits at a time from a
//! 16-entry table built at compile time: the same values as the `crc`
//! crate's catalogue entries (the tests compare them), with 16-entry tables
//! instead of 256-entry ones: 1.6 KB less flash on the board, at two table
//! steps per byte instead of one.

/// CRC-32/ISO-HDLC: reflected polynomial, initial value, final XOR.
const CRC32_POLY: u32 = 0xEDB8_8320;
/// x⁸ + x⁵ + x⁴ + 1, reflected, init 0 (Maxim application note 27).
const CRC8_MAXIM_POLY: u32 = 0x8C;
/// CRC-16/MODBUS: x¹⁶ + x¹⁵ + x² + 1 reflected, init 0xFFFF.
const CRC16_MODBUS_POLY: u32 = 0xA001;

const CRC32_TABLE: [u32; 16] = nibble_table(CRC32_POLY);
const CRC8_MAXIM_TABLE: [u32; 16] = nibble_table(CRC8_MAXIM_POLY);
const CRC16_MODBUS_TABLE: [u32; 16] = nibble_table(CRC16_MODBUS_POLY);

/// The register after shifting each 4-bit value through a reflected CRC of
/// polynomial `poly` (bit-reversed, any width ≤ 32).
const fn nibble_table(poly: u32) -> [u32; 16] {
    let mut table = [0u32; 16];
    let mut n = 0u32;
    while n < 16 {
        let mut c = n;
        let mut bit = 0;
        while bit < 4 {
            c = if c & 1 != 0 { (c >> 1) ^ poly } else { c >> 1 };
            bit += 1;
        }
        #[allow(clippy::indexing_slicing, reason = "n < 16 = the table's length")]
        {
            table[n as usize] = c;
        }
        n += 1;
    }
    table
}

/// A reflected CRC over `bytes` from register value `crc` (no final XOR):
/// each byte enters the low bits, then two 4-bit steps shift it through.
const fn reflected(table: &[u32; 16], mut crc: u32, mut bytes: &[u8]) -> u32 {
    while let [byte, rest @ ..] = bytes {
        crc ^= *byte as u32;
        #[allow(
            clippy::indexing_slicing,
            reason = "masked to 0..16, the table's length"
        )]
        {
            crc = (crc >> 4) ^ table[(crc & 0xF) as usize];
            crc = (crc >> 4) ^ table[(crc & 0xF) as usize];
        }
        bytes = rest;
    }
    crc
}

/// CRC-32 (the zip/Ethernet polynomial) of a byte string: the model
/// image's checksum, also shown over Modbus.
pub const fn crc32(bytes: &[u8]) -> u32 {
    !reflected(&CRC32_TABLE, !0, bytes)
}

/// Dallas/Maxim CRC-8 of `data`. A ROM code's eighth byte is the CRC-8 of
/// its first seven; a block followed by its CRC byte gives 0.
#[allow(
    clippy::cast_possible_truncation,
    reason = "an 8-bit CRC's register stays below 2^8"
)]
pub const fn crc8_maxim(data: &[u8]) -> u8 {
    reflected(&CRC8_MAXIM_TABLE, 0, data) as u8
}

/// CRC-16/MODBUS of `bytes` (sent low byte first).
#[allow(
    clippy::cast_possible_truncation,
    reason = "a 16-bit CRC's register stays below 2^16"
)]
pub const fn crc16_modbus(bytes: &[u8]) -> u16 {
    reflected(&CRC16_MODBUS_TABLE, 0xFFFF, bytes) as u16
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

    /// Every width against the `crc` crate's catalogue entry (256-entry
    /// tables), over lengths 0..300 of pseudo-random bytes and the check string.
    #[test]
    fn nibble_tables_give_the_catalogue_values() {
        use super::{crc16_modbus, crc32};
        let c32 = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let c16 = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);
        let c8 = crc::Crc::<u8>::new(&crc::CRC_8_MAXIM_DOW);
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc16_modbus(b"123456789"), 0x4B37);
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let bytes: std::vec::Vec<u8> = (0..300)
            .map(|_| {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                (x >> 56) as u8
            })
            .collect();
        for n in 0..=bytes.len() {
            let b = &bytes[..n];
            assert_eq!(crc32(b), c32.checksum(b), "crc32, {n} bytes");
            assert_eq!(crc16_modbus(b), c16.checksum(b), "crc16, {n} bytes");
            assert_eq!(crc8_maxim(b), c8.checksum(b), "crc8, {n} bytes");
        }
    }
}

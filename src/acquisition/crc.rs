//! Dallas/Maxim CRC-8 (polynomial x⁸ + x⁵ + x⁴ + 1, reflected 0x8C, init 0).

/// CRC-8 of `data`. A block followed by its CRC byte gives 0.
pub const fn crc8(data: &[u8]) -> u8 {
    let mut crc = 0u8;
    let mut i = 0;
    while i < data.len() {
        let mut byte = data[i];
        let mut b = 0;
        while b < 8 {
            let mix = (crc ^ byte) & 1;
            crc >>= 1;
            if mix != 0 {
                crc ^= 0x8C;
            }
            byte >>= 1;
            b += 1;
        }
        i += 1;
    }
    crc
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
    fn zeros_pass_the_crc() {
        // The defect the all-zero check exists for.
        assert_eq!(crc8(&[0u8; 8]), 0);
    }
}

//! Modbus RTU framing as the board speaks it: frame and request limits, the
//! CRC-16, and where a request ends.

/// Largest RTU frame (address + PDU 253 + CRC).
pub const MAX_FRAME: usize = 256;

/// Most registers one FC16 request may write (Modbus application protocol §6.12).
pub const MAX_WRITE_REGISTERS: usize = 123;

const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// CRC-16/MODBUS of `bytes` (sent low byte first).
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// Length of the RTU request that starts with `head`, once its first bytes
/// say it (FC 1–6: 8 bytes; FC 15/16: 9 + byte count); `None` while unknown
/// or for other function codes. Ports use it to end a frame as soon as it is
/// complete and fall back to the silent-gap rule otherwise.
pub fn expected_request_len(head: &[u8]) -> Option<usize> {
    match *head.get(1)? {
        0x01..=0x06 => Some(8),
        0x0F | 0x10 => head.get(6).map(|&n| 9 + usize::from(n)),
        _ => None,
    }
}

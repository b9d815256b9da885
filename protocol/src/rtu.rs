//! Modbus RTU framing as the board speaks it: frame and request limits, the
//! CRC-16, and where a request ends.

/// Largest RTU frame (address + PDU 253 + CRC).
pub const MAX_FRAME: usize = 256;

/// Most registers one FC16 request may write (Modbus application protocol §6.12).
pub const MAX_WRITE_REGISTERS: usize = 123;

/// CRC-16/MODBUS of `bytes` (sent low byte first): the core's, beside its
/// CRC-8 and CRC-32 (one small-table implementation for the three).
pub fn crc16(bytes: &[u8]) -> u16 {
    thermocomp_core::crc::crc16_modbus(bytes)
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

//! Any sequence of frames: the Modbus server answers within 256 bytes or stays
//! silent, never panics or stalls. The first byte picks a valid CRC or not.
#![no_main]
use libfuzzer_sys::fuzz_target;
use thermocomp::modbus::{Server, Snapshot};
use thermocomp::state::AppState;
use thermocomp_protocol::holding::HR_UNLOCK;
use thermocomp_protocol::rtu::{crc16, MAX_FRAME};

fuzz_target!(|data: &[u8]| {
    let mut server = Server::new();
    let mut state = AppState::new(1, 115_200);
    // A commissioned board with its own key.
    const KEY: u16 = 0x7E57;
    state.keys.unlock = Some(KEY);
    let snap = Snapshot::default();
    let mut reply: heapless::Vec<u8, MAX_FRAME> = heapless::Vec::new();
    // Unlocked, so protected writes and commits are reached too.
    let mut unlock = vec![1, 6, 0, HR_UNLOCK as u8, (KEY >> 8) as u8, KEY as u8];
    unlock.extend_from_slice(&crc16(&unlock).to_le_bytes());
    server.handle(&unlock, 0, &snap, &mut state, &mut reply);
    for (i, chunk) in data.split(|&b| b == 0xFE).enumerate() {
        let mut frame = chunk.to_vec();
        if frame.len() >= 4 && frame[frame.len() - 1] & 1 == 0 {
            let n = frame.len();
            let crc = crc16(&frame[..n - 2]);
            frame[n - 2..].copy_from_slice(&crc.to_le_bytes());
        }
        server.handle(&frame, i as u64, &snap, &mut state, &mut reply);
        assert!(reply.len() <= MAX_FRAME);
    }
});

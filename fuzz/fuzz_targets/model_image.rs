//! Any byte string: the image parser returns a model or a typed error, and a
//! model that parses evaluates and steps without overflow or panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use thermocomp_core::{Compensator, Model, StepInput};

fuzz_target!(|data: &[u8]| {
    // Half the inputs: re-seal the CRC so the parser's later checks are reached.
    let mut bytes = data.to_vec();
    if bytes.len() >= 36 && bytes[0] & 1 == 1 {
        bytes[0..4].copy_from_slice(b"TCMI");
        // Every format: v1, v2 with its typed sections after the tables, v3
        // with the envelope policy, v4 with its code 2 (extrapolate), v5
        // with the output filter (section kind 6).
        let version: u16 = 1 + u16::from((data[0] >> 1) % 5);
        bytes[4..6].copy_from_slice(&version.to_le_bytes());
        let n = bytes.len() as u32;
        bytes[8..12].copy_from_slice(&n.to_le_bytes());
        let crc = thermocomp_core::image::crc32(&bytes[..bytes.len() - 4]);
        let l = bytes.len();
        bytes[l - 4..].copy_from_slice(&crc.to_le_bytes());
    }
    if let Ok(model) = Model::parse(&bytes) {
        let n = model.sensors.len();
        let mut c = Compensator::new(Some(model));
        let temps = [Some(i32::from(i16::MAX)), Some(i32::from(i16::MIN)), None, Some(0)];
        for (k, now) in [0u64, 1, 15_000, u64::MAX / 2, u64::MAX].into_iter().enumerate() {
            let t: Vec<Option<i32>> = (0..n).map(|i| temps[(i + k) % 4]).collect();
            let _ = c.step(&StepInput { now_ms: now, temps: &t, spindle_rpm: i32::MAX, positions: &[i32::MIN, i32::MAX, 0, 0, 0, 0], stale: false });
        }
    }
});

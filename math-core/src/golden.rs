//! Golden vectors: a model image and a sequence of step inputs with the
//! outputs the host computed. The board replays them through its own build
//! of this crate and must reproduce every output bit for bit.
//!
//! File layout (little-endian): "TCGV", version u32 = 1, image_len u32,
//! image bytes, n_steps u32, n_sensors u8, n_axes u8, n_directions u8, 0,
//! then per step: now_ms u64, temps i32 × n_sensors (i32::MIN = invalid),
//! rpm i32, positions i32 × n_axes, stale u8, 3 × 0, expected status u16,
//! 2 × 0, corrections i32 × n_dir, predicted i32 × n_dir,
//! (offset i32, slope i32) × n_axes.

#[cfg(feature = "std")]
use crate::compensator::StepOutput;
use crate::compensator::{Compensator, StepInput};
use crate::image::{ImageError, Model};
use crate::limits::*;

pub const MAGIC: [u8; 4] = *b"TCGV";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoldenError {
    /// The file is not a golden-vector file or is cut short.
    Malformed,
    Image(ImageError),
    /// The output of step `step` differs from the host's.
    Mismatch {
        step: u32,
    },
}

struct Cursor<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], GoldenError> {
        let end = self.at.checked_add(n).ok_or(GoldenError::Malformed)?;
        let s = self.b.get(self.at..end).ok_or(GoldenError::Malformed)?;
        self.at = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], GoldenError> {
        <[u8; N]>::try_from(self.take(N)?).map_err(|_| GoldenError::Malformed)
    }
    fn u32(&mut self) -> Result<u32, GoldenError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn i32(&mut self) -> Result<i32, GoldenError> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    fn u64(&mut self) -> Result<u64, GoldenError> {
        Ok(u64::from(self.u32()?) | (u64::from(self.u32()?) << 32))
    }
}

/// Replay a golden file; Ok(number of steps) when every output matches.
pub fn check(bytes: &[u8]) -> Result<u32, GoldenError> {
    let mut c = Cursor { b: bytes, at: 0 };
    if c.take(4)? != MAGIC || c.u32()? != 1 {
        return Err(GoldenError::Malformed);
    }
    let image_len = c.u32()? as usize;
    let model = Model::parse(c.take(image_len)?).map_err(GoldenError::Image)?;
    let n_steps = c.u32()?;
    let [ns, na, nd, _] = c.array()?;
    let (ns, na, nd) = (usize::from(ns), usize::from(na), usize::from(nd));
    if ns > MAX_SENSORS || na > MAX_AXES || nd > MAX_DIRECTIONS {
        return Err(GoldenError::Malformed);
    }
    let mut comp = Compensator::new(Some(model));
    for step in 0..n_steps {
        let now_ms = c.u64()?;
        let mut temps = [None; MAX_SENSORS];
        for t in temps.iter_mut().take(ns) {
            let v = c.i32()?;
            *t = (v != i32::MIN).then_some(v);
        }
        let rpm = c.i32()?;
        let mut pos = [0i32; MAX_AXES];
        for p in pos.iter_mut().take(na) {
            *p = c.i32()?;
        }
        let [stale, _, _, _] = c.array()?;
        let out = comp.step(&StepInput {
            now_ms,
            temps: temps.get(..ns).ok_or(GoldenError::Malformed)?,
            spindle_rpm: rpm,
            positions: pos.get(..na).ok_or(GoldenError::Malformed)?,
            stale: stale != 0,
        });
        // The status is stored as a u32; its low half is the u16.
        let [lo, hi, _, _] = c.array()?;
        let mut ok = u16::from_le_bytes([lo, hi]) == out.status;
        // nd ≤ MAX_DIRECTIONS and na ≤ MAX_AXES (checked above): `take` takes exactly.
        for &v in out.corrections.iter().take(nd) {
            ok &= c.i32()? == v;
        }
        for &v in out.predicted.iter().take(nd) {
            ok &= c.i32()? == v;
        }
        for a in out.axes.iter().take(na) {
            ok &= c.i32()? == a.offset;
            ok &= c.i32()? == a.slope;
        }
        if !ok {
            return Err(GoldenError::Mismatch { step });
        }
    }
    if c.at != bytes.len() {
        return Err(GoldenError::Malformed);
    }
    Ok(n_steps)
}

/// Host side: write one step record (inputs and the host's outputs).
#[cfg(feature = "std")]
pub fn write_step(out: &mut Vec<u8>, input: &StepInput, result: &StepOutput, n_dir: usize) {
    out.extend_from_slice(&input.now_ms.to_le_bytes());
    for t in input.temps {
        out.extend_from_slice(&t.unwrap_or(i32::MIN).to_le_bytes());
    }
    out.extend_from_slice(&input.spindle_rpm.to_le_bytes());
    for p in input.positions {
        out.extend_from_slice(&p.to_le_bytes());
    }
    out.extend_from_slice(&[u8::from(input.stale), 0, 0, 0]);
    out.extend_from_slice(&u32::from(result.status).to_le_bytes());
    for c in result.corrections.iter().take(n_dir) {
        out.extend_from_slice(&c.to_le_bytes());
    }
    for p in result.predicted.iter().take(n_dir) {
        out.extend_from_slice(&p.to_le_bytes());
    }
    for a in result.axes.iter().take(input.positions.len()) {
        out.extend_from_slice(&a.offset.to_le_bytes());
        out.extend_from_slice(&a.slope.to_le_bytes());
    }
}

/// Host side: the demo model and a step sequence that walks through every
/// rule (warm-up, lags over long gaps, envelope edges, clamps, rate limits,
/// sensor faults and recovery), as a golden file. An error (the demo model
/// out of the fixed-point range) is a message, not a panic.
#[cfg(feature = "std")]
pub fn generate(n_steps: u32, seed: u64) -> Result<Vec<u8>, std::string::String> {
    use std::string::ToString;
    let fm = crate::float::demo_model(seed);
    let (mut model, _) = fm.quantize().map_err(|e| e.to_string())?;
    let mut image = vec![0u8; model.encoded_len()];
    let len = model.encode(&mut image).map_err(|e| e.to_string())?;
    image.truncate(len);
    let (ns, na, nd) = (
        model.sensors.len(),
        model.axes.len(),
        model.directions.len(),
    );
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&1u32.to_le_bytes());
    let image_len = u32::try_from(image.len()).map_err(|_| "image too long".to_string())?;
    out.extend_from_slice(&image_len.to_le_bytes());
    out.extend_from_slice(&image);
    out.extend_from_slice(&n_steps.to_le_bytes());
    let dim = |n: usize| u8::try_from(n).map_err(|_| "model too large".to_string());
    out.extend_from_slice(&[dim(ns)?, dim(na)?, dim(nd)?, 0]);
    let mut comp = Compensator::new(Some(model));
    let mut rng = seed | 1;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let mut now = 0u64;
    let mut temps: Vec<i32> = (20 * 16..).take(ns).collect();
    let mut rpm = 0i32;
    for step in 0..n_steps {
        now += match next() % 10 {
            0 => 0,
            1 => 3_600_000 + next() % 1000,
            2..=4 => 15_000,
            _ => 1_000 + next() % 500,
        };
        for t in temps.iter_mut() {
            // Warm-up drift with noise; occasionally far outside the envelope.
            *t += (next() % 7) as i32 - 2;
            if next() % 50 == 0 {
                *t += 400;
            }
            *t = (*t).clamp(-55 * 16, 125 * 16);
        }
        if next() % 8 == 0 {
            rpm = match next() % 5 {
                0 => 0,
                1 => 3000,
                2 => 6000,
                3 => 9000,
                _ => 12000,
            };
        }
        let mut t_in: Vec<Option<i32>> = temps.iter().map(|&t| Some(t)).collect();
        if step % 37 == 5 {
            let k = next() % ns as u64;
            if let Some(t) = usize::try_from(k).ok().and_then(|k| t_in.get_mut(k)) {
                *t = None;
            }
        }
        let pos: Vec<i32> = (0..na)
            .map(|_| (next() % 900_000) as i32 - 50_000)
            .collect();
        let input = StepInput {
            now_ms: now,
            temps: &t_in,
            spindle_rpm: rpm,
            positions: &pos,
            stale: step % 11 == 3,
        };
        let r = comp.step(&input);
        write_step(&mut out, &input, &r, nd);
    }
    Ok(out)
}

/// The model image inside a golden file (for benchmarks that need the model).
pub fn image(bytes: &[u8]) -> Option<&[u8]> {
    let mut c = Cursor { b: bytes, at: 0 };
    if c.take(4).ok()? != MAGIC || c.u32().ok()? != 1 {
        return None;
    }
    let n = c.u32().ok()? as usize;
    c.take(n).ok()
}

//! The compensator: a validated [`Model`] plus the state the board keeps
//! between steps, and the rules that make its output safe to hand to a CNC.
//!
//! Rules, in order, at every [`Compensator::step`]:
//! 1. **No model** → correction 0, status `NO_MODEL`, never `VALID`.
//! 2. **Sensor fault**: a sensor the model uses has no valid value → the
//!    served correction is held where it is, `SENSOR_FAULT` set, `VALID`
//!    cleared; filters do not advance. (The acquisition already bridged short
//!    gaps by holding the last good value; those arrive with `stale` set.)
//! 3. **Reference sample**: temperature rises are taken against the first
//!    step at which every sensor the model uses is valid (or against the
//!    image's stored reference with `FLAG_FIXED_REFERENCE`); the lag filters
//!    start from that sample. [`Compensator::rereference`] takes a new one.
//! 4. **Lag filters** advance in whole model steps (`step_ms`), the newest
//!    sample held over the elapsed steps (exact for any gap length).
//! 5. **Training envelope**: every input and position is held at the edge of
//!    the range seen in training (no extrapolation past it);
//!    `OUT_OF_ENVELOPE` says so. The model's output at the edge is the last
//!    value it was trained to produce, so it cannot run away.
//! 6. **Clamp** to ± max correction (`CLAMPED`), then **rate limit** to
//!    max rate × elapsed time from the previously served value
//!    (`RATE_LIMITED`). The first served value ramps up from 0.

use crate::eval::{AxisPair, Evaluation};
use crate::fixed::{decay_pow_q30, lag_update, FEATURE_FRAC_BITS};
use crate::image::{InputKind, Model, FLAG_FIXED_REFERENCE};
use crate::limits::*;

/// Largest rate limit, 0.1 µm/s (100 mm/s: no thermal drift comes near it).
pub const MAX_RATE: i32 = 1_000_000;

/// Status bits (one Modbus register).
pub mod status {
    /// The correction is computed from valid inputs by a valid model.
    pub const VALID: u16 = 1 << 0;
    /// A sensor the model needs is faulty; the correction is held.
    pub const SENSOR_FAULT: u16 = 1 << 1;
    /// No valid model loaded; the correction is 0.
    pub const NO_MODEL: u16 = 1 << 2;
    /// The correction was clamped to the maximum.
    pub const CLAMPED: u16 = 1 << 3;
    /// Within the model's warm-up time after the reference sample.
    pub const WARMING_UP: u16 = 1 << 4;
    /// Some input is a held (not fresh) value or the PLC's registers are old.
    pub const STALE_INPUTS: u16 = 1 << 5;
    /// Some input was outside the training envelope and held at its edge.
    pub const OUT_OF_ENVELOPE: u16 = 1 << 6;
    /// The correction's change was limited by the maximum rate.
    pub const RATE_LIMITED: u16 = 1 << 7;
}

/// Inputs of one step.
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    pub now_ms: u64,
    /// Temperature per model sensor (index as in the image), 1/16 °C; `None` = invalid.
    pub temps: &'a [Option<i32>],
    pub spindle_rpm: i32,
    /// Position per model axis (µm); missing entries count as the reference position.
    pub positions: &'a [i32],
    /// Some value is held rather than fresh.
    pub stale: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepOutput {
    /// Served correction per direction, 0.1 µm (after clamp and rate limit).
    pub corrections: [i32; MAX_DIRECTIONS],
    /// The model's prediction before limits, 0.1 µm.
    pub predicted: [i32; MAX_DIRECTIONS],
    pub axes: [AxisPair; MAX_AXES],
    pub status: u16,
}

pub struct Compensator {
    model: Option<Model>,
    reference: [i32; MAX_SENSORS],
    reference_ms: Option<u64>,
    filters_q16: [i64; MAX_INPUTS],
    filter_clock_ms: u64,
    last_step_ms: u64,
    served: [i32; MAX_DIRECTIONS],
    last_eval: Evaluation,
    /// Integrator limits (max correction, max rate) that may only tighten the image's.
    limit_override: [(i32, i32); MAX_DIRECTIONS],
}

impl Default for Compensator {
    fn default() -> Self {
        Self::new(None)
    }
}

impl Compensator {
    pub fn new(model: Option<Model>) -> Self {
        Compensator {
            model,
            reference: [0; MAX_SENSORS],
            reference_ms: None,
            filters_q16: [0; MAX_INPUTS],
            filter_clock_ms: 0,
            last_step_ms: 0,
            served: [0; MAX_DIRECTIONS],
            last_eval: Evaluation::default(),
            limit_override: [(i32::MAX, i32::MAX); MAX_DIRECTIONS],
        }
    }

    pub fn model(&self) -> Option<&Model> {
        self.model.as_ref()
    }

    /// Swap in a new model (or none). The reference and filters restart;
    /// the served correction is kept and moves to the new model's output at
    /// the new model's rate limit (no jump).
    pub fn load(&mut self, model: Option<Model>) {
        self.model = model;
        self.reference_ms = None;
    }

    /// Take a new reference sample at the next step (e.g. machine cold again).
    pub fn rereference(&mut self) {
        self.reference_ms = None;
    }

    /// The reference temperatures (1/16 °C) per model sensor, once taken.
    pub fn reference(&self) -> Option<&[i32]> {
        let n = self.model.as_ref()?.sensors.len();
        self.reference_ms.map(|_| &self.reference[..n])
    }

    /// Tighten one direction's limits (0.1 µm, 0.1 µm/s); values above the image's are ignored.
    pub fn set_limit_override(&mut self, direction: usize, max_correction: i32, max_rate: i32) {
        if let Some(l) = self.limit_override.get_mut(direction) {
            *l = (max_correction.max(0), max_rate.max(0));
        }
    }

    pub fn step(&mut self, input: &StepInput) -> StepOutput {
        let mut out = StepOutput::default();
        let Some(model) = self.model.as_ref() else {
            self.served = [0; MAX_DIRECTIONS];
            out.status = status::NO_MODEL;
            return out;
        };
        let temp = |s: u8| input.temps.get(usize::from(s)).copied().flatten();
        let needed_valid = model.inputs.iter().all(|inp| match inp.kind {
            InputKind::SensorRise { a } => temp(a).is_some(),
            InputKind::SensorDiff { a, b } => temp(a).is_some() && temp(b).is_some(),
            InputKind::Spindle => true,
        });
        if input.stale {
            out.status |= status::STALE_INPUTS;
        }
        if !needed_valid {
            out.status |= status::SENSOR_FAULT;
            out.corrections = self.served;
            out.predicted = self.last_eval.corrections;
            out.axes = self.last_eval.axes;
            self.last_step_ms = input.now_ms;
            return out;
        }

        // Features: Q16 of 1/16 °C or rpm, after the lag filters.
        let mut first = false;
        let reference_ms = match self.reference_ms {
            Some(t) => t,
            None => {
                first = true;
                for (i, (s, r)) in model
                    .sensors
                    .iter()
                    .zip(self.reference.iter_mut())
                    .enumerate()
                {
                    *r = if model.flags & FLAG_FIXED_REFERENCE != 0 {
                        s.ref_temp
                    } else {
                        temp(i as u8).unwrap_or(0)
                    };
                }
                self.reference_ms = Some(input.now_ms);
                self.filter_clock_ms = input.now_ms;
                input.now_ms
            }
        };
        // Whole filter steps since the last update; u32 division (hardware
        // UDIV) for any gap under 49 days, the 64-bit routine beyond.
        let step_ms = u64::from(model.step_ms);
        let elapsed = input.now_ms.saturating_sub(self.filter_clock_ms);
        let steps = match u32::try_from(elapsed) {
            Ok(e) => u64::from(e / model.step_ms),
            Err(_) => elapsed / step_ms,
        };
        self.filter_clock_ms += steps * step_ms;
        let t = |s: u8| i64::from(temp(s).unwrap_or(0));
        let mut features = [0i32; MAX_INPUTS];
        for (inp, (feature, filter)) in model
            .inputs
            .iter()
            .zip(features.iter_mut().zip(self.filters_q16.iter_mut()))
        {
            let raw = match inp.kind {
                InputKind::SensorRise { a } => {
                    t(a) - i64::from(self.reference.get(usize::from(a)).copied().unwrap_or(0))
                }
                InputKind::SensorDiff { a, b } => t(a) - t(b),
                InputKind::Spindle => i64::from(input.spindle_rpm),
            } << 16;
            let value_q16 = match inp.lag {
                None => raw,
                Some(_) if first => {
                    *filter = raw;
                    raw
                }
                Some(lag) => {
                    if steps > 0 {
                        *filter = lag_update(*filter, raw, decay_pow_q30(lag.decay_q30, steps));
                    }
                    *filter
                }
            };
            // Filters run in Q16 (i64); the model takes Q8 in an i32, saturated
            // (the envelope, within ±2^23 raw, then holds it at its edge).
            *feature = (value_q16 >> (16 - FEATURE_FRAC_BITS))
                .clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
        }
        let positions = input.positions;
        let eval = model.evaluate(&features[..model.inputs.len()], positions);
        if eval.out_of_envelope {
            out.status |= status::OUT_OF_ENVELOPE;
        }
        if input.now_ms.saturating_sub(reference_ms) < u64::from(model.warmup_s) * 1000 {
            out.status |= status::WARMING_UP;
        }
        // Elapsed whole seconds and remaining ms in u32 so the rate limit needs
        // no 64-bit division (max_rate ≤ MAX_RATE keeps rate·ms < 2^32).
        let dt_ms = input
            .now_ms
            .saturating_sub(self.last_step_ms)
            .min(u64::from(u32::MAX)) as u32;
        let (dt_s, dt_rem) = (dt_ms / 1000, dt_ms % 1000);
        let per_direction = self
            .served
            .iter_mut()
            .zip(&self.limit_override)
            .zip(&eval.corrections);
        for (dir, ((served, &(o_max, o_rate)), &predicted)) in
            model.directions.iter().zip(per_direction)
        {
            let max_c = i64::from(dir.max_correction.min(o_max));
            let rate = dir.max_rate.min(o_rate).clamp(0, MAX_RATE) as u32;
            let max_step = i64::from(rate) * i64::from(dt_s) + i64::from(rate * dt_rem / 1000);
            let mut target = i64::from(predicted);
            if target.abs() > max_c {
                target = target.clamp(-max_c, max_c);
                out.status |= status::CLAMPED;
            }
            let prev = i64::from(*served);
            if (target - prev).abs() > max_step {
                target = prev + (target - prev).clamp(-max_step, max_step);
                out.status |= status::RATE_LIMITED;
            }
            *served = target as i32;
        }
        self.last_step_ms = input.now_ms;
        self.last_eval = eval;
        out.corrections = self.served;
        out.predicted = eval.corrections;
        out.axes = eval.axes;
        out.status |= status::VALID;
        out
    }
}

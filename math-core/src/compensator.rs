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
//! 7. **Degraded mode** (images with fallback models, format v2): when a
//!    sensor some direction's main model reads is invalid, that direction is
//!    served by the first fallback (image order) whose inputs are all valid
//!    (`DEGRADED`; [`StepOutput::active`] names it); a direction with no such
//!    fallback is held as in rule 2. The switch (and the switch back when the
//!    sensor recovers) only changes the target: the served value still moves
//!    by at most max rate × elapsed time, so it never jumps. The lag filters
//!    of valid inputs keep running; an invalid input's filter is frozen and
//!    on recovery advances over the whole gap with its first new sample
//!    (rule 4, per input). Without fallbacks rule 2 applies unchanged.

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
    /// Some direction is served by a fallback model (a model sensor is invalid).
    pub const DEGRADED: u16 = 1 << 8;
}

/// [`StepOutput::active`]: no model serves the direction (held or no model).
pub const ACTIVE_NONE: u8 = 0xFF;

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
    /// Per direction, the model serving it: 0 main, k fallback k (1-based,
    /// image order), [`ACTIVE_NONE`] held or no model.
    pub active: [u8; MAX_DIRECTIONS],
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
    /// Per direction, bit i: the main model reads input i.
    main_mask: [u16; MAX_DIRECTIONS],
    /// Inputs whose filter is frozen (sensor invalid), and the filter clock
    /// each was last advanced to.
    frozen: u16,
    frozen_clock_ms: [u64; MAX_INPUTS],
    /// Inputs whose filter has not started (invalid at the reference sample).
    unstarted: u16,
    /// Sensors without a reference sample (invalid when it was taken): their
    /// rises stay invalid until the next reference.
    unreferenced: u32,
}

impl Default for Compensator {
    fn default() -> Self {
        Self::new(None)
    }
}

impl Compensator {
    pub fn new(model: Option<Model>) -> Self {
        let mut c = Compensator {
            model: None,
            reference: [0; MAX_SENSORS],
            reference_ms: None,
            filters_q16: [0; MAX_INPUTS],
            filter_clock_ms: 0,
            last_step_ms: 0,
            served: [0; MAX_DIRECTIONS],
            last_eval: Evaluation::default(),
            limit_override: [(i32::MAX, i32::MAX); MAX_DIRECTIONS],
            main_mask: [0; MAX_DIRECTIONS],
            frozen: 0,
            frozen_clock_ms: [0; MAX_INPUTS],
            unstarted: 0,
            unreferenced: 0,
        };
        c.load(model);
        c
    }

    pub fn model(&self) -> Option<&Model> {
        self.model.as_ref()
    }

    /// Swap in a new model (or none). The reference and filters restart;
    /// the served correction is kept and moves to the new model's output at
    /// the new model's rate limit (no jump).
    pub fn load(&mut self, model: Option<Model>) {
        self.main_mask = [0; MAX_DIRECTIONS];
        if let Some(m) = &model {
            for (d, mask) in self.main_mask.iter_mut().enumerate() {
                *mask = m.main_input_mask(d);
            }
        }
        self.model = model;
        self.rereference();
    }

    /// Take a new reference sample at the next step (e.g. machine cold again).
    pub fn rereference(&mut self) {
        self.reference_ms = None;
        self.frozen = 0;
        self.unstarted = 0;
        self.unreferenced = 0;
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
            out.active = [ACTIVE_NONE; MAX_DIRECTIONS];
            return out;
        };
        let temp = |s: u8| input.temps.get(usize::from(s)).copied().flatten();
        // Bit i: input i's sensors are valid.
        let mut valid = 0u16;
        for (i, inp) in model.inputs.iter().enumerate() {
            let ok = match inp.kind {
                InputKind::SensorRise { a } => {
                    temp(a).is_some() && self.unreferenced & (1 << (a % 32)) == 0
                }
                InputKind::SensorDiff { a, b } => temp(a).is_some() && temp(b).is_some(),
                InputKind::Spindle => true,
            };
            valid |= u16::from(ok) << i;
        }
        let all = (1u32 << model.inputs.len()) as u16;
        let all = all.wrapping_sub(1);
        if input.stale {
            out.status |= status::STALE_INPUTS;
        }
        // Per direction: the main model (0), a fallback (k), or none.
        let n_dir = model.directions.len().min(MAX_DIRECTIONS);
        let mut servable = valid == all;
        // (Before the reference sample too: a sensor dead at power-up then
        // gets no reference and its rises stay invalid until a new one.)
        if !servable && !model.fallbacks.is_empty() {
            for (d, (act, &mask)) in out
                .active
                .iter_mut()
                .zip(&self.main_mask)
                .enumerate()
                .take(n_dir)
            {
                *act = if mask & !valid == 0 {
                    0
                } else {
                    model
                        .fallbacks
                        .iter()
                        .position(|f| usize::from(f.direction) == d && f.input_mask & !valid == 0)
                        .map_or(ACTIVE_NONE, |k| (k + 1) as u8)
                };
                servable |= *act != ACTIVE_NONE;
            }
        }
        if !servable {
            out.active = [ACTIVE_NONE; MAX_DIRECTIONS];
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
                        match temp(i as u8) {
                            Some(v) => v,
                            None => {
                                self.unreferenced |= 1 << (i % 32);
                                0
                            }
                        }
                    };
                }
                self.unstarted = !valid & all;
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
        let clock_before = self.filter_clock_ms;
        self.filter_clock_ms += steps * step_ms;
        let t = |s: u8| i64::from(temp(s).unwrap_or(0));
        // Inputs needing more than the plain update (invalid, recovering, not started).
        let special = (!valid & all) | self.frozen | self.unstarted;
        let mut features = [0i32; MAX_INPUTS];
        for (i, (inp, (feature, filter))) in model
            .inputs
            .iter()
            .zip(features.iter_mut().zip(self.filters_q16.iter_mut()))
            .enumerate()
        {
            let bit = 1u16 << i;
            let (mut steps, mut start) = (steps, first);
            if special & bit != 0 {
                if valid & bit == 0 {
                    // Degraded: freeze this input at its last value (no fallback reads it).
                    if first {
                        *filter = 0;
                    }
                    if self.frozen & bit == 0 {
                        self.frozen |= bit;
                        self.frozen_clock_ms[i] = clock_before;
                    }
                    *feature = (*filter >> (16 - FEATURE_FRAC_BITS))
                        .clamp(i64::from(i32::MIN), i64::from(i32::MAX))
                        as i32;
                    continue;
                }
                // Recovered: advance over the whole gap (on the step grid).
                if self.frozen & bit != 0 {
                    self.frozen &= !bit;
                    steps = (self.filter_clock_ms - self.frozen_clock_ms[i]) / step_ms;
                }
                // Valid for the first time since the reference: start the filter.
                if self.unstarted & bit != 0 {
                    self.unstarted &= !bit;
                    start = true;
                }
            }
            let raw = match inp.kind {
                InputKind::SensorRise { a } => {
                    t(a) - i64::from(self.reference.get(usize::from(a)).copied().unwrap_or(0))
                }
                InputKind::SensorDiff { a, b } => t(a) - t(b),
                InputKind::Spindle => i64::from(input.spindle_rpm),
            } << 16;
            let value_q16 = match inp.lag {
                None => {
                    *filter = raw;
                    raw
                }
                Some(_) if start => {
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
        let mut eval = model.evaluate(&features[..model.inputs.len()], positions);
        if out.active[..n_dir].iter().any(|&a| a != 0) {
            let n = model.normalise(&features[..model.inputs.len()], positions);
            for (c, &a) in eval.corrections.iter_mut().zip(&out.active[..n_dir]) {
                match a {
                    0 => {}
                    ACTIVE_NONE => {
                        out.status |= status::SENSOR_FAULT;
                    }
                    k => {
                        *c = model.fallback_correction(usize::from(k) - 1, &n);
                        out.status |= status::DEGRADED;
                    }
                }
            }
        }
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
        for ((dir, ((served, &(o_max, o_rate)), &predicted)), &active) in
            model.directions.iter().zip(per_direction).zip(&out.active)
        {
            if active == ACTIVE_NONE {
                continue; // held: no model for this direction now
            }
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
        if out.status & status::SENSOR_FAULT == 0 {
            out.status |= status::VALID;
        }
        for a in out.active[n_dir..].iter_mut() {
            *a = ACTIVE_NONE;
        }
        out
    }
}

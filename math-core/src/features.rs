//! The feature pipeline: from one sample of sensor readings to the model's
//! inputs, with the state it keeps between samples. The one definition the
//! board ([`crate::Compensator::step`]) and the desktop's training (`tcomp
//! fit`) both run, so a model is trained on exactly the numbers the board
//! computes.
//!
//! Rules, at every [`FeatureState::step`]:
//! 1. **Units**: temperatures arrive in 1/16 °C (the DS18B20's LSB: the
//!    reading is rounded once, by the sensor or the trace parser), spindle
//!    speed in whole rpm.
//! 2. **Gaps**: when a sensor any input of the model reads has no valid
//!    value, the step yields nothing and nothing advances (no reference, no
//!    filter update). The next valid step catches up (rule 4).
//! 3. **Reference sample**: temperature rises are taken against the first
//!    step at which every sensor the inputs read is valid (or against the
//!    image's stored reference with `FLAG_FIXED_REFERENCE`, or the one the
//!    board kept, [`FeatureState::preset_reference`], before either); the
//!    lag filters start from that sample. [`FeatureState::rereference`]
//!    takes a new one.
//! 4. **Lag filters** advance in whole model steps (`step_ms`) since the last
//!    update, the newest sample held over the elapsed steps (exact for any
//!    gap length): y ← u + dⁿ (y − u), d = exp(−step/τ) in Q30.
//! 5. **Output**: each input in Q8 of its raw unit (i32, saturated).
//! 6. **Partial validity** (degraded mode, [`FeatureState::step_masked`]; the
//!    compensator uses it only for images with fallback models): the inputs
//!    whose sensors are valid advance as above; an invalid input's filter is
//!    frozen at its last value and, when its sensor is back, advances over
//!    the whole gap (on the step grid) with its first new sample. A sensor
//!    invalid when the reference is taken gets none: its rises stay invalid
//!    until the next reference. With every input valid this is exactly
//!    [`FeatureState::step`].

use crate::fixed::{decay_pow_q30, lag_update, FEATURE_FRAC_BITS};
use crate::image::{InputKind, Model, FLAG_FIXED_REFERENCE};
use crate::limits::*;

/// Model inputs of one step, Q8 of the raw unit (1/16 °C or rpm).
pub type Features = [i32; MAX_INPUTS];

/// What the pipeline keeps between samples.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FeatureState {
    reference: [i32; MAX_SENSORS],
    reference_ms: Option<u64>,
    filters_q16: [i64; MAX_INPUTS],
    filter_clock_ms: u64,
    features: Features,
    /// Inputs whose filter is frozen (sensor invalid), and the filter clock
    /// each was last advanced to.
    frozen: u16,
    frozen_clock_ms: [u64; MAX_INPUTS],
    /// Inputs whose filter has not started (invalid at the reference sample).
    unstarted: u16,
    /// Sensors without a reference sample (invalid when it was taken).
    unreferenced: u32,
    /// A reference sample given from outside ([`FeatureState::preset_reference`]):
    /// bit i set, sensor i takes `preset[i]` at the next reference.
    preset_mask: Option<u32>,
    preset: [i32; MAX_SENSORS],
}

impl Default for FeatureState {
    fn default() -> Self {
        Self::new()
    }
}

impl FeatureState {
    pub const fn new() -> Self {
        FeatureState {
            reference: [0; MAX_SENSORS],
            reference_ms: None,
            filters_q16: [0; MAX_INPUTS],
            filter_clock_ms: 0,
            features: [0; MAX_INPUTS],
            frozen: 0,
            frozen_clock_ms: [0; MAX_INPUTS],
            unstarted: 0,
            unreferenced: 0,
            preset_mask: None,
            preset: [0; MAX_SENSORS],
        }
    }

    /// Take a new reference sample (and restart the filters) at the next valid step.
    pub fn rereference(&mut self) {
        self.reference_ms = None;
        self.frozen = 0;
        self.unstarted = 0;
        self.unreferenced = 0;
        self.preset_mask = None;
    }

    /// Restart at the next step (as [`FeatureState::rereference`]) with
    /// this reference sample instead of the step's readings or the image's
    /// stored reference: `refs` per model sensor (1/16 °C); a sensor with
    /// `None` gets no reference (its rises stay invalid until the next
    /// one). The board's kept reference (rule 3), applied at boot.
    pub fn preset_reference(&mut self, refs: &[Option<i32>]) {
        self.rereference();
        let mut mask = 0u32;
        for (i, (p, r)) in self.preset.iter_mut().zip(refs).enumerate() {
            *p = r.unwrap_or(0);
            if r.is_some() {
                mask |= 1 << (i % 32);
            }
        }
        self.preset_mask = Some(mask);
    }

    /// Sensors without a reference: those invalid when it was taken, or,
    /// before a preset reference is taken, those it does not cover.
    #[inline]
    fn unreferenced_now(&self) -> u32 {
        match (self.reference_ms, self.preset_mask) {
            (None, Some(mask)) => !mask,
            _ => self.unreferenced,
        }
    }

    /// Bit i: input i of `model` can be computed now (its sensors are valid
    /// and, for a rise, its sensor has a reference sample).
    #[inline]
    pub fn valid_mask(&self, model: &Model, temps: &[Option<i32>]) -> u16 {
        let temp = |s: u8| temps.get(usize::from(s)).copied().flatten();
        let unreferenced = self.unreferenced_now();
        let mut valid = 0u16;
        for (i, inp) in model.inputs.iter().enumerate() {
            let ok = match inp.kind {
                InputKind::SensorRise { a } => {
                    temp(a).is_some() && unreferenced & (1 << (a % 32)) == 0
                }
                InputKind::SensorDiff { a, b } => temp(a).is_some() && temp(b).is_some(),
                InputKind::Spindle => true,
            };
            valid |= u16::from(ok) << i;
        }
        valid
    }

    /// Mask of every input of `model`.
    #[inline]
    pub fn all_inputs(model: &Model) -> u16 {
        #[allow(
            clippy::cast_possible_truncation,
            reason = "inputs.len() <= MAX_INPUTS = 12 < 16 (checked at parse)"
        )]
        let bits = (1u32 << model.inputs.len()) as u16;
        bits.wrapping_sub(1)
    }

    /// When the reference sample was taken (ms), once taken.
    pub fn reference_ms(&self) -> Option<u64> {
        self.reference_ms
    }

    /// The reference temperatures (1/16 °C) of the first `n` model sensors, once taken.
    pub fn reference(&self, n: usize) -> Option<&[i32]> {
        self.reference_ms
            .and(self.reference.get(..n.min(MAX_SENSORS)))
    }

    /// One sample: `temps` per model sensor (1/16 °C, `None` = invalid),
    /// spindle speed in rpm. Returns the model's inputs (Q8 of the raw unit,
    /// one per `model.inputs`), or `None` when a sensor the inputs read is
    /// invalid (rule 2: nothing advances).
    #[inline]
    pub fn step(
        &mut self,
        model: &Model,
        now_ms: u64,
        temps: &[Option<i32>],
        spindle_rpm: i32,
    ) -> Option<&[i32]> {
        // (Only `step_masked` with a partial mask marks sensors unreferenced,
        // so here this is "every sensor the inputs read is valid".)
        let all = Self::all_inputs(model);
        if self.valid_mask(model, temps) != all {
            return None;
        }
        Some(self.step_masked(model, now_ms, temps, spindle_rpm, all))
    }

    /// One sample with only the inputs in `valid` computable (rule 6;
    /// `valid` from [`FeatureState::valid_mask`]). Invalid inputs return
    /// their frozen last value, which no model that is served reads.
    pub fn step_masked(
        &mut self,
        model: &Model,
        now_ms: u64,
        temps: &[Option<i32>],
        spindle_rpm: i32,
        valid: u16,
    ) -> &[i32] {
        let temp = |s: u8| temps.get(usize::from(s)).copied().flatten();
        let all = Self::all_inputs(model);
        let first = self.reference_ms.is_none();
        if first {
            self.take_reference(model, &temp);
            self.unstarted = !valid & all;
            self.reference_ms = Some(now_ms);
            self.filter_clock_ms = now_ms;
        }
        // Whole filter steps since the last update; u32 division (hardware
        // UDIV) for any gap under 49 days, the 64-bit routine beyond.
        let step_ms = u64::from(model.step_ms);
        let elapsed = now_ms.saturating_sub(self.filter_clock_ms);
        let steps = match u32::try_from(elapsed) {
            Ok(e) => u64::from(e / model.step_ms),
            Err(_) => elapsed / step_ms,
        };
        let clock_before = self.filter_clock_ms;
        self.filter_clock_ms += steps * step_ms;
        let t = |s: u8| i64::from(temp(s).unwrap_or(0));
        // Inputs needing more than the plain update (invalid, recovering, not started).
        let special = (!valid & all) | self.frozen | self.unstarted;
        #[allow(
            clippy::indexing_slicing,
            clippy::cast_possible_truncation,
            reason = "i < inputs.len() <= MAX_INPUTS = frozen_clock_ms.len(); casts after a clamp to the i32 range"
        )]
        for (i, (inp, (feature, filter))) in model
            .inputs
            .iter()
            .zip(self.features.iter_mut().zip(self.filters_q16.iter_mut()))
            .enumerate()
        {
            let bit = 1u16 << i;
            let (mut steps, mut start) = (steps, first);
            if special & bit != 0 {
                if valid & bit == 0 {
                    // Frozen at its last value (no served model reads it).
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
                InputKind::Spindle => i64::from(spindle_rpm),
            } << 16;
            let value_q16 = match inp.lag {
                // Kept so a frozen unlagged input returns its last value.
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
        #[allow(
            clippy::indexing_slicing,
            reason = "inputs.len() <= MAX_INPUTS = features.len() (checked at parse)"
        )]
        &self.features[..model.inputs.len()]
    }

    /// The reference sample (rule 3): per model sensor the preset value, the
    /// image's stored reference, or the first reading; a sensor without one
    /// is marked unreferenced.
    fn take_reference(&mut self, model: &Model, temp: &impl Fn(u8) -> Option<i32>) {
        let per_sensor = model
            .sensors
            .iter()
            .zip(self.reference.iter_mut().zip(&self.preset))
            .zip(0u8..);
        for ((s, (r, &preset)), i) in per_sensor {
            let bit = 1u32 << (i % 32);
            *r = if let Some(mask) = self.preset_mask {
                if mask & bit == 0 {
                    self.unreferenced |= bit;
                }
                preset
            } else if model.flags & FLAG_FIXED_REFERENCE != 0 {
                s.ref_temp
            } else {
                match temp(i) {
                    Some(v) => v,
                    None => {
                        self.unreferenced |= bit;
                        0
                    }
                }
            };
        }
    }
}

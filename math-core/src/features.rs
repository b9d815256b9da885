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
//!    image's stored reference with `FLAG_FIXED_REFERENCE`); the lag filters
//!    start from that sample. [`FeatureState::rereference`] takes a new one.
//! 4. **Lag filters** advance in whole model steps (`step_ms`) since the last
//!    update, the newest sample held over the elapsed steps (exact for any
//!    gap length): y ← u + dⁿ (y − u), d = exp(−step/τ) in Q30.
//! 5. **Output**: each input in Q8 of its raw unit (i32, saturated).

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
        }
    }

    /// Take a new reference sample (and restart the filters) at the next valid step.
    pub fn rereference(&mut self) {
        self.reference_ms = None;
    }

    /// When the reference sample was taken (ms), once taken.
    pub fn reference_ms(&self) -> Option<u64> {
        self.reference_ms
    }

    /// The reference temperatures (1/16 °C) of the first `n` model sensors, once taken.
    pub fn reference(&self, n: usize) -> Option<&[i32]> {
        self.reference_ms
            .map(|_| &self.reference[..n.min(MAX_SENSORS)])
    }

    /// Every sensor an input of `model` reads has a valid value in `temps`.
    #[inline]
    pub fn inputs_valid(model: &Model, temps: &[Option<i32>]) -> bool {
        let temp = |s: u8| temps.get(usize::from(s)).copied().flatten();
        model.inputs.iter().all(|inp| match inp.kind {
            InputKind::SensorRise { a } => temp(a).is_some(),
            InputKind::SensorDiff { a, b } => temp(a).is_some() && temp(b).is_some(),
            InputKind::Spindle => true,
        })
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
        if !Self::inputs_valid(model, temps) {
            return None;
        }
        let temp = |s: u8| temps.get(usize::from(s)).copied().flatten();
        let mut first = false;
        if self.reference_ms.is_none() {
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
        self.filter_clock_ms += steps * step_ms;
        let t = |s: u8| i64::from(temp(s).unwrap_or(0));
        for (inp, (feature, filter)) in model
            .inputs
            .iter()
            .zip(self.features.iter_mut().zip(self.filters_q16.iter_mut()))
        {
            let raw = match inp.kind {
                InputKind::SensorRise { a } => {
                    t(a) - i64::from(self.reference.get(usize::from(a)).copied().unwrap_or(0))
                }
                InputKind::SensorDiff { a, b } => t(a) - t(b),
                InputKind::Spindle => i64::from(spindle_rpm),
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
        Some(&self.features[..model.inputs.len()])
    }
}

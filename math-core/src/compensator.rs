//! The compensator: a validated [`Model`] plus the state the board keeps
//! between steps, and the rules that make its output safe to hand to a CNC.
//!
//! Rules, in order, at every [`Compensator::step`]:
//! 1. **No model** → correction 0, status `NO_MODEL`, never `VALID`.
//! 2. **Sensor fault**: a sensor the model uses has no valid value → the
//!    served correction is held where it is, `SENSOR_FAULT` set, `VALID`
//!    cleared; filters do not advance. (The acquisition already bridged short
//!    gaps by holding the last good value; those arrive with `stale` set.)
//! 3. **Features** by the shared pipeline ([`crate::features`], the very
//!    code `tcomp fit` trains on): reference sample (the first step at which
//!    every sensor the model uses is valid, or the image's stored reference
//!    with `FLAG_FIXED_REFERENCE`; [`Compensator::rereference`] takes a new
//!    one), lag filters advanced in whole model steps (`step_ms`) with the
//!    newest sample held over the elapsed steps (exact for any gap length).
//! 4. **Training envelope**: every input and position is held at the edge of
//!    the range seen in training (no extrapolation past it, unless the
//!    direction's policy is `extrapolate`, below);
//!    `OUT_OF_ENVELOPE` says so. The model's output at the edge is the last
//!    value it was trained to produce, so it cannot run away. Per direction
//!    the image's envelope policy (section kind 5, format v3; older images:
//!    hold, margin 0) says what happens when an input of the model serving
//!    it lies beyond its range by more than the policy's margin (raw
//!    units): the step counts for that direction
//!    ([`Compensator::envelope_steps`], saturating at `u32::MAX`;
//!    [`StepOutput::envelope`]) and sets `OUT_OF_ENVELOPE`; under `hold`
//!    the input stays held at the edge, under `fallback` the sensors it
//!    reads count as faulted for that direction, which is then served by
//!    its first fallback (image order) that reads none of them nor an
//!    invalid sensor, as in rule 6 (`DEGRADED`); none: held at the edge.
//!    Under `extrapolate` (format v4; the parser admits it only for a
//!    direction every model of which is linear) the inputs of the model
//!    serving the direction (main or the fallback in force) are normalised
//!    over the extended span [lo − W·(hi − lo), hi + W·(hi − lo)], W =
//!    [`EXTRAPOLATE_WIDTHS`] = 2: the linear function continues up to two
//!    training widths beyond each edge and is held at that outer edge
//!    beyond (a stated bound); counted and flagged as under hold. It is
//!    computed only when an input is outside its range and the image has
//!    such a direction; other directions are served exactly as before.
//! 5. **Output low-pass** (section kind 6, format v5; older images and
//!    directions with decay 0: none, bit for bit as before): the final
//!    prediction of a served direction (model, fallback or extrapolated) is
//!    filtered by a causal first-order lag, y ← u + dⁿ (y − u), d =
//!    exp(−step/τ) in Q30, n the whole model steps (`step_ms`) since the
//!    filter's last update, the newest prediction held over them (exact for
//!    any gap length, as the input lags). The first served step after a
//!    load, restart or new reference starts it at the prediction (no ramp
//!    from 0); a direction not served (held, rule 2 or 6) does not advance
//!    and on its next served step advances over the whole gap. A switch
//!    between the main model and a fallback (rule 6, or the envelope's
//!    `fallback`) keeps the state: the switch is smoothed like any change
//!    (the fit chose τ on the main model).
//!    [`StepOutput::predicted`] is the filtered value. Then **clamp** to
//!    ± max correction (`CLAMPED`), then **rate limit** to
//!    max rate × elapsed time from the previously served value
//!    (`RATE_LIMITED`). The first served value ramps up from 0.
//! 6. **Degraded mode** (images with fallback models, format v2): when a
//!    sensor some direction's main model reads is invalid, that direction is
//!    served by the first fallback (image order) whose inputs are all valid
//!    (`DEGRADED`; [`StepOutput::active`] names it); a direction with no such
//!    fallback is held as in rule 2. The switch (and the switch back when the
//!    sensor recovers) only changes the target: the served value still moves
//!    by at most max rate × elapsed time, so it never jumps. The lag filters
//!    of valid inputs keep running; an invalid input's filter is frozen and
//!    on recovery advances over the whole gap with its first new sample
//!    ([`crate::features`] rule 6). Without fallbacks rule 2 applies unchanged.

use crate::eval::{AxisPair, Evaluation};
use crate::features::FeatureState;
use crate::fixed::{decay_pow_q30, lag_update, round_shift};
use crate::image::{EnvelopeMode, Model};
use crate::limits::*;

/// Kept here for its old path; defined with the other limits.
pub use crate::limits::MAX_RATE;

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
    /// The model's prediction before limits (after the output low-pass,
    /// rule 5), 0.1 µm.
    pub predicted: [i32; MAX_DIRECTIONS],
    pub axes: [AxisPair; MAX_AXES],
    pub status: u16,
    /// Per direction, the model serving it: 0 main, k fallback k (1-based,
    /// image order), [`ACTIVE_NONE`] held or no model.
    pub active: [u8; MAX_DIRECTIONS],
    /// Bit d: an input of the model serving direction d was beyond its
    /// envelope by more than the direction's margin (rule 4).
    pub envelope: u8,
}

pub struct Compensator {
    /// The model in force when `loaded` (held in place: a board parses an
    /// image straight into it, [`Compensator::load_with`], so no second
    /// copy of a model ever sits on its stack).
    model: Model,
    loaded: bool,
    features: FeatureState,
    last_step_ms: u64,
    served: [i32; MAX_DIRECTIONS],
    last_eval: Evaluation,
    /// Integrator limits (max correction, max rate) that may only tighten the image's.
    limit_override: [(i32, i32); MAX_DIRECTIONS],
    /// Per direction, bit i: the main model reads input i.
    main_mask: [u16; MAX_DIRECTIONS],
    /// Per direction, the steps served beyond the envelope (rule 4) since
    /// the model was loaded, saturating.
    envelope_steps: [u32; MAX_DIRECTIONS],
    /// The output low-pass's state (rule 5).
    output: OutputFilter,
}

/// Rule 5's state: per direction the filtered prediction (Q16 of 0.1 µm),
/// the filter clock (ms, on the model's step grid from the direction's
/// first served step) and, bit d, whether direction d's filter has started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct OutputFilter {
    y_q16: [i64; MAX_DIRECTIONS],
    clock_ms: [u64; MAX_DIRECTIONS],
    started: u8,
}

impl OutputFilter {
    const NEW: Self = OutputFilter {
        y_q16: [0; MAX_DIRECTIONS],
        clock_ms: [0; MAX_DIRECTIONS],
        started: 0,
    };

    /// Filter each served direction (`active` not [`ACTIVE_NONE`]) that has
    /// a decay, in place. Overflow: |u| ≤ 2^31 (an i32), so u and y, a
    /// convex combination of past u's (`lag_update` rounds within them),
    /// stay within 2^31·2^16 = 2^47 and y − u within 2^48, far inside the
    /// 2^62 that `lag_update`'s product allows; the rounded y/2^16 is then
    /// in the i32 range (clamped all the same).
    #[inline(always)]
    fn apply(
        &mut self,
        model: &Model,
        now_ms: u64,
        active: &[u8],
        corrections: &mut [i32; MAX_DIRECTIONS],
    ) {
        if let Some(decays) = &model.output_decay_q30 {
            self.filter(decays, model.step_ms, now_ms, active, corrections);
        }
    }

    #[inline(never)]
    fn filter(
        &mut self,
        decays: &[u32; MAX_DIRECTIONS],
        step_ms: u32,
        now_ms: u64,
        active: &[u8],
        corrections: &mut [i32; MAX_DIRECTIONS],
    ) {
        // step_ms ≥ 1 (the parser refuses 0); max(1) keeps the division total.
        let step_ms32 = step_ms.max(1);
        let step_ms = u64::from(step_ms32);
        let per_direction = corrections.iter_mut().zip(active).zip(decays);
        let state = self.y_q16.iter_mut().zip(self.clock_ms.iter_mut());
        for (d, (((c, &a), &decay), (y, clock))) in per_direction.zip(state).enumerate() {
            if decay == 0 || a == ACTIVE_NONE {
                continue;
            }
            let u = i64::from(*c) << 16;
            let bit = 1u8 << (d % 8);
            if self.started & bit == 0 {
                self.started |= bit;
                *y = u;
                *clock = now_ms;
            } else {
                // u32 division (hardware UDIV) for any gap under 49 days,
                // the 64-bit routine beyond (as the feature filters).
                let elapsed = now_ms.saturating_sub(*clock);
                let steps = match u32::try_from(elapsed) {
                    Ok(e) => u64::from(e / step_ms32),
                    Err(_) => elapsed / step_ms,
                };
                *clock += steps * step_ms;
                if steps > 0 {
                    *y = lag_update(*y, u, decay_pow_q30(decay, steps));
                }
            }
            #[allow(
                clippy::cast_possible_truncation,
                reason = "clamped to the i32 range first"
            )]
            {
                *c = round_shift(*y, 16).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
            }
        }
    }
}

impl Default for Compensator {
    fn default() -> Self {
        Self::new(None)
    }
}

impl Compensator {
    pub fn new(model: Option<Model>) -> Self {
        let mut c = Self::empty();
        c.load(model);
        c
    }

    /// `Compensator::new(None)`, as one value (no model, nothing to
    /// restart), so that it can be built straight where it is kept.
    #[inline(always)]
    pub fn empty() -> Self {
        Compensator {
            model: Model::empty(0, 0),
            loaded: false,
            features: FeatureState::new(),
            last_step_ms: 0,
            served: [0; MAX_DIRECTIONS],
            last_eval: Evaluation::default(),
            limit_override: [(i32::MAX, i32::MAX); MAX_DIRECTIONS],
            main_mask: [0; MAX_DIRECTIONS],
            envelope_steps: [0; MAX_DIRECTIONS],
            output: OutputFilter::NEW,
        }
    }

    /// Back to [`Compensator::empty`] in place (no model, limits and served
    /// correction cleared).
    pub fn clear(&mut self) {
        self.loaded = false;
        self.features = FeatureState::new();
        self.last_step_ms = 0;
        self.served = [0; MAX_DIRECTIONS];
        self.last_eval = Evaluation::default();
        self.limit_override = [(i32::MAX, i32::MAX); MAX_DIRECTIONS];
        self.main_mask = [0; MAX_DIRECTIONS];
        self.envelope_steps = [0; MAX_DIRECTIONS];
        self.output.started = 0;
    }

    /// Per direction, the steps served with an input beyond the envelope
    /// by more than the direction's margin (rule 4) since the model in
    /// force was loaded or restarted; saturating at `u32::MAX`.
    pub fn envelope_steps(&self) -> [u32; MAX_DIRECTIONS] {
        self.envelope_steps
    }

    pub fn model(&self) -> Option<&Model> {
        self.loaded.then_some(&self.model)
    }

    /// Swap in a new model (or none). The reference and filters restart;
    /// the served correction is kept and moves to the new model's output at
    /// the new model's rate limit (no jump).
    pub fn load(&mut self, model: Option<Model>) {
        self.loaded = false;
        if let Some(m) = model {
            self.model = m;
            self.loaded = true;
        }
        self.restart();
    }

    /// As [`Compensator::load`], with the model filled in place by `fill`
    /// (e.g. [`Model::parse_into`]); `false` from it: no model.
    pub fn load_with(&mut self, fill: impl FnOnce(&mut Model) -> bool) {
        self.loaded = false;
        self.loaded = fill(&mut self.model);
        self.restart();
    }

    /// Lend this compensator's model storage to `check` (e.g. parse a
    /// candidate image there to validate it, so that a board keeps no
    /// second model on its stack), then put the model in force back with
    /// `restore`, which must refill the very same model (e.g. re-parse the
    /// image it came from; its CRC is compared). Features, filters, the
    /// reference and the served correction are untouched. A restore that
    /// fails or gives another model leaves no model in force, as
    /// [`Compensator::load`] with none.
    pub fn check_with<R>(
        &mut self,
        check: impl FnOnce(&mut Model) -> R,
        restore: impl FnOnce(&mut Model) -> bool,
    ) -> R {
        let crc = self.model.crc;
        let outcome = check(&mut self.model);
        if self.loaded && !(restore(&mut self.model) && self.model.crc == crc) {
            self.loaded = false;
            self.restart();
        }
        outcome
    }

    /// As [`Compensator::load`] with the model held now (reference and
    /// filters restart).
    pub fn restart(&mut self) {
        self.main_mask = [0; MAX_DIRECTIONS];
        self.envelope_steps = [0; MAX_DIRECTIONS];
        if self.loaded {
            for (d, mask) in self.main_mask.iter_mut().enumerate() {
                *mask = self.model.main_input_mask(d);
            }
        }
        self.rereference();
    }

    /// Take a new reference sample at the next step (e.g. machine cold
    /// again); the output low-pass restarts there too (rule 5).
    pub fn rereference(&mut self) {
        self.features.rereference();
        self.output.started = 0;
    }

    /// Restart from this reference sample (per model sensor, 1/16 °C;
    /// `None`: that sensor gets no reference) at the next step, instead of
    /// the step's readings or the image's stored reference: the board's kept
    /// reference ([`FeatureState::preset_reference`]).
    pub fn preset_reference(&mut self, refs: &[Option<i32>]) {
        self.features.preset_reference(refs);
        self.output.started = 0;
    }

    /// The reference temperatures (1/16 °C) per model sensor, once taken.
    pub fn reference(&self) -> Option<&[i32]> {
        let n = self.model()?.sensors.len();
        self.features.reference(n)
    }

    /// Tighten one direction's limits (0.1 µm, 0.1 µm/s); values above the image's are ignored.
    pub fn set_limit_override(&mut self, direction: usize, max_correction: i32, max_rate: i32) {
        if let Some(l) = self.limit_override.get_mut(direction) {
            *l = (max_correction.max(0), max_rate.max(0));
        }
    }

    pub fn step(&mut self, input: &StepInput) -> StepOutput {
        let mut out = StepOutput::default();
        let Some(model) = self.loaded.then_some(&self.model) else {
            self.served = [0; MAX_DIRECTIONS];
            out.status = status::NO_MODEL;
            out.active = [ACTIVE_NONE; MAX_DIRECTIONS];
            return out;
        };
        // Bit i: input i's sensors are valid.
        let valid = self.features.valid_mask(model, input.temps);
        let all = FeatureState::all_inputs(model);
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
                    first_fallback(model, d, valid).unwrap_or(ACTIVE_NONE)
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

        // Features (reference sample, gaps, lag filters): the shared pipeline.
        let mut features = [0i32; MAX_INPUTS];
        #[allow(
            clippy::indexing_slicing,
            reason = "inputs.len() <= MAX_INPUTS (checked at parse)"
        )]
        let features = &mut features[..model.inputs.len()];
        features.copy_from_slice(self.features.step_masked(
            model,
            input.now_ms,
            input.temps,
            input.spindle_rpm,
            valid,
        ));
        envelope_rule(
            model,
            (&self.main_mask, &mut self.envelope_steps),
            features,
            valid,
            &mut out,
        );
        let reference_ms = self.features.reference_ms().unwrap_or(input.now_ms);
        let positions = input.positions;
        let mut eval = model.evaluate(features, positions);
        #[allow(
            clippy::indexing_slicing,
            reason = "n_dir <= MAX_DIRECTIONS = active.len()"
        )]
        let active = &out.active[..n_dir];
        if active.iter().any(|&a| a != 0) {
            let n = model.normalise(features, positions);
            for (c, &a) in eval.corrections.iter_mut().zip(active) {
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
        out.status |= outside_rule(model, features, active, &mut eval);
        self.output
            .apply(model, input.now_ms, active, &mut eval.corrections);
        if input.now_ms.saturating_sub(reference_ms) < u64::from(model.warmup_s) * 1000 {
            out.status |= status::WARMING_UP;
        }
        // Elapsed whole seconds and remaining ms in u32 so the rate limit needs
        // no 64-bit division (max_rate ≤ MAX_RATE keeps rate·ms < 2^32).
        let dt_ms =
            u32::try_from(input.now_ms.saturating_sub(self.last_step_ms)).unwrap_or(u32::MAX);
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
            #[allow(
                clippy::cast_possible_truncation,
                reason = "|target| <= max(|prev|, max_c): both within i32"
            )]
            {
                *served = target as i32;
            }
        }
        self.last_step_ms = input.now_ms;
        self.last_eval = eval;
        out.corrections = self.served;
        out.predicted = eval.corrections;
        out.axes = eval.axes;
        if out.status & status::SENSOR_FAULT == 0 {
            out.status |= status::VALID;
        }
        #[allow(
            clippy::indexing_slicing,
            reason = "n_dir <= MAX_DIRECTIONS = active.len()"
        )]
        let unused = &mut out.active[n_dir..];
        for a in unused {
            *a = ACTIVE_NONE;
        }
        out
    }
}

/// The first fallback (1-based, image order) of direction `d` whose inputs
/// are all in `ok` (bit i: input i may be read).
fn first_fallback(model: &Model, d: usize, ok: u16) -> Option<u8> {
    model
        .fallbacks
        .iter()
        .position(|f| usize::from(f.direction) == d && f.input_mask & !ok == 0)
        .and_then(|k| u8::try_from(k + 1).ok())
}

/// Rule 4's envelope policy for every served direction: count the step and
/// flag it when an input of the model serving the direction is beyond its
/// range by more than the margin; under `fallback`, a direction served by
/// its main model switches to its first fallback that reads none of the
/// sensors beyond (nor an invalid one).
fn envelope_rule(
    model: &Model,
    (main_mask, counts): (&[u16; MAX_DIRECTIONS], &mut [u32; MAX_DIRECTIONS]),
    features: &[i32],
    valid: u16,
    out: &mut StepOutput,
) {
    let policies = model.envelope.unwrap_or_default();
    let per_direction = out.active.iter_mut().zip(main_mask).zip(counts.iter_mut());
    for (d, (((act, &main), count), policy)) in per_direction
        .zip(&policies)
        .enumerate()
        .take(model.directions.len())
    {
        let reads = match *act {
            0 => main,
            ACTIVE_NONE => continue,
            k => model
                .fallbacks
                .get(usize::from(k) - 1)
                .map_or(0, |f| f.input_mask),
        };
        let beyond = model.beyond_mask(features, policy.margin) & reads;
        if beyond == 0 {
            continue;
        }
        *count = count.saturating_add(1);
        out.envelope |= 1 << d;
        out.status |= status::OUT_OF_ENVELOPE;
        if policy.mode == EnvelopeMode::Fallback && *act == 0 {
            let ok = valid & !model.sensor_closure(beyond);
            if let Some(k) = first_fallback(model, d, ok) {
                *act = k;
            }
        }
    }
}

/// Rule 4 when some input or position lies outside its range: the status
/// bit `OUT_OF_ENVELOPE` (returned; 0 inside), and under `extrapolate` each
/// extrapolating direction served by a model (main or fallback) evaluated
/// again with its inputs over the extended span (linear up to
/// [`EXTRAPOLATE_WIDTHS`] training widths beyond each edge, held there).
/// Nothing more is computed for an image without such a direction. Out of
/// line: the common case (inside) costs the step one test and a call.
#[inline(never)]
fn outside_rule(model: &Model, features: &[i32], active: &[u8], eval: &mut Evaluation) -> u16 {
    if !eval.out_of_envelope {
        return 0;
    }
    let mask = model.extrapolate_mask();
    if mask == 0 {
        return status::OUT_OF_ENVELOPE;
    }
    let n = model.normalise_extended(features);
    if !n.outside {
        return status::OUT_OF_ENVELOPE; // only a position was outside: held values stand
    }
    for (d, (c, &a)) in eval.corrections.iter_mut().zip(active).enumerate() {
        if mask & (1 << d) == 0 {
            continue;
        }
        *c = match a {
            0 => model.static_correction(d, &n),
            ACTIVE_NONE => continue,
            k => model.fallback_correction(usize::from(k) - 1, &n),
        };
    }
    status::OUT_OF_ENVELOPE
}

//! [`Model`]: a validated model image in RAM (no heap), and what the
//! compensator and the desktop ask of it.

use super::error::{push, ImageError};
use super::types::{
    name_str, Axis, Direction, EnvelopeMode, EnvelopePolicy, Fallback, InputSpec, Net, SensorRef,
    Table, Term,
};
use crate::five_axis::FiveAxis;
use crate::fixed::Span;
use crate::limits::*;
use crate::volumetric::Volumetric;
use heapless::Vec;

/// A validated model. Every index inside is in range and every range is
/// monotone, so evaluation needs no further checks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Model {
    pub flags: u16,
    pub model_version: u32,
    /// Lag-filter step (ms); the model was trained with this discretisation.
    pub step_ms: u32,
    /// The status bit "warming up" is set for this long after the reference sample.
    pub warmup_s: u32,
    pub sensors: Vec<SensorRef, MAX_SENSORS>,
    pub directions: Vec<Direction, MAX_DIRECTIONS>,
    pub axes: Vec<Axis, MAX_AXES>,
    pub inputs: Vec<InputSpec, MAX_INPUTS>,
    pub nets: Vec<Net, MAX_NETS>,
    pub tables: Vec<Table, MAX_TABLES>,
    /// Fallback models in priority order (format v2; empty in v1 images).
    pub fallbacks: Vec<Fallback, MAX_FALLBACKS>,
    pub fallback_terms: Vec<Term, MAX_FALLBACK_TERMS>,
    /// The volumetric correction (format v2, section kind 3), if any.
    pub volumetric: Option<Volumetric>,
    /// The five-axis part of the volumetric correction (section kind 4), if any.
    pub five_axis: Option<FiveAxis>,
    /// The envelope policy per direction (section kind 5, format v3); `None`
    /// in older images: every direction holds, margin 0.
    pub envelope: Option<[EnvelopePolicy; MAX_DIRECTIONS]>,
    /// The output low-pass per direction (section kind 6, format v5): the
    /// per-step decay exp(−step_ms/τ) in Q30, 0 = none (< 2^30); `None` in
    /// older images: no direction is filtered.
    pub output_decay_q30: Option<[u32; MAX_DIRECTIONS]>,
    /// Precomputed from the ranges at parse time (not stored in the image).
    /// Each input's envelope in Q8 of its raw unit, with its Q24 mapping.
    pub(crate) input_span: [Span; MAX_INPUTS],
    pub(crate) axis_span: [Span; MAX_AXES],
    /// Each axis's reference position, normalised (Q24); constant per model.
    pub(crate) axis_ref_q24: [i32; MAX_AXES],
    /// CRC-32 of the image this model came from (set by parse/encode).
    pub crc: u32,
}

impl Model {
    /// An empty model (no sensors, no outputs) to fill in and [`Model::encode`].
    // Inlined wherever it is called, so that a model built into its place
    // (a board's static app) is written there, not built on the stack and
    // copied (17 KB; `scripts/size.sh` measures it).
    #[inline(always)]
    pub fn empty(model_version: u32, step_ms: u32) -> Self {
        Model {
            flags: 0,
            model_version,
            step_ms,
            warmup_s: 0,
            sensors: Vec::new(),
            directions: Vec::new(),
            axes: Vec::new(),
            inputs: Vec::new(),
            nets: Vec::new(),
            tables: Vec::new(),
            fallbacks: Vec::new(),
            fallback_terms: Vec::new(),
            volumetric: None,
            five_axis: None,
            envelope: None,
            output_decay_q30: None,
            input_span: [Span::default(); MAX_INPUTS],
            axis_span: [Span::default(); MAX_AXES],
            axis_ref_q24: [0; MAX_AXES],
            crc: 0,
        }
    }

    /// [`Model::empty`] in place (no copy of a model on the stack).
    pub fn clear(&mut self, model_version: u32, step_ms: u32) {
        self.flags = 0;
        self.model_version = model_version;
        self.step_ms = step_ms;
        self.warmup_s = 0;
        self.sensors.clear();
        self.directions.clear();
        self.axes.clear();
        self.inputs.clear();
        self.nets.clear();
        self.tables.clear();
        self.fallbacks.clear();
        self.fallback_terms.clear();
        self.volumetric = None;
        self.five_axis = None;
        self.envelope = None;
        self.output_decay_q30 = None;
        self.input_span = [Span::default(); MAX_INPUTS];
        self.axis_span = [Span::default(); MAX_AXES];
        self.axis_ref_q24 = [0; MAX_AXES];
        self.crc = 0;
    }

    /// The terms of fallback `k` (0-based).
    pub fn fallback_terms_of(&self, k: usize) -> &[Term] {
        match self.fallbacks.get(k) {
            Some(f) => {
                let a = usize::from(f.first_term);
                self.fallback_terms
                    .get(a..a + usize::from(f.n_terms))
                    .unwrap_or(&[])
            }
            None => &[],
        }
    }

    /// Bit i: the main model of `direction` reads input i.
    pub fn main_input_mask(&self, direction: usize) -> u16 {
        let nets = self
            .nets
            .iter()
            .filter(|n| usize::from(n.direction) == direction)
            .fold(0, |m, n| m | input_mask(n.inputs.iter().copied()));
        self.tables
            .iter()
            .filter(|t| usize::from(t.direction) == direction)
            .fold(nets, |m, t| m | input_mask(t.terms.iter().map(|x| x.input)))
    }

    /// Add a fallback (desktop side; the parser checks it when the image is read back).
    pub fn push_fallback(
        &mut self,
        direction: u8,
        excluded: [u8; 2],
        terms: &[Term],
    ) -> Result<(), ImageError> {
        let too_many = ImageError::TooMany {
            what: "fallback terms",
            count: terms.len(),
            max: MAX_TERMS,
        };
        // The image stores a fallback's term count in a byte.
        let n_terms = u8::try_from(terms.len()).map_err(|_| too_many)?;
        let first_term = u16::try_from(self.fallback_terms.len()).map_err(|_| too_many)?;
        for t in terms {
            push(&mut self.fallback_terms, *t)?;
        }
        push(
            &mut self.fallbacks,
            Fallback {
                direction,
                excluded,
                first_term,
                n_terms,
                input_mask: input_mask(terms.iter().map(|t| t.input)),
            },
        )
    }

    /// Bit d: direction d's envelope policy is
    /// [`EnvelopeMode::Extrapolate`](super::types::EnvelopeMode) (0 without
    /// the policy section).
    pub fn extrapolate_mask(&self) -> u8 {
        let Some(policies) = &self.envelope else {
            return 0;
        };
        policies
            .iter()
            .take(self.directions.len())
            .enumerate()
            .filter(|(_, p)| p.mode == EnvelopeMode::Extrapolate)
            .fold(0, |m, (d, _)| m | (1 << d))
    }

    /// Directions' names as text (ASCII, zero padding dropped).
    pub fn direction_name(&self, i: usize) -> &str {
        self.directions
            .get(i)
            .map(|d| name_str(&d.name))
            .unwrap_or("")
    }

    pub fn axis_name(&self, i: usize) -> &str {
        self.axes.get(i).map(|a| name_str(&a.name)).unwrap_or("")
    }
}

/// Bit i set for every input index i (NONE and out-of-range indices ignored).
pub(super) fn input_mask(inputs: impl Iterator<Item = u8>) -> u16 {
    inputs
        .filter(|&i| usize::from(i) < MAX_INPUTS)
        .fold(0u16, |m, i| m | (1 << i))
}

//! The records a model is made of (sensors, directions, axes, inputs,
//! networks, tables, fallbacks), as the parser validates and the encoder
//! writes them.

use crate::limits::{MAX_HIDDEN, MAX_NET_INPUTS, MAX_TERMS};
use heapless::Vec;

/// Sensor identity: a DS18B20 ROM code, or (ROM all zero) a channel index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensorRef {
    pub rom: [u8; 8],
    pub channel: u8,
    /// Reference temperature (1/16 °C) used with `FLAG_FIXED_REFERENCE`.
    pub ref_temp: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Direction {
    pub name: [u8; 8],
    /// Largest correction served, 0.1 µm (absolute value).
    pub max_correction: i32,
    /// Largest change of the served correction, 0.1 µm per second.
    pub max_rate: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Axis {
    pub name: [u8; 8],
    pub pos_min: i32,
    pub pos_max: i32,
    /// Reference position of the offset/slope pair (TEMP_COMP style).
    pub ref_pos: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InputKind {
    /// Temperature of sensor `a` minus its reference sample (1/16 °C).
    SensorRise { a: u8 },
    /// Temperature of sensor `a` minus sensor `b` (1/16 °C).
    SensorDiff { a: u8, b: u8 },
    /// Spindle speed written by the PLC (rpm).
    Spindle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputSpec {
    pub kind: InputKind,
    /// First-order lag: time constant (documentation and the quantizer's
    /// source) and its per-step decay exp(−step/τ) in Q30. `None`: no lag.
    pub lag: Option<Lag>,
    /// Training envelope, raw units.
    pub min: i32,
    pub max: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lag {
    pub tau_s: u32,
    pub decay_q30: u32,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Net {
    pub direction: u8,
    pub inputs: Vec<u8, MAX_NET_INPUTS>,
    pub n_hidden: u8,
    pub w1: [[i32; MAX_NET_INPUTS]; MAX_HIDDEN],
    pub b1: [i32; MAX_HIDDEN],
    pub w2: [i32; MAX_HIDDEN],
    pub b2: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Term {
    pub coef: i32,
    /// Index into the model's inputs, or `NONE`.
    pub input: u8,
    pub input_power: u8,
    pub position_power: u8,
}

/// A fallback model (format v2, section kind 1): serves `direction` when
/// the main model's sensors are not all valid, without `excluded`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fallback {
    pub direction: u8,
    /// The sensors it does without (model sensor indices; `NONE`: unused slot).
    pub excluded: [u8; 2],
    /// Its terms: `Model::fallback_terms[first_term .. first_term + n_terms]`
    /// (a static polynomial table, position power 0).
    pub first_term: u16,
    pub n_terms: u8,
    /// Bit i: it reads model input i (computed at parse time).
    pub input_mask: u16,
}

/// What a direction serves when an input its model reads leaves the
/// training envelope (section kind 5, format v3, and v4 for
/// [`EnvelopeMode::Extrapolate`]; images without it: hold, margin 0, the
/// rule before the section existed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EnvelopePolicy {
    pub mode: EnvelopeMode,
    /// Raw units of each input (1/16 °C for temperatures, rpm for the
    /// spindle speed) an input may leave its range by before it counts as
    /// beyond the envelope.
    pub margin: u16,
}

/// A direction's envelope policy (section kind 5's code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EnvelopeMode {
    /// Code 0: every input held at the edge of its range.
    #[default]
    Hold,
    /// Code 1: an input beyond its range by more than the margin is treated
    /// as a faulted sensor: the direction is served by its first fallback
    /// without the sensors that input reads (held as before when there is none).
    Fallback,
    /// Code 2 (format v4): the inputs of the (linear) model serving the
    /// direction continue linearly up to
    /// [`EXTRAPOLATE_WIDTHS`](crate::limits::EXTRAPOLATE_WIDTHS) training
    /// widths beyond each edge of their range and are held at that outer edge
    /// beyond; the step counts and is flagged as under hold.
    Extrapolate,
}

impl EnvelopeMode {
    /// The policy's name as the fit file and the reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            EnvelopeMode::Hold => "hold",
            EnvelopeMode::Fallback => "fallback",
            EnvelopeMode::Extrapolate => "extrapolate",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    pub direction: u8,
    /// Axis whose position enters the terms, or `NONE`.
    pub axis: u8,
    pub terms: Vec<Term, MAX_TERMS>,
}

impl Net {
    pub fn new(direction: u8, inputs: &[u8], n_hidden: u8) -> Self {
        let mut v = Vec::new();
        for &i in inputs.iter().take(MAX_NET_INPUTS) {
            let _ = v.push(i);
        }
        Net {
            direction,
            inputs: v,
            n_hidden,
            w1: [[0; MAX_NET_INPUTS]; MAX_HIDDEN],
            b1: [0; MAX_HIDDEN],
            w2: [0; MAX_HIDDEN],
            b2: 0,
        }
    }
}

/// An 8-byte zero-padded ASCII name from text (longer names are cut at 8 bytes).
pub fn name8(s: &str) -> [u8; 8] {
    let mut n = [0u8; 8];
    for (d, c) in n.iter_mut().zip(s.bytes()) {
        *d = c;
    }
    n
}

/// A name's text: up to its first zero byte ("?" if that is not UTF-8).
pub(super) fn name_str(n: &[u8; 8]) -> &str {
    let end = n.iter().position(|&c| c == 0).unwrap_or(8);
    n.get(..end)
        .and_then(|s| core::str::from_utf8(s).ok())
        .unwrap_or("?")
}

//! One evaluation of a validated model: networks and polynomial tables for
//! one set of feature values. Stateless; the [`crate::compensator`] keeps the
//! state (reference, filters, limits) around it.

use crate::fixed::{mul_q24, round_shift, sigmoid_q17, FEATURE_FRAC_BITS, ONE_Q24};
use crate::image::{InputKind, Model, Net, Table, NONE};
use crate::limits::*;

/// The model's raw outputs before limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Evaluation {
    /// Predicted thermal error per direction, 0.1 µm.
    pub corrections: [i32; MAX_DIRECTIONS],
    /// Per axis: TEMP_COMP offset at the reference position (0.1 µm) and slope (0.01 µm/m).
    pub axes: [AxisPair; MAX_AXES],
    /// Some input or position was outside the training envelope and was held at its edge.
    pub out_of_envelope: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AxisPair {
    /// Position-independent part: the error at the reference position, 0.1 µm.
    pub offset: i32,
    /// Position-dependent part about the reference position, 0.01 µm/m.
    pub slope: i32,
    pub ref_pos: i32,
}

/// Normalised (Q24, clamped to the envelope) model inputs and positions.
#[derive(Debug, Clone, Copy)]
pub struct Normalised {
    pub x: [i32; MAX_INPUTS],
    pub p: [i32; MAX_AXES],
    pub p_ref: [i32; MAX_AXES],
    pub outside: bool,
}

impl Model {
    /// Normalise feature values (Q8 of raw units, one per model input) and
    /// axis positions (µm, one per model axis; missing ones count as the
    /// reference position).
    pub fn normalise(&self, features_q8: &[i32], positions: &[i32]) -> Normalised {
        let mut n = Normalised {
            x: [0; MAX_INPUTS],
            p: [0; MAX_AXES],
            p_ref: self.axis_ref_q24,
            outside: false,
        };
        // Over exactly the model's inputs: a tight loop. (A missing feature
        // leaves its input at the envelope's centre.)
        let k = self.inputs.len().min(MAX_INPUTS).min(features_q8.len());
        let mut outside = false;
        #[allow(
            clippy::indexing_slicing,
            reason = "k <= MAX_INPUTS = x.len() = input_span.len(), k <= features_q8.len()"
        )]
        for ((x, &v), span) in n.x[..k]
            .iter_mut()
            .zip(&features_q8[..k])
            .zip(&self.input_span[..k])
        {
            let (xv, out) = span.normalise(v);
            *x = xv;
            outside |= out;
        }
        let a_n = self.axes.len().min(MAX_AXES);
        #[allow(
            clippy::indexing_slicing,
            reason = "a_n <= MAX_AXES = p.len() = axis_span.len()"
        )]
        for (a, ((p, span), axis)) in n.p[..a_n]
            .iter_mut()
            .zip(&self.axis_span[..a_n])
            .zip(&self.axes)
            .enumerate()
        {
            let pos = positions.get(a).copied().unwrap_or(axis.ref_pos);
            let (pv, out) = span.normalise(pos);
            *p = pv;
            outside |= out;
        }
        n.outside = outside;
        n
    }

    /// Evaluate every network and table (see [`crate::fixed`] for the Q
    /// formats), and each axis's TEMP_COMP offset/slope pair.
    pub fn evaluate(&self, features_q8: &[i32], positions: &[i32]) -> Evaluation {
        let n = self.normalise(features_q8, positions);
        let mut e = self.corrections_at(&n);
        if self.tables.iter().any(|t| t.axis != NONE) {
            self.axis_pairs(&n, &mut e.axes);
        }
        e
    }

    /// The corrections only (networks and all tables at the current
    /// positions), without the offset/slope pairs.
    pub fn evaluate_corrections(&self, features_q8: &[i32], positions: &[i32]) -> Evaluation {
        self.corrections_at(&self.normalise(features_q8, positions))
    }

    fn corrections_at(&self, n: &Normalised) -> Evaluation {
        let mut e = Evaluation {
            out_of_envelope: n.outside,
            ..Evaluation::default()
        };
        // One Q25 accumulator per direction, rounded once: networks (< 2^53
        // each) and tables (Q32 → Q25, < 2^53 each) add without overflow.
        let mut acc = [0i64; MAX_DIRECTIONS];
        for net in &self.nets {
            if let Some(a) = acc.get_mut(usize::from(net.direction)) {
                *a += eval_net_q25(net, &n.x);
            }
        }
        for t in &self.tables {
            let p = n.p.get(usize::from(t.axis)).copied();
            let value = match (t.axis == NONE, p) {
                (false, Some(p)) => eval_table_at(t, &n.x, p),
                _ => eval_table_static(&t.terms, &n.x),
            };
            if let Some(acc) = acc.get_mut(usize::from(t.direction)) {
                *acc += round_shift(value, 7);
            }
        }
        let n_dir = self.directions.len().min(MAX_DIRECTIONS);
        #[allow(
            clippy::indexing_slicing,
            reason = "n_dir <= MAX_DIRECTIONS = corrections.len() = acc.len()"
        )]
        for (c, &a) in e.corrections[..n_dir].iter_mut().zip(&acc[..n_dir]) {
            *c = sat_i32(round_shift(a, 25));
        }
        for (pair, axis) in e.axes.iter_mut().zip(&self.axes) {
            pair.ref_pos = axis.ref_pos;
        }
        e
    }

    /// Bit i: input i's feature (Q8 of its raw unit) lies outside its
    /// training range by more than `margin` raw units (the envelope policy,
    /// [`crate::image::EnvelopePolicy`]).
    pub fn beyond_mask(&self, features_q8: &[i32], margin: u16) -> u16 {
        let m = i64::from(margin) << FEATURE_FRAC_BITS;
        let mut mask = 0u16;
        for (i, (&v, span)) in features_q8
            .iter()
            .zip(&self.input_span)
            .enumerate()
            .take(self.inputs.len())
        {
            let v = i64::from(v);
            if v < i64::from(span.lo) - m || v > i64::from(span.hi) + m {
                mask |= 1 << i;
            }
        }
        mask
    }

    /// `mask` and every input that reads a sensor an input of `mask` reads:
    /// the inputs a fault of those sensors would make invalid.
    pub fn sensor_closure(&self, mask: u16) -> u16 {
        let sensors_of = |kind: InputKind| -> u32 {
            let bit = |s: u8| 1u32.checked_shl(u32::from(s)).unwrap_or(0);
            match kind {
                InputKind::SensorRise { a } => bit(a),
                InputKind::SensorDiff { a, b } => bit(a) | bit(b),
                InputKind::Spindle => 0,
            }
        };
        let inputs = self.inputs.iter().take(16).enumerate();
        let faulted = inputs
            .clone()
            .filter(|(i, _)| mask & (1 << i) != 0)
            .fold(0u32, |s, (_, inp)| s | sensors_of(inp.kind));
        inputs
            .filter(|(_, inp)| sensors_of(inp.kind) & faulted != 0)
            .fold(mask, |m, (i, _)| m | (1 << i))
    }

    /// The inputs normalised over their extended spans (envelope policy
    /// `extrapolate`, [`crate::fixed::Span::normalise_extended`]: Q24 within
    /// ±(1 + 2·[`EXTRAPOLATE_WIDTHS`])); positions left at 0, as the models
    /// such a direction may have read none (checked at parse).
    pub fn normalise_extended(&self, features_q8: &[i32]) -> Normalised {
        let mut n = Normalised {
            x: [0; MAX_INPUTS],
            p: [0; MAX_AXES],
            p_ref: self.axis_ref_q24,
            outside: false,
        };
        for ((x, &v), span) in
            n.x.iter_mut()
                .zip(features_q8)
                .zip(&self.input_span)
                .take(self.inputs.len())
        {
            *x = span.normalise_extended(v);
            n.outside |= v < span.lo || v > span.hi;
        }
        n
    }

    /// Direction `d`'s main correction (0.1 µm) from its static tables
    /// alone, rounded as [`Model::evaluate`] rounds it: the whole main model
    /// of an extrapolating direction (no network, no axis table: checked at
    /// parse), so on the same inputs the very same value.
    pub fn static_correction(&self, d: usize, n: &Normalised) -> i32 {
        let acc: i64 = self
            .tables
            .iter()
            .filter(|t| usize::from(t.direction) == d)
            .map(|t| static_q25(&t.terms, &n.x))
            .sum();
        sat_i32(round_shift(acc, 25))
    }

    /// Fallback `k`'s correction (0.1 µm), rounded once as the main model's.
    pub fn fallback_correction(&self, k: usize, n: &Normalised) -> i32 {
        sat_i32(round_shift(static_q25(self.fallback_terms_of(k), &n.x), 25))
    }

    /// Per axis, the TEMP_COMP pair of its position-dependent tables: the
    /// value at the reference position (offset) and d/dp there (slope).
    fn axis_pairs(&self, n: &Normalised, axes: &mut [AxisPair; MAX_AXES]) {
        for (a, ((axis, span), pair)) in self
            .axes
            .iter()
            .zip(&self.axis_span)
            .zip(axes.iter_mut())
            .enumerate()
        {
            let p_ref = n.p_ref.get(a).copied().unwrap_or(0);
            // Both sums ≤ 2^61: the parser's MAX_AXIS_TABLE_WEIGHT (fixed.rs).
            let (mut off, mut der, mut any) = (0i64, 0i64, false);
            for t in self.tables.iter().filter(|t| usize::from(t.axis) == a) {
                let (o, d) = eval_table_pair(t, &n.x, p_ref);
                off += o;
                der += d;
                any = true;
            }
            if !any {
                continue;
            }
            // dE/dp in Q8 of 0.1 µm per half span; slope = dE/dp · 0.1 µm / (span/2 µm)
            // in 0.01 µm/m = dE/dp · 2·10^7 / span = der_q8 · 78125 / span
            // (the parser bounds |der| ≤ 2^61, so |der_q8| ≤ 2^37 and the
            // numerator < 2^54; see fixed.rs), divided by
            // multiplying with the span's reciprocal (no 64-bit division).
            let der_q8 = round_shift(der, 24);
            *pair = AxisPair {
                offset: sat_i32(round_shift(off, 32)),
                slope: sat_i32(span.divide(der_q8 * 78_125)),
                ref_pos: axis.ref_pos,
            };
        }
    }
}

/// One network: Q24 inputs → Q25 accumulator of 0.1 µm. Kept out of line:
/// its own register allocation keeps the inner loop at load-load-SMLAL.
#[inline(never)]
#[allow(
    clippy::indexing_slicing,
    reason = "n_in <= MAX_NET_INPUTS = xs.len() = row.len(), h <= MAX_HIDDEN = w1.len() = b1.len() = w2.len()"
)]
pub fn eval_net_q25(net: &Net, x: &[i32; MAX_INPUTS]) -> i64 {
    // Gather the network's inputs once so the inner loop is load-load-SMLAL.
    let n_in = net.inputs.len().min(MAX_NET_INPUTS);
    let mut xs = [0i32; MAX_NET_INPUTS];
    for (dst, &i) in xs.iter_mut().zip(net.inputs.iter()) {
        *dst = x.get(usize::from(i)).copied().unwrap_or(0);
    }
    let xs = &xs[..n_in];
    let mut out: i64 = i64::from(net.b2) << 17;
    let h = usize::from(net.n_hidden).min(MAX_HIDDEN);
    for ((row, &b1), &w2) in net.w1[..h].iter().zip(&net.b1[..h]).zip(&net.w2[..h]) {
        let mut acc: i64 = i64::from(b1) << 24;
        for (&w, &xi) in row[..n_in].iter().zip(xs) {
            acc += i64::from(w) * i64::from(xi);
        }
        let h = sigmoid_q17(round_shift(acc, 24));
        out += i64::from(w2) * i64::from(h);
    }
    out
}

/// A table without a position (every term's position power is 0): its Q32
/// accumulator (0.1 µm).
fn eval_table_static(terms: &[crate::image::Term], x: &[i32; MAX_INPUTS]) -> i64 {
    let mut value = 0i64;
    for term in terms {
        let xpow = match (x.get(usize::from(term.input)), term.input_power) {
            (Some(&xi), 1) => xi,
            (Some(&xi), k) => {
                let mut v = ONE_Q24;
                for _ in 0..k {
                    v = mul_q24(v, xi);
                }
                v
            }
            (None, _) => ONE_Q24,
        };
        value += i64::from(term.coef) * i64::from(xpow);
    }
    value
}

/// A static table's value rounded to the Q25 accumulator (0.1 µm), as
/// [`Model::evaluate`] adds it: fallbacks and extrapolating directions.
/// Out of line: one copy for both (flash).
#[inline(never)]
fn static_q25(terms: &[crate::image::Term], x: &[i32; MAX_INPUTS]) -> i64 {
    round_shift(eval_table_static(terms, x), 7)
}

/// Powers 0..=3 of a Q24 value.
fn powers(v: i32) -> [i32; 4] {
    let v2 = mul_q24(v, v);
    [ONE_Q24, v, v2, mul_q24(v2, v)]
}

/// A term's input power (Q24).
fn input_power(term: &crate::image::Term, x: &[i32; MAX_INPUTS]) -> i32 {
    let mut xpow = ONE_Q24;
    if let Some(&xi) = x.get(usize::from(term.input)) {
        for _ in 0..term.input_power {
            xpow = mul_q24(xpow, xi);
        }
    }
    xpow
}

/// One position-dependent table's Q32 accumulator (0.1 µm) at position `p` (Q24).
fn eval_table_at(t: &Table, x: &[i32; MAX_INPUTS], p: i32) -> i64 {
    let pp = powers(p);
    let mut value = 0i64;
    for term in &t.terms {
        let k = usize::from(term.position_power).min(3);
        #[allow(clippy::indexing_slicing, reason = "k <= 3 < pp.len() = 4")]
        let pk = pp[k];
        value += i64::from(term.coef) * i64::from(mul_q24(input_power(term, x), pk));
    }
    value
}

/// A table's value and d/dp at `p_ref` (Q32 accumulators).
#[allow(
    clippy::indexing_slicing,
    reason = "k <= 3 < pr.len() = 4, k - 1 only when k > 0"
)]
fn eval_table_pair(t: &Table, x: &[i32; MAX_INPUTS], p_ref: i32) -> (i64, i64) {
    let pr = powers(p_ref);
    let (mut off, mut der) = (0i64, 0i64);
    for term in &t.terms {
        let xpow = input_power(term, x);
        let k = usize::from(term.position_power).min(3);
        let coef = i64::from(term.coef);
        off += coef * i64::from(mul_q24(xpow, pr[k]));
        if k > 0 {
            // k ≤ 3, so coef·k < 2^33 and the product < 2^57.
            der += coef * k as i64 * i64::from(mul_q24(xpow, pr[k - 1]));
        }
    }
    (off, der)
}

#[inline(always)]
#[allow(
    clippy::cast_possible_truncation,
    reason = "clamped to the i32 range first"
)]
fn sat_i32(v: i64) -> i32 {
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

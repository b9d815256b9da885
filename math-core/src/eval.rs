//! One evaluation of a validated model: networks and polynomial tables for
//! one set of feature values. Stateless; the [`crate::compensator`] keeps the
//! state (reference, filters, limits) around it.

use crate::fixed::{mul_q24, normalise_q24, round_shift, sigmoid_q17, ONE_Q24};
use crate::image::{Model, Net, Table, NONE};
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
    /// Normalise feature values (Q16 of raw units, one per model input) and
    /// axis positions (µm, one per model axis; missing ones count as the
    /// reference position).
    pub fn normalise(&self, features_q16: &[i64], positions: &[i32]) -> Normalised {
        let mut n = Normalised {
            x: [0; MAX_INPUTS],
            p: [0; MAX_AXES],
            p_ref: [0; MAX_AXES],
            outside: false,
        };
        for (i, inp) in self.inputs.iter().enumerate() {
            let v = features_q16.get(i).copied().unwrap_or(0);
            let (x, out) = normalise_q24(v, inp.min, inp.max, self.input_gain_q40[i]);
            n.x[i] = x;
            n.outside |= out;
        }
        for (a, axis) in self.axes.iter().enumerate() {
            let g = self.axis_gain_q40[a];
            let pos = positions.get(a).copied().unwrap_or(axis.ref_pos);
            let (p, out) = normalise_q24(i64::from(pos) << 16, axis.pos_min, axis.pos_max, g);
            n.p[a] = p;
            n.outside |= out;
            n.p_ref[a] =
                normalise_q24(i64::from(axis.ref_pos) << 16, axis.pos_min, axis.pos_max, g).0;
        }
        n
    }

    /// Evaluate every network and table (see [`crate::fixed`] for the Q formats).
    pub fn evaluate(&self, features_q16: &[i64], positions: &[i32]) -> Evaluation {
        let n = self.normalise(features_q16, positions);
        let mut e = Evaluation {
            out_of_envelope: n.outside,
            ..Evaluation::default()
        };
        // One Q25 accumulator per direction, rounded once: networks (< 2^53
        // each) and tables (Q32 → Q25, < 2^53 each) add without overflow.
        let mut acc = [0i64; MAX_DIRECTIONS];
        for net in &self.nets {
            acc[usize::from(net.direction)] += eval_net_q25(net, &n.x);
        }
        for t in &self.tables {
            let p = if t.axis == NONE {
                0
            } else {
                n.p[usize::from(t.axis)]
            };
            acc[usize::from(t.direction)] += round_shift(eval_table(t, &n.x, p, false), 7);
        }
        for (c, a) in e.corrections.iter_mut().zip(acc) {
            *c = sat_i32(round_shift(a, 25));
        }
        for (a, axis) in self.axes.iter().enumerate() {
            let (mut off, mut der) = (0i64, 0i64);
            for t in self.tables.iter().filter(|t| usize::from(t.axis) == a) {
                off += eval_table(t, &n.x, n.p_ref[a], false);
                der += eval_table(t, &n.x, n.p_ref[a], true);
            }
            let span = i64::from(axis.pos_max) - i64::from(axis.pos_min);
            // dE/dp in Q8 of 0.1 µm per half span; slope = dE/dp · 0.1 µm / (span/2 µm)
            // in 0.01 µm/m = dE/dp · 2·10^7 / span. |der_q8| < 2^36, ·2·10^7 < 2^61.
            let der_q8 = round_shift(der, 24);
            let slope = (der_q8 * 20_000_000 + (span << 7)) / (span << 8);
            e.axes[a] = AxisPair {
                offset: sat_i32(round_shift(off, 32)),
                slope: sat_i32(slope),
                ref_pos: axis.ref_pos,
            };
        }
        e
    }
}

/// One network: Q24 inputs → Q25 accumulator of 0.1 µm.
#[inline]
pub fn eval_net_q25(net: &Net, x: &[i32; MAX_INPUTS]) -> i64 {
    let n_in = net.inputs.len();
    let mut out: i64 = i64::from(net.b2) << 17;
    for j in 0..usize::from(net.n_hidden).min(MAX_HIDDEN) {
        let mut acc: i64 = i64::from(net.b1[j]) << 24;
        for k in 0..n_in {
            let xi = x[usize::from(net.inputs[k]) % MAX_INPUTS];
            acc += i64::from(net.w1[j][k]) * i64::from(xi);
        }
        let h = sigmoid_q17(round_shift(acc, 24));
        out += i64::from(net.w2[j]) * i64::from(h);
    }
    out
}

/// One table's Q32 accumulator (0.1 µm) at position `p` (Q24). With
/// `derivative`, d/dp of the table instead.
fn eval_table(t: &Table, x: &[i32; MAX_INPUTS], p: i32, derivative: bool) -> i64 {
    let mut acc = 0i64;
    for term in &t.terms {
        let mut prod = ONE_Q24;
        let mut coef = i64::from(term.coef);
        let mut pp = term.position_power;
        if derivative {
            if pp == 0 {
                continue;
            }
            coef *= i64::from(pp);
            pp -= 1;
        }
        if term.input != NONE {
            let xi = x[usize::from(term.input) % MAX_INPUTS];
            for _ in 0..term.input_power {
                prod = mul_q24(prod, xi);
            }
        }
        for _ in 0..pp {
            prod = mul_q24(prod, p);
        }
        acc += coef * i64::from(prod);
    }
    acc
}

#[inline(always)]
fn sat_i32(v: i64) -> i32 {
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

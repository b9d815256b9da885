//! Fixed-point formats and primitives.
//!
//! | quantity                         | type | format                          |
//! |----------------------------------|------|---------------------------------|
//! | temperature (rise)               | i32  | 1/16 °C (DS18B20 LSB)           |
//! | spindle speed                    | i32  | rpm                             |
//! | axis position                    | i32  | µm (or 0.001°)                  |
//! | lag-filter state                 | i64  | Q16 of the raw unit             |
//! | filter decay exp(-step/τ)        | u32  | Q30, < 1                        |
//! | model input feature              | i32  | Q8 of the raw unit (±2^23 raw)  |
//! | normalised input / position      | i32  | Q24, in [-1, 1] after clamping  |
//! | hidden weights W1, biases b1     | i32  | Q16 (|w| < 32768)               |
//! | pre-activation z                 | i64  | Q40 accumulator → Q16           |
//! | hidden activation h              | i32  | Q17, in [0, 1]                  |
//! | output weights w2, b2, table coef| i32  | Q8 of 0.1 µm                    |
//! | output accumulator               | i64  | Q25 (net) / Q32 (table) of 0.1 µm |
//! | correction                       | i32  | 0.1 µm                          |
//!
//! Why nothing overflows: normalised values are clamped to [-1, 1] (|x| ≤ 2^24)
//! before any product. A W1·x product is ≤ 2^31·2^24 = 2^55 and at most
//! MAX_NET_INPUTS = 8 of them plus the bias (< 2^55) sum below 2^59 < 2^63.
//! h ≤ 2^17, so a w2·h product is ≤ 2^48 and 17 of them (with b2 << 17) stay
//! below 2^53. A table term is a Q24 product of at most six factors each ≤ 1
//! (renormalised after every multiply, so ≤ 2^24) times a coefficient ≤ 2^31:
//! ≤ 2^55, and MAX_TERMS = 32 of them stay ≤ 2^60 (one table's Q32 value).
//! Per direction, `eval` adds MAX_NETS = 4 networks (< 2^53) and MAX_TABLES =
//! 8 tables rounded Q32 → Q25 (≤ 2^53): below 2^57, for any image.
//!
//! The TEMP_COMP pair sums every table of one axis in Q32: the offset
//! Σ coef·x^i·p^k and the derivative Σ coef·k·x^i·p^(k−1). Without a further
//! bound that is 8 tables · 32 terms · 3 · 2^55 = 3·2^63, which overflows i64
//! (found by issue 13). It is **bounded in the parser**, not widened: the
//! image parser refuses an image whose tables on one axis have
//! Σ |coef| · max(1, k) > MAX_AXIS_TABLE_WEIGHT = 2^37
//! (`ImageError::TableSumTooLarge`), so both sums are ≤ 2^37·2^24 = 2^61 and
//! their rounding (+2^31) cannot overflow; d/dp in Q8 is then ≤ 2^37 and
//! times 78,125 < 2^54 for [`Span::divide`]. Why not i128: the pair is
//! evaluated at every step on the Cortex-M4 within the ≤ 2,000-instruction
//! budget, and 2^37 in Q8 of 0.1 µm is 53 m of correction, far beyond any
//! model the quantizer emits, so the bound refuses only broken images.
//! `math-core/tests/image.rs` evaluates an image at the bound, at the input
//! extremes, with overflow checks on. Filter states are bounded by the
//! inputs they follow (|raw| < 2^31, Q16 → < 2^47); the decay is < 1. The
//! filtered feature is handed to the model as Q8 in an i32, saturated; the
//! image limits every input's envelope to ±2^23 raw units, so the clamp to
//! the envelope happens before anything saturates matters. The envelope
//! mapping ([`Span`]) multiplies a value < 2^32 by a gain ≤ 2^26.
//!
//! A direction under the envelope policy `extrapolate` (image format v4)
//! has its inputs normalised over the extended span
//! ([`Span::normalise_extended`]): |x| ≤ (1 + 2W)·2^24 = 5·2^24 < 2^27
//! (W = [`EXTRAPOLATE_WIDTHS`] = 2). The parser lets such a direction be
//! served only by linear static tables (input power ≤ 1, position power 0),
//! so each term is coef·x with no Q24 product of two extended values: one
//! term ≤ 2^31·5·2^24 < 2^58.4, and MAX_TERMS = 32 of them < 5·2^60 < 2^63
//! even for coefficients at i32's limit (the prediction bound, checked over
//! the extended span, keeps the sum far lower: ≤ 2^25·2^24 = 2^49). The
//! tables' Q32 → Q25 rounding and the per-direction sum are then as above.
//!
//! The volumetric section (image kind 3) has its own formats and overflow
//! argument in [`crate::volumetric`]: Q24 variables in [0, 1], coefficients
//! in pm, an i64 accumulator in 1/16 pm bounded by 2^52.

use crate::limits::EXTRAPOLATE_WIDTHS;

include!(concat!(env!("OUT_DIR"), "/sigmoid_table.rs"));

/// One in Q24 (normalised inputs and positions).
pub const ONE_Q24: i32 = 1 << 24;
/// One in Q17 (hidden activations).
pub const ONE_Q17: i32 = 1 << 17;
/// Table step of the sigmoid: 1/32 in Q16.
const SIG_STEP_SHIFT: u32 = 11;
/// Sigmoid input saturation: |z| ≥ 16 gives 0 or 1 (error < 1.2e-7, below the Q17 LSB).
const SIG_Z_MAX_Q16: i64 = 16 << 16;

/// Worst-case |sigmoid_q17(z)/2^17 − σ(z)| over all z, checked densely by a
/// test: linear interpolation at step 1/32 (≤ h²/8·max|σ''| = 1.2e-5) plus
/// the table's Q17 rounding (3.8e-6) and the interpolation's truncation (7.6e-6).
pub const SIGMOID_MAX_ERROR: f64 = 2.5e-5;

/// Logistic sigmoid of `z_q16` (Q16) in Q17, by table and linear interpolation.
/// Symmetric: σ(−z) = 1 − σ(z). Total for every i64.
#[inline]
#[allow(
    clippy::cast_possible_truncation,
    clippy::indexing_slicing,
    reason = "mag <= 16 << 16 fits u32; indices are capped at 512 < SIGMOID_Q17.len() = 513"
)]
pub fn sigmoid_q17(z_q16: i64) -> i32 {
    let mag = z_q16.unsigned_abs().min(SIG_Z_MAX_Q16 as u64) as u32;
    let idx = (mag >> SIG_STEP_SHIFT) as usize;
    let frac = (mag & ((1 << SIG_STEP_SHIFT) - 1)) as i32;
    // idx ≤ 512; at idx == 512 frac is 0 and the next entry is not needed.
    let lo = i32::from(SIGMOID_Q17[idx.min(512)]);
    let hi = i32::from(SIGMOID_Q17[(idx + 1).min(512)]);
    let v = lo + (((hi - lo) * frac) >> SIG_STEP_SHIFT);
    if z_q16 >= 0 {
        ONE_Q17 / 2 + v
    } else {
        ONE_Q17 / 2 - v
    }
}

/// A training range [lo, hi] mapped onto Q24 [-1, 1] in 32-bit
/// arithmetic: x = 2(v − lo)/(hi − lo) − 1. With L the span's bit length,
/// d = v − lo (after clamping) is first scaled to d' = d << (32 − L) < 2^32,
/// then x + 1 = (d' · gain + 2^31) >> 32 with gain = 2^(25+L)/span in
/// (2^25, 2^26]: one UMULL, the high word is the result (≤ 2^25 + 1). The
/// gain's rounding (relative 2^-26) costs at most half an LSB of Q24. The
/// constants are computed once when the model is parsed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Span {
    pub lo: i32,
    pub hi: i32,
    gain: u32,
    pre_shift: u32,
}

impl Span {
    /// `None` unless hi − lo ≥ 2.
    #[allow(clippy::cast_possible_truncation, reason = "gain <= 2^26 (see below)")]
    pub fn new(lo: i32, hi: i32) -> Option<Span> {
        let span = i64::from(hi) - i64::from(lo);
        if span < 2 {
            return None;
        }
        let span = span as u64; // < 2^32
        let bits = 64 - span.leading_zeros(); // 2..=32
        let gain = ((1u64 << (25 + bits)) + span / 2) / span; // in (2^25, 2^26]
        Some(Span {
            lo,
            hi,
            gain: gain as u32,
            pre_shift: 32 - bits,
        })
    }

    /// `a / (hi − lo)` rounded, for |a| < 2^56, by the reciprocal: a · gain
    /// / 2^(25+L) (the gain's relative error 2^-26 stays far below 1 for
    /// the slopes this serves).
    #[allow(
        clippy::cast_possible_truncation,
        reason = "the result is about a / (hi - lo) with |a| < 2^56"
    )]
    pub fn divide(&self, a: i64) -> i64 {
        let bits = 32 - self.pre_shift; // L
        let shift = 25 + bits; // ≤ 57
        let p = i128::from(a) * i128::from(self.gain);
        ((p + (1i128 << (shift - 1))) >> shift) as i64
    }

    /// Normalise `v` to Q24 in [-1, 1]; `true` when `v` was outside [lo, hi]
    /// (held at the edge: the training-envelope rule).
    #[inline(always)]
    pub fn normalise(&self, v: i32) -> (i32, bool) {
        let (c, outside) = if v < self.lo {
            (self.lo, true)
        } else if v > self.hi {
            (self.hi, true)
        } else {
            (v, false)
        };
        let d = (c.wrapping_sub(self.lo) as u32) << self.pre_shift; // < 2^32
        let x = ((u64::from(d) * u64::from(self.gain) + (1 << 31)) >> 32) as i32 - ONE_Q24;
        (x.clamp(-ONE_Q24, ONE_Q24), outside)
    }

    /// [`Span::normalise`]'s mapping over the extended span [lo − W·(hi − lo),
    /// hi + W·(hi − lo)], W = [`EXTRAPOLATE_WIDTHS`]: the line continues
    /// beyond the range and is held at that outer edge, so the result is
    /// Q24 within ±(1 + 2W). Within [lo, hi] it is `normalise`'s value bit
    /// for bit (the same product, non-negative, and the same clamp to ±1).
    /// d = v − lo is clamped to [−W·span, (1 + W)·span] and scaled like
    /// `normalise`'s d' (span << (32 − L) < 2^32), so |d'| < (1 + W)·2^32
    /// < 2^34 and |d'·gain| < 2^60: no overflow in i64.
    #[allow(
        clippy::cast_possible_truncation,
        reason = "clamped to ±(1 + 2W)·2^24 first"
    )]
    pub fn normalise_extended(&self, v: i32) -> i32 {
        let span = i64::from(self.hi) - i64::from(self.lo);
        let d = i64::from(v) - i64::from(self.lo);
        let reach = i64::from(EXTRAPOLATE_WIDTHS) * span;
        let bound = if (0..=span).contains(&d) {
            i64::from(ONE_Q24)
        } else {
            i64::from(ONE_Q24) * (1 + 2 * i64::from(EXTRAPOLATE_WIDTHS))
        };
        // max/min rather than clamp: no panic path even for a span no parser made.
        let d = d.max(-reach).min(span + reach) << self.pre_shift;
        let x = ((d * i64::from(self.gain) + (1 << 31)) >> 32) - i64::from(ONE_Q24);
        x.max(-bound).min(bound) as i32
    }
}

/// Fractional bits of model input features (Q8 of the raw unit): 1/4096 °C
/// for temperatures, 1/256 rpm; raw values stay within ±2^23.
pub const FEATURE_FRAC_BITS: u32 = 8;

/// Multiply two Q24 values (both within [-1, 1]) to Q24, rounding to nearest.
#[inline(always)]
#[allow(
    clippy::cast_possible_truncation,
    reason = "both factors within [-1, 1] Q24: the product is within ±2^24"
)]
pub fn mul_q24(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b) + (1 << 23)) >> 24) as i32
}

/// decay^n in Q30 for a decay in [0, 1) Q30, by square-and-multiply (exact
/// integer steps, so the board and the host agree; n may be any gap length).
#[allow(
    clippy::cast_possible_truncation,
    reason = "result starts at 2^30 and only shrinks (base < 2^30)"
)]
pub fn decay_pow_q30(decay_q30: u32, mut n: u64) -> u32 {
    if n == 1 {
        return decay_q30; // the common case: one step per sample
    }
    let mut result: u64 = 1 << 30;
    let mut base = u64::from(decay_q30);
    while n > 0 && result != 0 {
        if n & 1 == 1 {
            result = (result * base + (1 << 29)) >> 30;
        }
        base = (base * base + (1 << 29)) >> 30;
        n >>= 1;
    }
    result as u32
}

/// First-order lag with zero-order-hold input: after `n` filter steps at input
/// `u`, y ← u + d^n (y − u). State and input in Q16 of the raw unit.
#[inline]
pub fn lag_update(y_q16: i64, u_q16: i64, decay_n_q30: u32) -> i64 {
    let diff = y_q16 - u_q16;
    u_q16 + mul_q30_i64(diff, decay_n_q30)
}

/// a · d / 2^30 for |a| < 2^62 and d ≤ 2^30 without overflow, rounding to
/// nearest. Split as a = hi·2^30 + lo (0 ≤ lo < 2^30) so both partial products
/// fit in i64; the result equals ⌊(a·d + 2^29) / 2^30⌋ exactly, no i128 needed.
#[inline]
fn mul_q30_i64(a: i64, d: u32) -> i64 {
    let d = i64::from(d);
    let hi = a >> 30;
    let lo = a & ((1 << 30) - 1);
    hi * d + ((lo * d + (1 << 29)) >> 30)
}

/// Round a Q-`shift` accumulator to an integer, to nearest (ties up).
#[inline(always)]
pub fn round_shift(acc: i64, shift: u32) -> i64 {
    (acc + (1i64 << (shift - 1))) >> shift
}

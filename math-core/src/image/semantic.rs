//! Semantic limits (issue 30): what a well-formed image may still not ask
//! of the board. The layout checks say an image can be read; these say its
//! numbers are ones `tcomp export` can produce and its predictions stay
//! within a stated bound, so a hostile or broken image (every coefficient
//! at `i32::MAX`, a warm-up of 136 years) is refused before it serves.
//!
//! **Prediction bound, analytically.** The evaluation normalises every
//! input and position to [−1, 1] over its own envelope and holds it at the
//! edge outside (`crate::fixed::Span::normalise`), so the envelope is the
//! whole input space. Over it, a network's output (Q8 of 0.1 µm) lies in
//! `b2 + Σ min(w2, 0) … b2 + Σ max(w2, 0)` (the sigmoid is within [0, 1]),
//! and a table term's in `±|coef|` (every power of a value in [−1, 1] is in
//! [−1, 1]). Per direction the sum of these intervals over its networks
//! and tables, and for each fallback the sum of its terms, must stay
//! within ±[`MAX_PREDICTION`]: a sound bound (no input can leave it), not
//! a tight one (hidden units that cancel are counted apart).
//!
//! **Extrapolating directions** (envelope policy `extrapolate`, format v4):
//! their inputs are normalised over the extended span (each input's range
//! widened by [`EXTRAPOLATE_WIDTHS`] training widths on either side, held at
//! its outer edge beyond), so they reach ±(1 + 2W) = ±5 instead of ±1. Such
//! a direction must be linear in every model that can serve it: no network,
//! no table bound to an axis, every term of its tables and of its fallbacks
//! of input power ≤ 1 and position power 0 (refused otherwise, `BadValue`).
//! The bound then counts a term that reads an input at (1 + 2W)·|coef|
//! (a constant term at |coef|).

use super::error::ImageError;
use super::format::NONE;
use super::model::Model;
use super::types::Term;
use crate::limits::{
    EXTRAPOLATE_WIDTHS, MAX_DIRECTIONS, MAX_NET_WEIGHT_Q16, MAX_PREDICTION, MAX_TAU_S, MAX_WARMUP_S,
};

/// Every semantic limit, in the order the module docs give them.
pub(crate) fn check(m: &Model) -> Result<(), ImageError> {
    if m.warmup_s > MAX_WARMUP_S {
        return Err(ImageError::WarmupTooLong { value: m.warmup_s });
    }
    for (input, spec) in (0u8..).zip(&m.inputs) {
        if let Some(lag) = spec.lag {
            if lag.tau_s == 0 || lag.tau_s > MAX_TAU_S {
                return Err(ImageError::LagTooLong {
                    input,
                    value: lag.tau_s,
                });
            }
        }
    }
    for (net, n) in (0u8..).zip(&m.nets) {
        let h = usize::from(n.n_hidden);
        let n_in = n.inputs.len();
        let weights = n.w1.iter().take(h).flat_map(|row| row.iter().take(n_in));
        let hidden = weights.chain(n.b1.iter().take(h));
        if hidden
            .into_iter()
            .any(|w| w.unsigned_abs() > MAX_NET_WEIGHT_Q16)
        {
            return Err(ImageError::CoefficientRange { net });
        }
    }
    check_prediction_bound(m)
}

const NOT_LINEAR: ImageError = ImageError::BadValue {
    what: "envelope policy extrapolate: the direction's model is not linear",
};

/// Σ |coef| of `terms` (Q8 of 0.1 µm) over the inputs' reach: a term
/// reading an input counts once within the envelope, 1 + 2W times for an
/// extrapolating direction, a constant once; `None` when the direction
/// extrapolates and a term is not linear (input power > 1, a position).
fn terms_bound(terms: &[Term], extrapolates: bool) -> Option<i64> {
    let reach = if extrapolates {
        1 + 2 * i64::from(EXTRAPOLATE_WIDTHS)
    } else {
        1
    };
    let mut sum = 0i64;
    for t in terms {
        if extrapolates && (t.input_power > 1 || t.position_power != 0) {
            return None;
        }
        let k = if t.input != NONE && t.input_power > 0 {
            reach
        } else {
            1
        };
        sum += i64::from(t.coef.unsigned_abs()) * k;
    }
    Some(sum)
}

/// The analytic bound of the module docs, in Q8 of 0.1 µm (i64: at most
/// 8 nets · 17 values and 8 · 32 + 256 terms of < 2^31, times 5 at most:
/// far below 2^63). With it, an extrapolating direction's linearity.
fn check_prediction_bound(m: &Model) -> Result<(), ImageError> {
    let limit = i64::from(MAX_PREDICTION) << 8;
    let mut lo = [0i64; MAX_DIRECTIONS];
    let mut hi = [0i64; MAX_DIRECTIONS];
    let mask = m.extrapolate_mask();
    let extrapolates = |d: u8| u32::from(mask) & 1u32.checked_shl(u32::from(d)).unwrap_or(0) != 0;
    for n in &m.nets {
        if extrapolates(n.direction) {
            return Err(NOT_LINEAR);
        }
        let d = usize::from(n.direction);
        let w2 =
            n.w2.iter()
                .take(usize::from(n.n_hidden))
                .map(|&w| i64::from(w));
        let (neg, pos) = w2.fold((0, 0), |(neg, pos), w| (neg + w.min(0), pos + w.max(0)));
        if let (Some(l), Some(h)) = (lo.get_mut(d), hi.get_mut(d)) {
            *l += i64::from(n.b2) + neg;
            *h += i64::from(n.b2) + pos;
        }
    }
    for t in &m.tables {
        let d = usize::from(t.direction);
        let ext = extrapolates(t.direction);
        if ext && t.axis != NONE {
            return Err(NOT_LINEAR);
        }
        let sum = terms_bound(&t.terms, ext).ok_or(NOT_LINEAR)?;
        if let (Some(l), Some(h)) = (lo.get_mut(d), hi.get_mut(d)) {
            *l -= sum;
            *h += sum;
        }
    }
    let over = |l: i64, h: i64| l < -limit || h > limit;
    if let Some(direction) = (0u8..)
        .zip(lo.iter().zip(&hi))
        .find(|(_, (&l, &h))| over(l, h))
        .map(|(d, _)| d)
    {
        return Err(ImageError::PredictionBound { direction });
    }
    for (k, f) in m.fallbacks.iter().enumerate() {
        let sum =
            terms_bound(m.fallback_terms_of(k), extrapolates(f.direction)).ok_or(NOT_LINEAR)?;
        if over(-sum, sum) {
            return Err(ImageError::PredictionBound {
                direction: f.direction,
            });
        }
    }
    Ok(())
}

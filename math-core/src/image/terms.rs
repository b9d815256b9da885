//! The one term parser: the 8-byte polynomial term of tables and fallback
//! models, read and checked term by term.

use super::error::{push, ImageError};
use super::format::NONE;
use super::reader::Reader;
use super::types::Term;
use crate::limits::{MAX_POWER, MAX_TERMS};
use heapless::Vec;

/// What a term may use where it stands, and how its refusals are named.
pub(super) struct TermRule {
    /// Inputs of the model: a term's input index must be below.
    pub n_inputs: usize,
    /// The table is bound to an axis, so a position power may be non-zero.
    pub has_axis: bool,
    /// [`ImageError::BadIndex`] name of an input that does not exist.
    pub input_what: &'static str,
    /// [`ImageError::BadValue`] name of a power above `MAX_POWER`.
    pub power_what: &'static str,
    /// [`ImageError::BadValue`] name of a power of an absent input or axis.
    pub no_variable_what: &'static str,
}

/// One term: coef i32, input u8, input power u8, position power u8, pad.
/// Out of line: one copy for tables and fallbacks.
#[inline(never)]
fn read_term(r: &mut Reader<'_>) -> Result<Term, ImageError> {
    let coef = r.i32()?;
    let [input, input_power, position_power, _pad] = r.array()?;
    Ok(Term {
        coef,
        input,
        input_power,
        position_power,
    })
}

impl TermRule {
    fn check(&self, t: &Term) -> Result<(), ImageError> {
        if t.input != NONE && usize::from(t.input) >= self.n_inputs {
            return Err(ImageError::BadIndex {
                what: self.input_what,
                index: t.input,
            });
        }
        if t.input_power > MAX_POWER || t.position_power > MAX_POWER {
            return Err(ImageError::BadValue {
                what: self.power_what,
            });
        }
        if (t.input == NONE && t.input_power != 0) || (!self.has_axis && t.position_power != 0) {
            return Err(ImageError::BadValue {
                what: self.no_variable_what,
            });
        }
        Ok(())
    }
}

/// Read `n` (≤ `MAX_TERMS`, checked by the caller) terms; each is checked
/// as it is read, by `rule` and then by `also` (a section's own rule).
pub(super) fn read_terms(
    r: &mut Reader<'_>,
    n: u8,
    rule: &TermRule,
    mut also: impl FnMut(&Term) -> Result<(), ImageError>,
) -> Result<Vec<Term, MAX_TERMS>, ImageError> {
    let mut terms = Vec::new();
    for _ in 0..n {
        let t = read_term(r)?;
        rule.check(&t)?;
        also(&t)?;
        push(&mut terms, t)?;
    }
    Ok(terms)
}

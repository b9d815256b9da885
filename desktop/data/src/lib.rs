//! tcomp-data: run files — the run CSV format (`runcsv`: reading, checking
//! and writing a recorded run) — and how every desktop binary ends on an
//! error (`cli_error`: one line in the user's terms). Depends on no other
//! tcomp crate; the numerics live in tcomp-numerics.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cli_error;
pub mod runcsv;

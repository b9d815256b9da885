//! tcomp-data: the bottom layer of the desktop crates. Run files (`runcsv`),
//! the one linear-algebra backend (`linalg`), the one seeded random source
//! (`rng`), statistics and decimation shared by fitting and diagnosis
//! (`stats`), and how every desktop binary ends on an error (`cli_error`).
//! Depends on no other tcomp crate.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod cli_error;
pub mod linalg;
pub mod rng;
pub mod runcsv;
pub mod stats;

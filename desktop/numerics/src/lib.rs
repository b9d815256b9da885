//! tcomp-numerics: the numerics every desktop crate shares — the one
//! linear-algebra backend (`linalg`), the one seeded random source (`rng`),
//! statistics and decimation shared by fitting and diagnosis (`stats`).
//! Depends on no other tcomp crate; knows nothing of files or machines.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod linalg;
pub mod rng;
pub mod stats;

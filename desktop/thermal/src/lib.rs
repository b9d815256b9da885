//! tcomp-thermal: the thermal machine simulator (`sim`: thermal network,
//! machine files, duty cycles, effects) and the sim-to-real diagnosis
//! (`diagnose`: with a machine file, or by an identified network without
//! one). Library only: the benchmarks and their truth model live in
//! `tcomp-bench`, the commands in `tcomp`.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod diagnose;
pub mod sim;

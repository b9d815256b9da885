//! tcomp-bench: what the benchmark binaries share. `truth` is a thermal
//! model written separately from the simulator (the open-world benchmark's
//! ground truth); `harness` draws the benchmark cases and scores the
//! diagnosis on them (closed, open and cross-model worlds); `cli` parses
//! the binaries' flags, `progress` draws `bench-fit`'s bar.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod cli;
pub mod harness;
pub mod progress;
pub mod truth;

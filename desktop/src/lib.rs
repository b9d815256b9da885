//! tcomp: the desktop side of thermocomp. Every subcommand is a module here;
//! `main.rs` only parses the command line and dispatches.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod board_link;
pub mod cli_error;
pub mod diagnose;
pub mod export;
pub mod fit;
pub mod geometry;
pub mod linalg;
pub mod plots;
pub mod replay;
pub mod runcsv;
pub mod select;
pub mod sim;

//! Geometric and volumetric errors of a three-axis machine (issue 14):
//! the 21 ISO 230-1 errors (`errors`), the kinematic chain that turns them
//! into a tool-point error (`kinematics`), their identification from
//! displacement lines (`lines`, `identify`), the thermal drift of the errors
//! (`thermal`), the volumetric polynomial and its quantised image section
//! (`volumetric`, `board`), and the simulated and held-out checks (`sim`,
//! `check`, `study`). Library only: the `tcomp geometry` commands live in the
//! `tcomp` crate.

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod errors;
pub mod kinematics;

pub use errors::{Axis, Component, GeometricErrors, Poly, Squareness, Term};
pub use kinematics::{
    sensitivity, tool_tip_error_exact, tool_tip_error_linear, Sensitivity, Structure,
};
pub mod adequacy;
pub mod bench_rich;
pub mod board;
pub mod board5;
pub mod check;
pub mod dense;
pub mod five_axis;
pub mod generic;
pub mod guard;
pub mod identify;
pub mod lines;
pub mod plan;
pub mod plan_design;
pub mod plan_optics;
pub mod predict;
mod prior_solve;
pub mod rotary;
pub mod rtest;
pub mod score;
pub mod shape_free;
pub mod sim;
pub mod smooth;
pub mod study;
pub mod thermal;
mod unit_svd;
pub mod volumetric;

// The rotary files' former paths, for the callers outside this crate that
// still name them (desktop/model's export summary, tcomp's export and its
// tests): the modules now live in `rotary/`.
pub use rotary::board as rotary_board;
pub use rotary::frames as rotary_frames;
pub use rotary::sim as rotary_sim;

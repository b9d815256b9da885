//! `tcomp fit`: MLR baseline and the GA-BPN network (genetic search of the
//! initial weights, then Levenberg–Marquardt refinement), trained on the
//! board's own features ([`features`]: the math core's pipeline — 1/16 °C
//! readings, the reference row, gaps, lag filters per whole model step):
//! sensor rises / differences / spindle speed, optional first-order lags,
//! normalization of each input to [−1, 1] by its training range.
//!
//! Validation is always on held-out runs or later time blocks — never a random
//! row split.
//!
//! This file only declares the modules and re-exports their items at
//! `fit::`: the modules import each other, never this hub.

pub mod candidates;
pub mod choice;
pub mod envelope;
pub mod fallback;
pub mod features;
pub mod greedy;
pub mod lags;
pub mod mlr;
pub mod model;
pub mod net;
pub mod output_lag;
pub mod pipeline;
pub mod plan;
pub mod progress;
pub mod report;
pub mod ridge;
pub mod samples;
pub mod shipped;
pub mod split;
pub mod stability;

// The fit's types, rows, linear baseline, input choice and run splits, at
// `fit::` as before they had files of their own.
pub use greedy::*;
pub use mlr::*;
pub use model::*;
pub use samples::*;
pub use split::*;

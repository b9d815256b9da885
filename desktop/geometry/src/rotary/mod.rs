//! The rotary axes of a table-tilting XYZ-A-C machine (issue 31), one role
//! per file:
//!
//! * `model`: the rotary model (location errors, component errors, drift)
//!   and its kinematic chain in the R-test convention; its items are
//!   re-exported here (`rotary::RotaryModel`, `rotary::tool_tip_error` …);
//! * `sim`: simulated R-test cycles and the pose plan;
//! * `identify`: the rotary errors from R-test files, the linear axes as
//!   known input (`identify_tests`: its tests); `columns`: the fit's
//!   unknowns and what each does to a reading; `unobservable`: what the
//!   files cannot see, and why;
//! * `orders`: the harmonic order of each axis's error motions chosen by
//!   the evidence (`--order-a auto`);
//! * `spindle`: the spindle's direction from several tool lengths, or
//!   why it is undetermined (`spindle_tests`);
//! * `joint`: the same fit with the 14 lines as data; `joint_generic`:
//!   with the generic identifier's posterior (≥ 18 lines, no null
//!   direction);
//! * `bias`: the location constants re-optimised on tool-tip readings;
//! * `check`: the five-axis check over a held-out grid, and the whole
//!   simulated chain the benchmark runs;
//! * `frames`: the R-test convention → the board's (`frames_tests`);
//! * `board`: a rotary model → image section kind 4, with what it costs.
//!
//! This file only declares and re-exports: the files import each other
//! (`super::model::…`), never this hub.

pub mod bias;
pub mod board;
pub mod check;
mod columns;
pub mod frames;
pub mod identify;
pub mod joint;
pub mod joint_generic;
pub mod model;
pub mod orders;
pub mod sim;
pub mod spindle;
mod unobservable;

pub use model::{
    location_shift_of_offset, nominal_chain, reading_sensitivity, rtcp_position, spindle_offset_um,
    tool_tip_error, Axis5, Drift, Linear, Location, Pose, ReadingSensitivity, RotaryModel, Spindle,
    COMPONENT_NAMES, LOCATION_NAMES, LOCATION_UNITS,
};

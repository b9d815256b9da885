//! Geometric and volumetric errors of a three-axis machine (issue 14):
//! the 21 ISO 230-1 errors (`errors`), the kinematic chain that turns them
//! into a tool-point error (`kinematics`).

pub mod cli;
pub mod errors;
pub mod kinematics;

pub use errors::{Axis, Component, GeometricErrors, Poly, Squareness, Term};
pub use kinematics::{
    sensitivity, tool_tip_error_exact, tool_tip_error_linear, Sensitivity, Structure,
};
pub mod bench_rich;
pub mod board;
pub mod check;
pub mod five_axis;
pub mod guard;
pub mod identify;
pub mod lines;
pub mod score;
pub mod sim;
pub mod smooth;
pub mod smooth_cli;
pub mod thermal;
pub mod volumetric;

//! The per-command argument structs and glue of `tcomp`: each parses its
//! flags, calls the library crates and prints.

pub mod diagnose;
pub mod export;
pub mod fit;
pub mod geometry;
pub mod geometry_adequacy;
pub mod geometry_check;
pub mod geometry_generic;
pub mod geometry_identify;
pub mod geometry_plan;
pub mod geometry_predict;
pub mod geometry_rotary;
pub mod geometry_rotary_linear;
pub mod geometry_score;
pub mod geometry_smooth;
pub mod geometry_table;
pub mod keys;
pub mod progress;
pub mod replay;
pub mod sanity;
pub mod select;
pub mod sim;

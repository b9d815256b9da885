//! The verdict room: what is claimed and how it is reported. `gate` is the
//! noise gate, `judge` the margins every candidate of the machine-file mode
//! is judged by, `release` the design values the data push beyond their
//! tolerance (judged alike), `ambiguity` when the gate cannot separate the
//! best explanation from another class, `periodic_first` a measured
//! periodic driver ahead of a parameter finding that leaves its line,
//! `render` the markdown report and its plots.

pub mod ambiguity;
mod gate;
mod judge;
mod periodic_first;
mod release;
pub mod render;

pub(crate) use gate::{beats_in_noise, late_step, z_of, BLOCK_S, Z_MIN};
pub(crate) use judge::Judge;
pub(crate) use periodic_first::{merge_periodic, rule as periodic_rule};
pub(crate) use release::{merge_releases, CalNull};
pub use render::report_md;

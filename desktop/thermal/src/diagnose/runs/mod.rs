//! The runs room: measured runs read into what each mode fits on.
//! `prep` matches a run to a machine file's sensors and directions (the
//! machine-file diagnosis); `series` reads the run-CSV columns themselves
//! into the signals `diagnose fit` identifies its nominal on.

mod prep;
pub mod series;

#[cfg(test)]
pub use prep::Channel;
pub use prep::{prepare, Kind, Prepared};
pub use series::{load, Dataset, RunData, BLOCKS, HELD_BLOCKS};

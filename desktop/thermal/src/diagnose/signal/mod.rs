//! The signal room: first-order lag filters and the residual statistics
//! both diagnosis modes share (correlation, operating phases, where the gap
//! lies, whiteness, which channels move). Leaves: they take series and
//! return numbers, and import nothing else of `diagnose`.

pub mod lag;
pub mod stats;

pub use lag::{held, held_rise, lag, lag_signal};
pub use stats::{
    corr, first_order, ljung_box, mean_finite, moves, normal_sf, phases, phases_from_temperatures,
    r4, rms_of, unusable_channel, where_json, ResidualView,
};

//! The calibration room: the null hypothesis of the machine-file mode.
//! `calibrate` fits the design values inside their tolerances (`boxqp`
//! solves its steps), `freedom` leaves that bounded freedom to every
//! candidate, and `design_heat` / `design_mimic` tell which effects are
//! only a design error the tolerance already allows.

mod boxqp;
pub mod calibrate;
pub mod design_heat;
pub mod design_mimic;
mod freedom;
mod knobs;

pub use calibrate::calibrate;
#[cfg(test)]
pub(crate) use freedom::tests::setup;
pub(crate) use freedom::{print_evals, Freedom};
pub(crate) use knobs::{apply, design_value, Knob};

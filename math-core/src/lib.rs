//! thermocomp-core: the compensator's math, no_std, no hardware, no heap.
//!
//! One source of truth for the board and the desktop: the fixed-point
//! evaluation here is what the firmware runs and what `tcomp` uses to predict
//! the board's output, bit for bit.
//!
//! - [`image`]: the model image (binary blob with CRC-32) → validated [`image::Model`].
//! - [`fixed`]: Q formats, the sigmoid table, normalisation, lag-filter decay.
//! - [`eval`]: the network and the polynomial tables for one set of inputs.
//! - [`features`]: the feature pipeline (reference sample, gaps, lag filters
//!   in whole model steps) the board runs and `tcomp fit` trains on.
//! - [`compensator`]: the state machine around them (features, training
//!   envelope, clamps, rate limit, status bits).
//! - `float` (feature `std`): the same model in f64 and the quantizer.
//! - [`reference`]: correction terms from probe references at a gauge
//!   (Kalman bias + drift, gate, re-zero), issue 28.
//! - [`volumetric`]: the geometric-thermal tool-tip correction (image
//!   section kind 3), integers only.
//! - [`five_axis`]: the rotary axes' errors of a table-tilting five-axis
//!   machine added to the volumetric correction at the PLC's A and C
//!   (image section kind 4), with [`trig`]'s fixed-point sine and cosine.
//! - [`golden`]: golden vectors checked on the board (generated on the host).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

pub mod ask;
pub mod compensator;
pub mod crc;
pub mod eval;
pub mod features;
pub mod five_axis;
pub mod fixed;
#[cfg(feature = "std")]
pub mod float;
pub mod golden;
pub mod image;
pub mod limits;
pub mod reference;
pub mod trig;
pub mod volumetric;

pub use compensator::{Compensator, StepInput, StepOutput};
pub use features::FeatureState;
pub use image::{ImageError, Model};
pub use limits::*;

//! tcomp-model: from calibration runs to the model image the board loads.
//! `select` (temperature-sensitive points) → `fit` (features by the math
//! core's pipeline, MLR and network ensembles, the cross-validated choice,
//! fallbacks) → `export` (quantised image, golden vectors) → `replay` (the
//! board's bit-exact output for a run) → `plots` (SVG report).

// `!(x > 0.0)` is how the input checks reject NaN along with the bad range;
// the numeric kernels index several arrays with one loop variable.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod export;
pub mod fit;
pub mod plots;
pub mod probe_drift;
pub mod reference_args;
pub mod reference_replay;
pub mod replay;
pub mod select;
pub mod signing;

//! The claim's margins in `diagnose fit` (`fitmode::claim`), apart so that
//! the listing rules (`undecided`) judge by the very same levels.

/// A periodic drive must stand this far above the median of the residual
/// spectrum (sum over sensors) to be claimed.
pub const PERIODIC_MIN_PEAK: f64 = 8.0;

/// Held-out gap after / before at which a sensor step is claimed without its
/// fit-row BIC (see `bic_ok`).
pub const STEP_HELD_REL: f64 = 0.5;

/// Held-out gap after / the nominal's at which the speed law is claimed
/// without its fit-row BIC (see `nominal_halved`).
pub const SPEED_HELD_REL: f64 = 0.5;

/// Held-out gap after / before at most for the speed law (either form) to
/// be claimed (see `steep_enough`); between this and `1 − FIT_MIN_REL` it
/// is listed untestable (`speed_law_inconclusive`).
pub const SPEED_CLAIM_REL: f64 = 0.45;

/// Relative held-out shrink (noise units, affected outputs) to claim an effect.
pub const FIT_MIN_REL: f64 = 0.3;
/// Relative held-out shrink to claim a sensor step or lag (see `score`).
pub const SENSOR_MIN_REL: f64 = 0.4;
/// Absolute held-out shrink (noise-variance units) to claim an effect.
pub const FIT_MIN_ABS: f64 = 1.0;

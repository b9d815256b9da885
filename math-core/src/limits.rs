//! Fixed maximum sizes: every array in the core is bounded by these, so a
//! parsed model has a known RAM footprint and no heap is needed. The image
//! carries the actual sizes (5-11-1 is the default, not a limit).

/// Temperature sensors a model may name (seed 000 uses 20).
pub const MAX_SENSORS: usize = 20;
/// Model inputs (features) computed by the board.
pub const MAX_INPUTS: usize = 12;
/// Networks in one image (one per compensated direction, typically).
pub const MAX_NETS: usize = 8;
/// Inputs of one network.
pub const MAX_NET_INPUTS: usize = 8;
/// Hidden neurons of one network.
pub const MAX_HIDDEN: usize = 16;
/// Polynomial tables (seed 001: per axis and error term).
pub const MAX_TABLES: usize = 8;
/// Terms of one polynomial table.
pub const MAX_TERMS: usize = 32;
/// Highest power of an input or a position in a table term.
pub const MAX_POWER: u8 = 3;
/// Compensated directions (X, Y, Z, and up to three more).
pub const MAX_DIRECTIONS: usize = 6;
/// Machine axes whose position the PLC writes.
pub const MAX_AXES: usize = 6;
/// Largest model image in bytes (bounds the staging area and flash slots).
pub const MAX_IMAGE_BYTES: usize = 8192;
/// Largest `max_correction` an image may set, 0.1 µm (10 mm: no thermal drift
/// of a machine tool comes near it; an image asking for more is broken).
pub const MAX_CORRECTION: i32 = 100_000;
/// Bound on Σ |coef| · max(1, position power) over every term of every table
/// bound to one axis (coefficients Q8 of 0.1 µm, so 2^37 is 53 m): keeps the
/// offset and d/dp sums of the TEMP_COMP pair below 2^61 (see `fixed`).
pub const MAX_AXIS_TABLE_WEIGHT: u64 = 1 << 37;
/// Fallback models (format v2, section kind 1) in one image: per direction
/// one without each model sensor and, where room, without each pair.
pub const MAX_FALLBACKS: usize = 32;
/// Terms of all fallback models together (each fallback is one static
/// polynomial table of at most [`MAX_TERMS`] terms).
pub const MAX_FALLBACK_TERMS: usize = 256;
/// Typed sections after the tables (format v2).
pub const MAX_SECTIONS: usize = 8;
/// Largest rate limit a direction may set, 0.1 µm/s (100 mm/s: no thermal
/// drift comes near it; keeps the compensator's rate · ms below 2^32).
pub const MAX_RATE: i32 = 1_000_000;
/// Sensors one volumetric section (image section kind 3) may read.
pub const MAX_VOL_SENSORS: usize = 4;
/// Terms of one volumetric section (each carries x, y and z coefficients).
pub const MAX_VOL_TERMS: usize = 256;
/// Highest exponent of a volumetric variable (2 bits in the image).
pub const MAX_VOL_POWER: u8 = 3;
/// Longest volumetric stroke, µm (100 m).
pub const MAX_VOL_STROKE_UM: i32 = 100_000_000;
/// Longest volumetric tool-length scale, µm (10 m).
pub const MAX_VOL_TOOL_UM: i32 = 10_000_000;
/// Highest Fourier order of a five-axis component error (image section kind 4).
pub const MAX_FOURIER_ORDER: usize = 4;

// Semantic limits (issue 30, `image::semantic`): numbers `tcomp export`
// can produce and predictions within a stated bound.

/// Largest prediction an image may be able to make per direction over its
/// own input envelope, 0.1 µm (10 mm, as [`MAX_CORRECTION`]: no thermal
/// drift of a machine tool comes near it), bounded analytically.
pub const MAX_PREDICTION: i32 = 100_000;
/// Largest hidden-layer weight or bias of a network, Q16 (256.0: inputs
/// are normalised to [−1, 1], so a larger weight only turns a neuron into
/// a step within 1/256 of the envelope; the quantizer refuses beyond it).
pub const MAX_NET_WEIGHT_Q16: u32 = 1 << 24;
/// Longest warm-up, s (24 h).
pub const MAX_WARMUP_S: u32 = 86_400;
/// Longest lag time constant, s (7 days: the slowest machine-hall
/// temperature cycles are hours).
pub const MAX_TAU_S: u32 = 604_800;

/// Envelope policy `extrapolate` (image section kind 5, code 2, format v4):
/// the linear model of such a direction continues this many training widths
/// (hi − lo of each input) beyond each edge of the input's range, and is
/// held at that outer edge beyond: its normalised inputs stay within
/// ±(1 + 2·`EXTRAPOLATE_WIDTHS`) (±5), the bound the parser's prediction
/// check and the evaluation's overflow argument (`crate::eval`) use. Beyond
/// the margin the step still counts and is flagged, as under hold.
/// Why 2: a stated bound, not a fitted one. The served runs the project
/// knows leave their training range by at most about one width (FL_THERMAL's
/// test block, the extrapolation bench's +2 K and unseen speeds); two
/// leaves room for that while keeping a linear model's reach, and so its
/// worst output, at most five times its output over the training range.
pub const EXTRAPOLATE_WIDTHS: i32 = 2;

//! The model image: one binary blob (little-endian) carrying everything the
//! board needs to compensate, protected by a CRC-32. Parse → validate → use:
//! [`Model::parse`] accepts only a fully valid image and never panics; any
//! defect is an [`ImageError`].
//!
//! Layout (format version 5; version 4 is the same without section kind 6,
//! version 3 the same without the envelope policy code 2, version 2 the
//! same without section kind 5, version 1 the same without the sections;
//! every count is bounded by [`crate::limits`]):
//!
//! ```text
//! header   32 B  "TCMI", format u16, flags u16, total_len u32, model_version u32,
//!                step_ms u32, warmup_s u32, n_sensors u8, n_inputs u8, n_nets u8,
//!                n_tables u8, n_directions u8, n_axes u8, units u8, reserved u8
//! sensor   16 B  rom [8] (all zero: by channel), channel u8, 3 × 0, ref_temp i32 (1/16 °C)
//!                (a ROM code names the physical sensor: the board reads the
//!                channel its channel map holds that ROM on, never `channel`,
//!                which then records the run column it was trained on)
//! direction 16 B name [8] (ASCII, zero-padded), max_correction i32 (0.1 µm),
//!                max_rate i32 (0.1 µm/s)
//! axis     20 B  name [8], pos_min i32, pos_max i32, ref_pos i32 (µm or 0.001°)
//! input    20 B  kind u8, a u8, b u8, lagged u8, tau_s u32, decay_q30 u32 (per step),
//!                min i32, max i32 (raw units: 1/16 °C or rpm; the training envelope)
//! net           n_in u8, n_hidden u8, direction u8, 0, input index × n_in,
//!               W1 i32 × n_hidden·n_in (Q16, row per hidden), b1 i32 × n_hidden (Q16),
//!               w2 i32 × n_hidden (Q8 of 0.1 µm), b2 i32 (Q8 of 0.1 µm)
//! table         direction u8, axis u8 (0xFF: none), n_terms u8, 0,
//!               term × n_terms: coef i32 (Q8 of 0.1 µm), input u8 (0xFF: none),
//!               input_power u8, position_power u8, 0
//! sections      (v2 and later) n_sections u8, 3 × 0, then per section:
//!               kind u8, 0, len u16, payload (len bytes)
//! crc32   4 B   CRC-32/ISO-HDLC of every byte before it
//! ```
//!
//! Section kinds (each at most once; an unknown kind is refused, so a board
//! never serves an image whose meaning it only half reads):
//!
//! ```text
//! kind 1  fallback models: n u8, 3 × 0, then per fallback (priority order):
//!         direction u8, excluded sensor a u8, excluded sensor b u8 (0xFF: none),
//!         n_terms u8, term × n_terms (the table term encoding; position power 0)
//! kind 5  envelope policy (issue 50; format v3 and later, in a v2 image unknown):
//!         n u8 (= n_directions), 3 × 0, then per direction (image order):
//!         policy u8 (0 hold, 1 fallback, 2 extrapolate: format v4 only), 0,
//!         margin u16 (raw units of each input: 1/16 °C for temperatures,
//!         rpm for the spindle speed)
//! kind 6  output filter (issue 51; format v5 and later, in an older image unknown):
//!         n u8 (= n_directions), 3 × 0, then per direction (image order):
//!         decay_q30 u32 = exp(−step_ms/τ) · 2^30 per model step (0: none; < 2^30)
//! kind 3  volumetric correction (issue 14, crate::volumetric):
//!         n_sensors u8, 0, n_terms u16, position slot of X, Y, Z u8 × 3
//!         (index into HR_POSITIONS), 0, tool_max i32 (µm),
//!         per direction x, y, z: origin i32 (µm), stroke i32 (µm),
//!                                max_correction i32 (0.1 µm),
//!         sensor × n_sensors (16 B): rom [8] (all zero: by channel), channel u8,
//!                0, ref i16, min i16, max i16 (1/16 °C),
//!         term × n_terms (16 B): exponents u8 (u | v << 2 | w << 4 | l << 6),
//!                sensor u8 (0xFF: constant), 0, 0, coef x, y, z i32
//!                (pm at full scale, or pm per kelvin of the sensor)
//! kind 4  five-axis part of the volumetric correction (issue 31, crate::five_axis;
//!         needs a kind-3 section, whose first n_sensors sensors it reads):
//!         n_sensors u8, order u8, flags u8, 0, pivot_a i32 × 3 (µm, machine frame),
//!         offset_c i32 × 3 (µm, A frame), A min, A max, C min, C max i32 (0.001°),
//!         max_correction i32 × 3 (0.1 µm, the total's clamp),
//!         location × 8 (XOC, YOC, AOC, BOC, YOA, ZOA, BOA, COA):
//!                constant i32, then per kelvin of each sensor i32 × n_sensors
//!                (pm, or prad for AOC, BOC, BOA, COA),
//!         component errors, axis A then C, E{X,Y,Z,A,B,C} each:
//!                per order k = 1 … order: cos coefficient i32, sin coefficient i32
//!                (pm for X, Y, Z; prad for A, B, C);
//!         56 B + 32 B per temperature column + 96 B per order;
//!         flags: bit 0 the location errors are in the R-test convention
//!         (served as (I − R(θ))·ξ_L(T), zero at A = C = 0; images before
//!         the flag have 0 there and are read as before), other bits refused
//! ```
//!
//! The five-axis section's refusals (each a named [`ImageError`], result
//! codes 80–87): no kind-3 section, more temperature columns than kind 3
//! has sensors, order > 4, pivot/offset beyond ±2^27 µm or kind-3
//! positions beyond ±2^28 µm, an angle range not increasing or beyond
//! ±720°, a max correction outside 1..=`MAX_CORRECTION`, an error that can
//! exceed 1 mm / 1 mrad, an unknown flag (87), non-zero padding: the premises of the overflow
//! argument in [`crate::five_axis`].
//!
//! The volumetric section is read on its own: it names its sensors like
//! the image's sensor records do (ROM code, or a channel) with their own
//! reference temperatures and envelope, so an image with it and without
//! any thermal model is valid, and the main model's behaviour does not
//! depend on it. Size: 48 B + 16 B per sensor + 16 B per term (the 156
//! terms of a three-axis machine's static geometry: 2,544 B). Beyond the
//! layout the parser refuses (each with its own [`ImageError`]) a position
//! slot ≥ `MAX_AXES`, a stroke outside 2 µm … 100 m (or whose end does not
//! fit an i32), a tool-length scale outside 2 µm … 10 m, a max correction
//! outside 1..=[`MAX_CORRECTION`](crate::limits::MAX_CORRECTION), a sensor's reference or envelope outside
//! the DS18B20 range (−55 … 125 °C) or an envelope whose minimum is not
//! below its maximum, a term naming no section sensor, non-zero padding,
//! and 0 or more than 256 terms: the premises of the overflow argument in
//! [`crate::volumetric`].
//!
//! The envelope policy (section kind 5) says, per direction, what the board
//! serves when an input of the model serving it lies beyond its training range
//! (`min`, `max` of its input record) by more than the margin: `hold` keeps
//! every input at the edge of its range (the rule of every older image, which
//! reads as `hold`, margin 0); `fallback` treats the sensors that input reads
//! as faulted for that direction and serves it from its first fallback (kind
//! 1, image order) that reads none of them, as degraded mode does (held at the
//! edge when there is none); `extrapolate` (format v4) normalises the inputs
//! of the model serving the direction (main or the fallback in force) over
//! the extended span [min − W·(max − min), max + W·(max − min)], W =
//! [`EXTRAPOLATE_WIDTHS`](crate::limits::EXTRAPOLATE_WIDTHS) = 2: the linear
//! model continues up to two training widths beyond each edge and is held at
//! that outer edge beyond. Whichever policy, the step is counted per direction
//! (input registers 360–371) and status bit 6 is set. The encoder writes
//! version 3 only with this section (8 B + 4 B per direction) and version 4
//! only when some direction extrapolates, so a build that reads versions 1
//! and 2 refuses the former, one that reads up to 3 the latter, by its
//! version check (result 8, unsupported format) and keeps its model; without
//! the section the image is byte-identical to a v2 (or v1) build's. The
//! parser refuses a count other than the image's directions, a policy code
//! other than 0 or 1 (or 2 in a v4 image) and non-zero padding (`BadValue`,
//! result 13), and an extrapolating direction that is not linear in every
//! model that can serve it: a network, a table bound to an axis, a term of
//! its tables or fallbacks of input power above 1 or position power above 0
//! (`BadValue`); its prediction bound is checked over the extended span
//! (`semantic`).
//!
//! The output filter (section kind 6) low-passes each direction's
//! prediction (after the envelope rule, before clamp and rate limit) by a
//! causal first-order lag of time constant τ, advanced in whole model steps
//! like the input lags (`crate::compensator` rule 5). The encoder writes
//! version 5 only with this section (8 B + 4 B per direction), so a build
//! that reads up to version 4 refuses such an image by its version check
//! (result 8) and keeps its model. The parser refuses a count other than the
//! image's directions, a decay ≥ 2^30 and non-zero padding (`BadValue`).
//!
//! A fallback is one static polynomial table over the image's inputs that
//! serves its direction without the excluded sensor(s): it may not use an
//! input that reads them. The encoder writes version 1 when there are no
//! sections, so such images (and the golden vectors) are byte-identical to
//! v1 builds. Size: a fallback costs 4 + 8·terms bytes (an MLR on five
//! inputs: 52 B), the section 8 B; the whole image stays within
//! [`MAX_IMAGE_BYTES`](crate::limits::MAX_IMAGE_BYTES) (8192), checked by the parser and by `tcomp export`.
//!
//! Beyond the layout, the parser refuses (each with its own [`ImageError`]):
//! bytes after the CRC; a sensor ROM code that fails its CRC-8 or names a
//! sensor twice; model version 0 ("no model" on the register map); a
//! sensor channel ≥ [`MAX_SENSORS`](crate::limits::MAX_SENSORS); `max_correction` outside
//! 1..=[`MAX_CORRECTION`](crate::limits::MAX_CORRECTION) (10 mm) and `max_rate` outside 1..=`MAX_RATE`
//! (100 mm/s); tables on one axis with Σ |coef| · max(1, position power) >
//! [`MAX_AXIS_TABLE_WEIGHT`](crate::limits::MAX_AXIS_TABLE_WEIGHT), the bound that keeps the evaluation's i64
//! sums from overflowing (argument in [`crate::fixed`]).
//!
//! Files: [`format`] (constants, checksums), `types` (the records),
//! `model` ([`Model`]), [`error`] ([`ImageError`]), `reader` (the
//! bounds-checked cursor), `parse` (envelope, header, one reader per record
//! kind), `terms` (the one term parser of tables and fallbacks), `sections`
//! (v2 sections), `encode` (the writer).

mod encode;
pub(crate) mod error;
pub(crate) mod format;
mod model;
mod parse;
mod reader;
mod sections;
mod semantic;
pub mod signed;
mod terms;
pub(crate) mod types;

pub use error::{EncodeError, ImageError};
pub use format::{
    crc32, rom_crc8, ENVELOPE_EXTRAPOLATE, ENVELOPE_FALLBACK, ENVELOPE_HOLD, ENVELOPE_VERSION,
    EXTRAPOLATE_VERSION, FIVE_AXIS_FLAGS, FIVE_AXIS_RTEST_LOCATION, FLAG_FIXED_REFERENCE,
    FORMAT_VERSION, HEADER_LEN, MAGIC, NONE, OUTPUT_FILTER_VERSION, SECTIONS_VERSION,
    SECTION_ENVELOPE, SECTION_FALLBACKS, SECTION_FIVE_AXIS, SECTION_OUTPUT_FILTER,
    SECTION_VOLUMETRIC, UNITS_V1,
};
pub use model::Model;
pub use signed::{split_signed, SignedImage, MAX_SIGNED_BYTES};
pub use types::{
    name8, Axis, Direction, EnvelopeMode, EnvelopePolicy, Fallback, InputKind, InputSpec, Lag, Net,
    SensorRef, Table, Term,
};

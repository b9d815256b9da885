//! The format's constants and checksums (the layout is in the module docs
//! of [`crate::image`]).

/// Kept under their old names here: the image's CRC-32, and the ROM code's
/// CRC-8 that sensor records are checked with.
pub use crate::crc::{crc32, crc8_maxim as rom_crc8};

pub const MAGIC: [u8; 4] = *b"TCMI";
/// The newest format this build reads and writes (it also reads versions 1
/// to 4). The encoder writes the oldest version that holds the model: 1
/// without sections, [`SECTIONS_VERSION`] with sections, [`ENVELOPE_VERSION`]
/// with the envelope policy (section kind 5), [`EXTRAPOLATE_VERSION`] when
/// some direction's policy is [`ENVELOPE_EXTRAPOLATE`], 5 only with the
/// output filter (section kind 6), so a build that reads up to 4 refuses
/// such an image by its version check, before anything else.
pub const FORMAT_VERSION: u16 = 5;
/// The format that added the envelope policy (section kind 5, codes 0 and 1).
pub const ENVELOPE_VERSION: u16 = 3;
/// The format that added the policy code [`ENVELOPE_EXTRAPOLATE`].
pub const EXTRAPOLATE_VERSION: u16 = 4;
/// The format that added the output filter (section kind 6).
pub const OUTPUT_FILTER_VERSION: u16 = 5;
/// The format that added the sections (kinds 1, 3, 4).
pub const SECTIONS_VERSION: u16 = 2;
/// Section kind: fallback models (degraded-mode compensation).
pub const SECTION_FALLBACKS: u8 = 1;
/// Section kind: volumetric correction (issue 14, [`crate::volumetric`]).
pub const SECTION_VOLUMETRIC: u8 = 3;
/// Section kind: the five-axis part of the volumetric correction (issue 31,
/// [`crate::five_axis`]); needs a kind-3 section.
pub const SECTION_FIVE_AXIS: u8 = 4;
/// Section kind: the envelope policy per direction (issue 50, format v3 and later).
pub const SECTION_ENVELOPE: u8 = 5;
/// Section kind: the output low-pass per direction (issue 51, format v5 and later).
pub const SECTION_OUTPUT_FILTER: u8 = 6;
/// Envelope policy codes (section kind 5): hold every input at the edge of
/// its training range, serve the direction from its fallback without an
/// input beyond the margin, or (format v4 only) continue the linear model up
/// to [`EXTRAPOLATE_WIDTHS`](crate::limits::EXTRAPOLATE_WIDTHS) training
/// widths beyond each edge.
pub const ENVELOPE_HOLD: u8 = 0;
pub const ENVELOPE_FALLBACK: u8 = 1;
pub const ENVELOPE_EXTRAPOLATE: u8 = 2;
/// Units code 1: corrections 0.1 µm, temperatures 1/16 °C, speed rpm, positions µm.
pub const UNITS_V1: u8 = 1;
/// Flag: use the stored reference temperatures instead of the first valid sample.
pub const FLAG_FIXED_REFERENCE: u16 = 1 << 0;
pub const HEADER_LEN: usize = 32;
/// "No input" / "no axis" marker in tables.
pub const NONE: u8 = 0xFF;
/// Bytes of the CRC-32 that ends an image.
pub(crate) const CRC_LEN: usize = 4;
/// Five-axis section (kind 4): the eight location errors in the section's
/// order (`shared/formats/rtest.md` names; translations in pm, angles in prad).
pub const LOCATION_NAMES: [&str; 8] = ["XOC", "YOC", "AOC", "BOC", "YOA", "ZOA", "BOA", "COA"];
/// Five-axis section: the component errors of each axis in the section's
/// order, E{X,Y,Z,A,B,C}{axis} (the first three translations, pm; the last three angles, prad).
pub const MOTION_LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];
/// Five-axis section flag (byte 2 of the payload; 0 in images before it):
/// the location slots hold the errors in the R-test convention and are
/// served as `(I − R(θ))·ξ_L(T)`, zero at A = C = 0 (`crate::five_axis`).
pub const FIVE_AXIS_RTEST_LOCATION: u8 = 1 << 0;
/// Every five-axis flag this build reads; another bit is refused.
pub const FIVE_AXIS_FLAGS: u8 = FIVE_AXIS_RTEST_LOCATION;

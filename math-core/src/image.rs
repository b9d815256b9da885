//! The model image: one binary blob (little-endian) carrying everything the
//! board needs to compensate, protected by a CRC-32. Parse → validate → use:
//! [`Model::parse`] accepts only a fully valid image and never panics; any
//! defect is an [`ImageError`].
//!
//! Layout (format version 2; version 1 is the same without the sections;
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
//! sections      (v2 only) n_sections u8, 3 × 0, then per section:
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
//! ```
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
//! outside 1..=[`MAX_CORRECTION`], a sensor's reference or envelope outside
//! the DS18B20 range (−55 … 125 °C) or an envelope whose minimum is not
//! below its maximum, a term naming no section sensor, non-zero padding,
//! and 0 or more than 256 terms: the premises of the overflow argument in
//! [`crate::volumetric`].
//!
//! A fallback is one static polynomial table over the image's inputs that
//! serves its direction without the excluded sensor(s): it may not use an
//! input that reads them. The encoder writes version 1 when there are no
//! sections, so such images (and the golden vectors) are byte-identical to
//! v1 builds. Size: a fallback costs 4 + 8·terms bytes (an MLR on five
//! inputs: 52 B), the section 8 B; the whole image stays within
//! [`MAX_IMAGE_BYTES`] (8192), checked by the parser and by `tcomp export`.
//!
//! Beyond the layout, the parser refuses (each with its own [`ImageError`]):
//! bytes after the CRC; a sensor ROM code that fails its CRC-8 or names a
//! sensor twice; model version 0 ("no model" on the register map); a
//! sensor channel ≥ [`MAX_SENSORS`]; `max_correction` outside
//! 1..=[`MAX_CORRECTION`] (10 mm) and `max_rate` outside 1..=`MAX_RATE`
//! (100 mm/s); tables on one axis with Σ |coef| · max(1, position power) >
//! [`MAX_AXIS_TABLE_WEIGHT`], the bound that keeps the evaluation's i64
//! sums from overflowing (argument in [`crate::fixed`]).

use crate::fixed::{Span, FEATURE_FRAC_BITS};
use crate::limits::*;
use crate::volumetric::{
    VolSensor, VolTerm, Volumetric, VolumetricSpec, MAX_VOL_SENSORS, MAX_VOL_TERMS,
};
use heapless::Vec;

pub const MAGIC: [u8; 4] = *b"TCMI";
/// The newest format this build reads and writes (it also reads version 1).
pub const FORMAT_VERSION: u16 = 2;
/// Section kind: fallback models (degraded-mode compensation).
pub const SECTION_FALLBACKS: u8 = 1;
/// Section kind: volumetric correction (issue 14, [`crate::volumetric`]).
pub const SECTION_VOLUMETRIC: u8 = 3;
/// Units code 1: corrections 0.1 µm, temperatures 1/16 °C, speed rpm, positions µm.
pub const UNITS_V1: u8 = 1;
/// Flag: use the stored reference temperatures instead of the first valid sample.
pub const FLAG_FIXED_REFERENCE: u16 = 1 << 0;
pub const HEADER_LEN: usize = 32;
/// "No input" / "no axis" marker in tables.
pub const NONE: u8 = 0xFF;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
/// The 1-Wire ROM code's CRC-8 (Dallas/Maxim, x^8 + x^5 + x^4 + 1).
const CRC8_MAXIM: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_MAXIM_DOW);

/// CRC-8 of a ROM code's first seven bytes (its eighth byte must equal it).
pub fn rom_crc8(bytes: &[u8]) -> u8 {
    CRC8_MAXIM.checksum(bytes)
}

/// CRC-32 of a byte string (the image's checksum, also shown over Modbus).
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

/// Why an image was refused. Every variant is a clean refusal; the board then
/// keeps (or serves "no model" instead of) the refused image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    /// Fewer bytes than the header or than `total_len` says.
    TooShort {
        needed: usize,
        got: usize,
    },
    /// Larger than [`MAX_IMAGE_BYTES`].
    TooLong {
        len: usize,
    },
    BadMagic,
    UnsupportedVersion(u16),
    UnsupportedUnits(u8),
    BadCrc {
        stored: u32,
        computed: u32,
    },
    /// A count above its fixed maximum (`what` names it).
    TooMany {
        what: &'static str,
        count: usize,
        max: usize,
    },
    /// A reference to a sensor, input, direction or axis that does not exist.
    BadIndex {
        what: &'static str,
        index: u8,
    },
    /// A range whose minimum is not below its maximum (or narrower than 2 LSB).
    NonMonotoneRange {
        what: &'static str,
        index: u8,
    },
    /// A field outside its documented domain.
    BadValue {
        what: &'static str,
    },
    /// The sections end before or after `total_len − 4`.
    LengthMismatch,
    /// Bytes after the sealed image (`total_len` and its CRC): a staged
    /// length that does not match the image, or garbage appended to it.
    TrailingBytes {
        image_len: usize,
        got: usize,
    },
    /// A sensor names a bus channel the board does not have (≥ [`MAX_SENSORS`]).
    SensorChannelOutOfRange {
        sensor: u8,
        channel: u8,
    },
    /// Model version 0 is what the register map shows for "no model".
    ZeroModelVersion,
    /// `max_rate` outside 1..=[`crate::compensator::MAX_RATE`] (0 would freeze the correction).
    MaxRateOutOfRange {
        direction: u8,
        value: i32,
    },
    /// `max_correction` outside 1..=[`MAX_CORRECTION`].
    MaxCorrectionOutOfRange {
        direction: u8,
        value: i32,
    },
    /// The tables of one axis have coefficients so large that the evaluation's
    /// i64 sums could overflow (above [`MAX_AXIS_TABLE_WEIGHT`]).
    TableSumTooLarge {
        axis: u8,
    },
    /// A v2 section of a kind this build does not know.
    UnknownSection {
        kind: u8,
    },
    /// A v2 section's payload does not match its declared length (or its
    /// header is malformed).
    SectionLength {
        kind: u8,
    },
    /// The same section kind twice.
    DuplicateSection {
        kind: u8,
    },
    /// A fallback model uses an input that reads a sensor it is meant to do without.
    FallbackUsesExcluded {
        fallback: u8,
        sensor: u8,
    },
    /// A sensor named by a ROM code whose CRC-8 byte does not match (a
    /// mistyped or corrupted code would name no sensor on any bus).
    BadSensorRom {
        sensor: u8,
    },
    /// Two sensors named by the same ROM code (one physical sensor cannot
    /// be two model sensors).
    DuplicateSensorRom {
        sensor: u8,
        first: u8,
    },
    /// Volumetric section: a direction's position slot is not a PLC axis (≥ `MAX_AXES`).
    VolumetricAxisSlot {
        axis: u8,
        slot: u8,
    },
    /// Volumetric section: a stroke outside 2 µm … 100 m, or origin + stroke beyond i32.
    VolumetricStroke {
        axis: u8,
        value: i32,
    },
    /// Volumetric section: the tool-length scale outside 2 µm … 10 m.
    VolumetricTool {
        value: i32,
    },
    /// Volumetric section: a sensor's reference or envelope outside −55 … 125 °C,
    /// or its envelope's minimum not below its maximum.
    VolumetricTemperature {
        sensor: u8,
    },
    /// Volumetric section: a max correction outside 1..=[`MAX_CORRECTION`].
    VolumetricMaxCorrection {
        direction: u8,
        value: i32,
    },
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ImageError::TooShort { needed, got } => {
                write!(f, "image too short: {got} bytes, needs {needed}")
            }
            ImageError::TooLong { len } => write!(
                f,
                "image too long: {len} bytes, the board takes at most {MAX_IMAGE_BYTES}"
            ),
            ImageError::BadMagic => write!(f, "not a model image (it does not start with TCMI)"),
            ImageError::UnsupportedVersion(v) => write!(
                f,
                "image format version {v} not supported (this build reads 1 and {FORMAT_VERSION})"
            ),
            ImageError::UnsupportedUnits(u) => write!(
                f,
                "units code {u} not supported (this build reads {UNITS_V1})"
            ),
            ImageError::BadCrc { stored, computed } => write!(
                f,
                "CRC-32 mismatch: stored {stored:#010x}, computed {computed:#010x} (image corrupted)"
            ),
            ImageError::TooMany { what, count, max } => {
                write!(f, "{count} {what}, at most {max} allowed")
            }
            ImageError::BadIndex { what, index } => {
                write!(f, "{what} index {index} refers to nothing in the image")
            }
            ImageError::NonMonotoneRange { what, index } => write!(
                f,
                "{what} {index}: range minimum is not at least 2 below its maximum"
            ),
            ImageError::BadValue { what } => write!(f, "invalid {what}"),
            ImageError::LengthMismatch => {
                write!(f, "the image's sections do not fill its length exactly")
            }
            ImageError::TrailingBytes { image_len, got } => write!(
                f,
                "{} bytes after the end of the {image_len}-byte image",
                got.saturating_sub(image_len)
            ),
            ImageError::SensorChannelOutOfRange { sensor, channel } => write!(
                f,
                "sensor {sensor} names bus channel {channel}; the board has channels 0-{}",
                MAX_SENSORS - 1
            ),
            ImageError::ZeroModelVersion => write!(
                f,
                "model version 0 is reserved for \"no model\"; versions start at 1"
            ),
            ImageError::MaxRateOutOfRange { direction, value } => write!(
                f,
                "direction {direction}: max rate {value} (0.1 um/s) outside 1..={}",
                crate::compensator::MAX_RATE
            ),
            ImageError::MaxCorrectionOutOfRange { direction, value } => write!(
                f,
                "direction {direction}: max correction {value} (0.1 um) outside 1..={MAX_CORRECTION}"
            ),
            ImageError::TableSumTooLarge { axis } => write!(
                f,
                "tables of axis {axis}: coefficients too large (sum of |coef| x max(1, position power) above 2^37); the evaluation could overflow"
            ),
            ImageError::UnknownSection { kind } => write!(
                f,
                "image section kind {kind} not known to this build (it reads kinds {SECTION_FALLBACKS} and {SECTION_VOLUMETRIC})"
            ),
            ImageError::SectionLength { kind } => write!(
                f,
                "image section kind {kind}: contents do not match its declared length"
            ),
            ImageError::DuplicateSection { kind } => {
                write!(f, "image section kind {kind} appears more than once")
            }
            ImageError::FallbackUsesExcluded { fallback, sensor } => write!(
                f,
                "fallback model {fallback} uses sensor {sensor}, which it is meant to do without"
            ),
            ImageError::BadSensorRom { sensor } => write!(
                f,
                "sensor {sensor}: ROM code fails its CRC-8 (not a 1-Wire ROM code)"
            ),
            ImageError::DuplicateSensorRom { sensor, first } => write!(
                f,
                "sensor {sensor} has the same ROM code as sensor {first}"
            ),
            ImageError::VolumetricAxisSlot { axis, slot } => write!(
                f,
                "volumetric direction {axis} reads position slot {slot}; the PLC writes slots 0-{}",
                MAX_AXES - 1
            ),
            ImageError::VolumetricStroke { axis, value } => write!(
                f,
                "volumetric direction {axis}: stroke {value} um outside 2..={} (or its end beyond the i32 range)",
                crate::volumetric::MAX_VOL_STROKE_UM
            ),
            ImageError::VolumetricTool { value } => write!(
                f,
                "volumetric tool-length scale {value} um outside 2..={}",
                crate::volumetric::MAX_VOL_TOOL_UM
            ),
            ImageError::VolumetricTemperature { sensor } => write!(
                f,
                "volumetric sensor {sensor}: reference or envelope outside -55..125 C, or minimum not below maximum"
            ),
            ImageError::VolumetricMaxCorrection { direction, value } => write!(
                f,
                "volumetric direction {direction}: max correction {value} (0.1 um) outside 1..={MAX_CORRECTION}"
            ),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    BufferTooSmall { needed: usize },
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            EncodeError::BufferTooSmall { needed } => {
                write!(f, "image buffer too small: the image needs {needed} bytes")
            }
        }
    }
}

/// Sensor identity: a DS18B20 ROM code, or (ROM all zero) a channel index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensorRef {
    pub rom: [u8; 8],
    pub channel: u8,
    /// Reference temperature (1/16 °C) used with [`FLAG_FIXED_REFERENCE`].
    pub ref_temp: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Direction {
    pub name: [u8; 8],
    /// Largest correction served, 0.1 µm (absolute value).
    pub max_correction: i32,
    /// Largest change of the served correction, 0.1 µm per second.
    pub max_rate: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Axis {
    pub name: [u8; 8],
    pub pos_min: i32,
    pub pos_max: i32,
    /// Reference position of the offset/slope pair (TEMP_COMP style).
    pub ref_pos: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InputKind {
    /// Temperature of sensor `a` minus its reference sample (1/16 °C).
    SensorRise { a: u8 },
    /// Temperature of sensor `a` minus sensor `b` (1/16 °C).
    SensorDiff { a: u8, b: u8 },
    /// Spindle speed written by the PLC (rpm).
    Spindle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputSpec {
    pub kind: InputKind,
    /// First-order lag: time constant (documentation and the quantizer's
    /// source) and its per-step decay exp(−step/τ) in Q30. `None`: no lag.
    pub lag: Option<Lag>,
    /// Training envelope, raw units.
    pub min: i32,
    pub max: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lag {
    pub tau_s: u32,
    pub decay_q30: u32,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Net {
    pub direction: u8,
    pub inputs: Vec<u8, MAX_NET_INPUTS>,
    pub n_hidden: u8,
    pub w1: [[i32; MAX_NET_INPUTS]; MAX_HIDDEN],
    pub b1: [i32; MAX_HIDDEN],
    pub w2: [i32; MAX_HIDDEN],
    pub b2: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Term {
    pub coef: i32,
    /// Index into the model's inputs, or [`NONE`].
    pub input: u8,
    pub input_power: u8,
    pub position_power: u8,
}

/// A fallback model (format v2, section kind 1): serves `direction` when
/// the main model's sensors are not all valid, without `excluded`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fallback {
    pub direction: u8,
    /// The sensors it does without (model sensor indices; [`NONE`]: unused slot).
    pub excluded: [u8; 2],
    /// Its terms: `Model::fallback_terms[first_term .. first_term + n_terms]`
    /// (a static polynomial table, position power 0).
    pub first_term: u16,
    pub n_terms: u8,
    /// Bit i: it reads model input i (computed at parse time).
    pub input_mask: u16,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    pub direction: u8,
    /// Axis whose position enters the terms, or [`NONE`].
    pub axis: u8,
    pub terms: Vec<Term, MAX_TERMS>,
}

/// A validated model. Every index inside is in range and every range is
/// monotone, so evaluation needs no further checks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Model {
    pub flags: u16,
    pub model_version: u32,
    /// Lag-filter step (ms); the model was trained with this discretisation.
    pub step_ms: u32,
    /// The status bit "warming up" is set for this long after the reference sample.
    pub warmup_s: u32,
    pub sensors: Vec<SensorRef, MAX_SENSORS>,
    pub directions: Vec<Direction, MAX_DIRECTIONS>,
    pub axes: Vec<Axis, MAX_AXES>,
    pub inputs: Vec<InputSpec, MAX_INPUTS>,
    pub nets: Vec<Net, MAX_NETS>,
    pub tables: Vec<Table, MAX_TABLES>,
    /// Fallback models in priority order (format v2; empty in v1 images).
    pub fallbacks: Vec<Fallback, MAX_FALLBACKS>,
    pub fallback_terms: Vec<Term, MAX_FALLBACK_TERMS>,
    /// The volumetric correction (format v2, section kind 3), if any.
    pub volumetric: Option<Volumetric>,
    /// Precomputed from the ranges at parse time (not stored in the image).
    /// Each input's envelope in Q8 of its raw unit, with its Q24 mapping.
    pub(crate) input_span: [Span; MAX_INPUTS],
    pub(crate) axis_span: [Span; MAX_AXES],
    /// Each axis's reference position, normalised (Q24); constant per model.
    pub(crate) axis_ref_q24: [i32; MAX_AXES],
    /// CRC-32 of the image this model came from (set by parse/encode).
    pub crc: u32,
}

impl Net {
    pub fn new(direction: u8, inputs: &[u8], n_hidden: u8) -> Self {
        let mut v = Vec::new();
        for &i in inputs.iter().take(MAX_NET_INPUTS) {
            let _ = v.push(i);
        }
        Net {
            direction,
            inputs: v,
            n_hidden,
            w1: [[0; MAX_NET_INPUTS]; MAX_HIDDEN],
            b1: [0; MAX_HIDDEN],
            w2: [0; MAX_HIDDEN],
            b2: 0,
        }
    }
}

impl Model {
    /// An empty model (no sensors, no outputs) to fill in and [`Model::encode`].
    pub fn empty(model_version: u32, step_ms: u32) -> Self {
        Model {
            flags: 0,
            model_version,
            step_ms,
            warmup_s: 0,
            sensors: Vec::new(),
            directions: Vec::new(),
            axes: Vec::new(),
            inputs: Vec::new(),
            nets: Vec::new(),
            tables: Vec::new(),
            fallbacks: Vec::new(),
            fallback_terms: Vec::new(),
            volumetric: None,
            input_span: [Span::default(); MAX_INPUTS],
            axis_span: [Span::default(); MAX_AXES],
            axis_ref_q24: [0; MAX_AXES],
            crc: 0,
        }
    }

    /// Parse and validate an image. `bytes` must be exactly the image
    /// (`total_len` bytes): anything after its CRC is refused.
    pub fn parse(bytes: &[u8]) -> Result<Model, ImageError> {
        if bytes.len() < HEADER_LEN + 4 {
            return Err(ImageError::TooShort {
                needed: HEADER_LEN + 4,
                got: bytes.len(),
            });
        }
        let mut r = Reader { b: bytes, at: 0 };
        if r.array::<4>()? != MAGIC {
            return Err(ImageError::BadMagic);
        }
        let version = r.u16()?;
        if version != 1 && version != FORMAT_VERSION {
            return Err(ImageError::UnsupportedVersion(version));
        }
        let flags = r.u16()?;
        let total_len = r.u32()? as usize;
        if total_len > MAX_IMAGE_BYTES {
            return Err(ImageError::TooLong { len: total_len });
        }
        if total_len < HEADER_LEN + 4 || bytes.len() < total_len {
            return Err(ImageError::TooShort {
                needed: total_len.max(HEADER_LEN + 4),
                got: bytes.len(),
            });
        }
        if bytes.len() > total_len {
            return Err(ImageError::TrailingBytes {
                image_len: total_len,
                got: bytes.len(),
            });
        }
        let body = &bytes[..total_len - 4];
        let stored = u32::from_le_bytes([
            bytes[total_len - 4],
            bytes[total_len - 3],
            bytes[total_len - 2],
            bytes[total_len - 1],
        ]);
        let computed = crc32(body);
        if stored != computed {
            return Err(ImageError::BadCrc { stored, computed });
        }
        // From here on read only the body: a section running into the CRC is a length error.
        let mut r = Reader { b: body, at: 12 };
        let model_version = r.u32()?;
        if model_version == 0 {
            return Err(ImageError::ZeroModelVersion);
        }
        let step_ms = r.u32()?;
        let warmup_s = r.u32()?;
        let n_sensors = r.count("sensors", MAX_SENSORS)?;
        let n_inputs = r.count("inputs", MAX_INPUTS)?;
        let n_nets = r.count("nets", MAX_NETS)?;
        let n_tables = r.count("tables", MAX_TABLES)?;
        let n_directions = r.count("directions", MAX_DIRECTIONS)?;
        let n_axes = r.count("axes", MAX_AXES)?;
        let units = r.u8()?;
        if units != UNITS_V1 {
            return Err(ImageError::UnsupportedUnits(units));
        }
        let _reserved = r.u8()?;
        if step_ms == 0 || step_ms > 3_600_000 {
            return Err(ImageError::BadValue { what: "step_ms" });
        }
        if flags & !FLAG_FIXED_REFERENCE != 0 {
            return Err(ImageError::BadValue { what: "flags" });
        }
        let mut m = Model::empty(model_version, step_ms);
        m.flags = flags;
        m.warmup_s = warmup_s;

        for i in 0..n_sensors {
            let rom = r.array::<8>()?;
            let channel = r.u8()?;
            let _pad = r.array::<3>()?;
            let ref_temp = r.i32()?;
            if usize::from(channel) >= MAX_SENSORS {
                return Err(ImageError::SensorChannelOutOfRange {
                    sensor: i as u8,
                    channel,
                });
            }
            if rom != [0; 8] {
                if rom_crc8(&rom[..7]) != rom[7] {
                    return Err(ImageError::BadSensorRom { sensor: i as u8 });
                }
                if let Some(first) = m.sensors.iter().position(|s| s.rom == rom) {
                    return Err(ImageError::DuplicateSensorRom {
                        sensor: i as u8,
                        first: first as u8,
                    });
                }
            }
            push(
                &mut m.sensors,
                SensorRef {
                    rom,
                    channel,
                    ref_temp,
                },
            )?;
        }
        for i in 0..n_directions {
            let name = r.array::<8>()?;
            let max_correction = r.i32()?;
            let max_rate = r.i32()?;
            if !(1..=MAX_CORRECTION).contains(&max_correction) {
                return Err(ImageError::MaxCorrectionOutOfRange {
                    direction: i as u8,
                    value: max_correction,
                });
            }
            if !(1..=crate::compensator::MAX_RATE).contains(&max_rate) {
                return Err(ImageError::MaxRateOutOfRange {
                    direction: i as u8,
                    value: max_rate,
                });
            }
            push(
                &mut m.directions,
                Direction {
                    name,
                    max_correction,
                    max_rate,
                },
            )?;
        }
        for i in 0..n_axes {
            let name = r.array::<8>()?;
            let pos_min = r.i32()?;
            let pos_max = r.i32()?;
            let ref_pos = r.i32()?;
            if i64::from(pos_max) - i64::from(pos_min) < 2 || ref_pos < pos_min || ref_pos > pos_max
            {
                return Err(ImageError::NonMonotoneRange {
                    what: "axis",
                    index: i as u8,
                });
            }
            let span = Span::new(pos_min, pos_max).ok_or(ImageError::NonMonotoneRange {
                what: "axis",
                index: i as u8,
            })?;
            m.axis_span[i] = span;
            m.axis_ref_q24[i] = span.normalise(ref_pos).0;
            push(
                &mut m.axes,
                Axis {
                    name,
                    pos_min,
                    pos_max,
                    ref_pos,
                },
            )?;
        }
        for i in 0..n_inputs {
            let kind = r.u8()?;
            let a = r.u8()?;
            let b = r.u8()?;
            let lagged = r.u8()?;
            let tau_s = r.u32()?;
            let decay_q30 = r.u32()?;
            let min = r.i32()?;
            let max = r.i32()?;
            let kind = match kind {
                0 => InputKind::SensorRise {
                    a: sensor_index(a, n_sensors)?,
                },
                1 => InputKind::SensorDiff {
                    a: sensor_index(a, n_sensors)?,
                    b: sensor_index(b, n_sensors)?,
                },
                2 => InputKind::Spindle,
                _ => return Err(ImageError::BadValue { what: "input kind" }),
            };
            let lag = match lagged {
                0 => None,
                1 if decay_q30 < (1 << 30) => Some(Lag { tau_s, decay_q30 }),
                _ => return Err(ImageError::BadValue { what: "input lag" }),
            };
            if i64::from(max) - i64::from(min) < 2 {
                return Err(ImageError::NonMonotoneRange {
                    what: "input",
                    index: i as u8,
                });
            }
            // Features are Q8 of the raw unit in an i32: raw values within ±2^23.
            const RAW_LIMIT: i32 = 1 << (31 - FEATURE_FRAC_BITS);
            if min <= -RAW_LIMIT || max >= RAW_LIMIT {
                return Err(ImageError::BadValue {
                    what: "input range beyond ±2^23 raw units",
                });
            }
            m.input_span[i] = Span::new(min << FEATURE_FRAC_BITS, max << FEATURE_FRAC_BITS).ok_or(
                ImageError::NonMonotoneRange {
                    what: "input",
                    index: i as u8,
                },
            )?;
            push(
                &mut m.inputs,
                InputSpec {
                    kind,
                    lag,
                    min,
                    max,
                },
            )?;
        }
        for _ in 0..n_nets {
            let n_in = r.u8()? as usize;
            let n_hidden = r.u8()? as usize;
            let direction = r.u8()?;
            let _pad = r.u8()?;
            if n_in == 0 || n_in > MAX_NET_INPUTS {
                return Err(ImageError::TooMany {
                    what: "net inputs",
                    count: n_in,
                    max: MAX_NET_INPUTS,
                });
            }
            if n_hidden == 0 || n_hidden > MAX_HIDDEN {
                return Err(ImageError::TooMany {
                    what: "hidden neurons",
                    count: n_hidden,
                    max: MAX_HIDDEN,
                });
            }
            if usize::from(direction) >= n_directions {
                return Err(ImageError::BadIndex {
                    what: "net direction",
                    index: direction,
                });
            }
            let mut net = Net::new(direction, &[], n_hidden as u8);
            for _ in 0..n_in {
                let idx = r.u8()?;
                if usize::from(idx) >= n_inputs {
                    return Err(ImageError::BadIndex {
                        what: "net input",
                        index: idx,
                    });
                }
                push(&mut net.inputs, idx)?;
            }
            for j in 0..n_hidden {
                for i in 0..n_in {
                    net.w1[j][i] = r.i32()?;
                }
            }
            for j in 0..n_hidden {
                net.b1[j] = r.i32()?;
            }
            for j in 0..n_hidden {
                net.w2[j] = r.i32()?;
            }
            net.b2 = r.i32()?;
            push(&mut m.nets, net)?;
        }
        for _ in 0..n_tables {
            let direction = r.u8()?;
            let axis = r.u8()?;
            let n_terms = r.u8()? as usize;
            let _pad = r.u8()?;
            if usize::from(direction) >= n_directions {
                return Err(ImageError::BadIndex {
                    what: "table direction",
                    index: direction,
                });
            }
            if axis != NONE && usize::from(axis) >= n_axes {
                return Err(ImageError::BadIndex {
                    what: "table axis",
                    index: axis,
                });
            }
            if n_terms > MAX_TERMS {
                return Err(ImageError::TooMany {
                    what: "table terms",
                    count: n_terms,
                    max: MAX_TERMS,
                });
            }
            let mut t = Table {
                direction,
                axis,
                terms: Vec::new(),
            };
            for _ in 0..n_terms {
                let Term {
                    coef,
                    input,
                    input_power,
                    position_power,
                } = r.term()?;
                if input != NONE && usize::from(input) >= n_inputs {
                    return Err(ImageError::BadIndex {
                        what: "term input",
                        index: input,
                    });
                }
                if input_power > MAX_POWER || position_power > MAX_POWER {
                    return Err(ImageError::BadValue { what: "term power" });
                }
                if (input == NONE && input_power != 0) || (axis == NONE && position_power != 0) {
                    return Err(ImageError::BadValue {
                        what: "term power without variable",
                    });
                }
                push(
                    &mut t.terms,
                    Term {
                        coef,
                        input,
                        input_power,
                        position_power,
                    },
                )?;
            }
            push(&mut m.tables, t)?;
        }
        if version >= 2 {
            parse_sections(&mut r, &mut m)?;
        }
        if r.at != body.len() {
            return Err(ImageError::LengthMismatch);
        }
        // The overflow bound of eval.rs's TEMP_COMP pair (fixed.rs): per axis,
        // Σ |coef| · max(1, position power) ≤ MAX_AXIS_TABLE_WEIGHT. At most
        // 8 · 32 terms of < 2^31 · 3, so the u64 sum cannot overflow.
        let mut weight = [0u64; MAX_AXES];
        for t in &m.tables {
            if let Some(w) = weight.get_mut(usize::from(t.axis)) {
                for term in &t.terms {
                    *w +=
                        u64::from(term.coef.unsigned_abs()) * u64::from(term.position_power.max(1));
                }
            }
        }
        if let Some(axis) = weight.iter().position(|&w| w > MAX_AXIS_TABLE_WEIGHT) {
            return Err(ImageError::TableSumTooLarge { axis: axis as u8 });
        }
        m.crc = computed;
        Ok(m)
    }

    /// The terms of fallback `k` (0-based).
    pub fn fallback_terms_of(&self, k: usize) -> &[Term] {
        match self.fallbacks.get(k) {
            Some(f) => {
                let a = usize::from(f.first_term);
                self.fallback_terms
                    .get(a..a + usize::from(f.n_terms))
                    .unwrap_or(&[])
            }
            None => &[],
        }
    }

    /// Bit i: the main model of `direction` reads input i.
    pub fn main_input_mask(&self, direction: usize) -> u16 {
        let nets = self
            .nets
            .iter()
            .filter(|n| usize::from(n.direction) == direction)
            .fold(0, |m, n| m | input_mask(n.inputs.iter().copied()));
        self.tables
            .iter()
            .filter(|t| usize::from(t.direction) == direction)
            .fold(nets, |m, t| m | input_mask(t.terms.iter().map(|x| x.input)))
    }

    /// Add a fallback (desktop side; the parser checks it when the image is read back).
    pub fn push_fallback(
        &mut self,
        direction: u8,
        excluded: [u8; 2],
        terms: &[Term],
    ) -> Result<(), ImageError> {
        let first_term = self.fallback_terms.len() as u16;
        for t in terms {
            push(&mut self.fallback_terms, *t)?;
        }
        push(
            &mut self.fallbacks,
            Fallback {
                direction,
                excluded,
                first_term,
                n_terms: terms.len() as u8,
                input_mask: input_mask(terms.iter().map(|t| t.input)),
            },
        )
    }

    /// Size of the v2 sections (0 when there are none: the image is v1).
    fn sections_len(&self) -> usize {
        let fallbacks = self.fallbacks_payload_len().map_or(0, |n| 4 + n);
        let volumetric = self.volumetric.as_ref().map_or(0, |v| 4 + v.encoded_len());
        if fallbacks + volumetric == 0 {
            return 0;
        }
        4 + fallbacks + volumetric
    }

    fn fallbacks_payload_len(&self) -> Option<usize> {
        (!self.fallbacks.is_empty())
            .then(|| 4 + self.fallbacks.len() * 4 + self.fallback_terms.len() * 8)
    }

    /// Size of the encoded image in bytes.
    pub fn encoded_len(&self) -> usize {
        let mut n = HEADER_LEN + 4;
        n += self.sensors.len() * 16 + self.directions.len() * 16 + self.axes.len() * 20;
        n += self.inputs.len() * 20;
        for net in &self.nets {
            let (i, h) = (net.inputs.len(), usize::from(net.n_hidden));
            n += 4 + i + 4 * (h * i + 2 * h + 1);
        }
        for t in &self.tables {
            n += 4 + 8 * t.terms.len();
        }
        n + self.sections_len()
    }

    /// Write the image with its CRC into `out`; returns its length. Also
    /// sets `self.crc`. (The desktop builds a model, encodes it and parses it
    /// back, which is what validates it.)
    pub fn encode(&mut self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let len = self.encoded_len();
        if out.len() < len {
            return Err(EncodeError::BufferTooSmall { needed: len });
        }
        let mut w = Writer { b: out, at: 0 };
        w.put(&MAGIC);
        let version: u16 = if self.sections_len() > 0 {
            FORMAT_VERSION
        } else {
            1
        };
        w.put(&version.to_le_bytes());
        w.put(&self.flags.to_le_bytes());
        w.put(&(len as u32).to_le_bytes());
        w.put(&self.model_version.to_le_bytes());
        w.put(&self.step_ms.to_le_bytes());
        w.put(&self.warmup_s.to_le_bytes());
        w.put(&[
            self.sensors.len() as u8,
            self.inputs.len() as u8,
            self.nets.len() as u8,
            self.tables.len() as u8,
            self.directions.len() as u8,
            self.axes.len() as u8,
            UNITS_V1,
            0,
        ]);
        for s in &self.sensors {
            w.put(&s.rom);
            w.put(&[s.channel, 0, 0, 0]);
            w.put(&s.ref_temp.to_le_bytes());
        }
        for d in &self.directions {
            w.put(&d.name);
            w.put(&d.max_correction.to_le_bytes());
            w.put(&d.max_rate.to_le_bytes());
        }
        for a in &self.axes {
            w.put(&a.name);
            w.put(&a.pos_min.to_le_bytes());
            w.put(&a.pos_max.to_le_bytes());
            w.put(&a.ref_pos.to_le_bytes());
        }
        for inp in &self.inputs {
            let (kind, a, b) = match inp.kind {
                InputKind::SensorRise { a } => (0, a, 0),
                InputKind::SensorDiff { a, b } => (1, a, b),
                InputKind::Spindle => (2, 0, 0),
            };
            let (lagged, tau, decay) = match inp.lag {
                Some(l) => (1, l.tau_s, l.decay_q30),
                None => (0, 0, 0),
            };
            w.put(&[kind, a, b, lagged]);
            w.put(&tau.to_le_bytes());
            w.put(&decay.to_le_bytes());
            w.put(&inp.min.to_le_bytes());
            w.put(&inp.max.to_le_bytes());
        }
        for net in &self.nets {
            let h = usize::from(net.n_hidden);
            w.put(&[net.inputs.len() as u8, net.n_hidden, net.direction, 0]);
            w.put(&net.inputs);
            for row in net.w1.iter().take(h) {
                for v in row.iter().take(net.inputs.len()) {
                    w.put(&v.to_le_bytes());
                }
            }
            for v in net.b1.iter().take(h) {
                w.put(&v.to_le_bytes());
            }
            for v in net.w2.iter().take(h) {
                w.put(&v.to_le_bytes());
            }
            w.put(&net.b2.to_le_bytes());
        }
        for t in &self.tables {
            w.put(&[t.direction, t.axis, t.terms.len() as u8, 0]);
            for term in &t.terms {
                w.put(&term.coef.to_le_bytes());
                w.put(&[term.input, term.input_power, term.position_power, 0]);
            }
        }
        if self.sections_len() > 0 {
            let n = u8::from(!self.fallbacks.is_empty()) + u8::from(self.volumetric.is_some());
            w.put(&[n, 0, 0, 0]);
        }
        if let Some(payload) = self.fallbacks_payload_len() {
            w.put(&[SECTION_FALLBACKS, 0]);
            w.put(&(payload as u16).to_le_bytes());
            w.put(&[self.fallbacks.len() as u8, 0, 0, 0]);
            for k in 0..self.fallbacks.len() {
                let f = self.fallbacks[k];
                w.put(&[f.direction, f.excluded[0], f.excluded[1], f.n_terms]);
                for term in self.fallback_terms_of(k) {
                    w.put(&term.coef.to_le_bytes());
                    w.put(&[term.input, term.input_power, term.position_power, 0]);
                }
            }
        }
        if let Some(v) = &self.volumetric {
            w.put(&[SECTION_VOLUMETRIC, 0]);
            w.put(&(v.encoded_len() as u16).to_le_bytes());
            w.put(&[v.sensors.len() as u8, 0]);
            w.put(&(v.terms.len() as u16).to_le_bytes());
            w.put(&[v.slots[0], v.slots[1], v.slots[2], 0]);
            w.put(&v.tool_max_um.to_le_bytes());
            for k in 0..3 {
                w.put(&v.origin_um[k].to_le_bytes());
                w.put(&v.stroke_um[k].to_le_bytes());
                w.put(&v.max_correction[k].to_le_bytes());
            }
            for s in &v.sensors {
                w.put(&s.sensor.rom);
                w.put(&[s.sensor.channel, 0]);
                w.put(&(s.sensor.ref_temp as i16).to_le_bytes());
                w.put(&s.min.to_le_bytes());
                w.put(&s.max.to_le_bytes());
            }
            for t in &v.terms {
                let [a, b, c, e] = t.exps;
                w.put(&[
                    (a & 3) | (b & 3) << 2 | (c & 3) << 4 | (e & 3) << 6,
                    t.sensor,
                    0,
                    0,
                ]);
                for c in t.coef {
                    w.put(&c.to_le_bytes());
                }
            }
        }
        let crc = crc32(&w.b[..w.at]);
        w.put(&crc.to_le_bytes());
        self.crc = crc;
        Ok(w.at)
    }

    /// Directions' names as text (ASCII, zero padding dropped).
    pub fn direction_name(&self, i: usize) -> &str {
        self.directions
            .get(i)
            .map(|d| name_str(&d.name))
            .unwrap_or("")
    }

    pub fn axis_name(&self, i: usize) -> &str {
        self.axes.get(i).map(|a| name_str(&a.name)).unwrap_or("")
    }
}

/// An 8-byte zero-padded ASCII name from text (longer names are cut at 8 bytes).
pub fn name8(s: &str) -> [u8; 8] {
    let mut n = [0u8; 8];
    for (d, c) in n.iter_mut().zip(s.bytes()) {
        *d = c;
    }
    n
}

fn name_str(n: &[u8; 8]) -> &str {
    let end = n.iter().position(|&c| c == 0).unwrap_or(8);
    core::str::from_utf8(&n[..end]).unwrap_or("?")
}

/// Bit i set for every input index i (NONE and out-of-range indices ignored).
fn input_mask(inputs: impl Iterator<Item = u8>) -> u16 {
    inputs
        .filter(|&i| usize::from(i) < MAX_INPUTS)
        .fold(0u16, |m, i| m | (1 << i))
}

/// The v2 sections after the tables (see the module docs).
fn parse_sections(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let n = r.count("sections", MAX_SECTIONS)?;
    let _pad = r.array::<3>()?;
    let mut seen = 0u32;
    for _ in 0..n {
        let kind = r.u8()?;
        let _pad = r.u8()?;
        let len = usize::from(r.u16()?);
        let start = r.at;
        let end = start
            .checked_add(len)
            .filter(|&e| e <= r.b.len())
            .ok_or(ImageError::SectionLength { kind })?;
        let bit = 1u32 << (kind % 32);
        if kind != SECTION_FALLBACKS && kind != SECTION_VOLUMETRIC {
            return Err(ImageError::UnknownSection { kind });
        }
        if seen & bit != 0 {
            return Err(ImageError::DuplicateSection { kind });
        }
        seen |= bit;
        let mut sr = Reader {
            b: &r.b[..end],
            at: start,
        };
        let parsed = match kind {
            SECTION_VOLUMETRIC => parse_volumetric(&mut sr, m),
            _ => parse_fallbacks(&mut sr, m),
        };
        parsed.map_err(|e| match e {
            ImageError::LengthMismatch => ImageError::SectionLength { kind },
            e => e,
        })?;
        if sr.at != end {
            return Err(ImageError::SectionLength { kind });
        }
        r.at = end;
    }
    Ok(())
}

/// Section kind 3: the volumetric correction (validated by [`Volumetric::new`]).
fn parse_volumetric(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let n_sensors = r.count("volumetric sensors", MAX_VOL_SENSORS)?;
    let pad = r.u8()?;
    let n_terms = usize::from(r.u16()?);
    let slots = r.array::<3>()?;
    let pad2 = r.u8()?;
    if pad != 0 || pad2 != 0 {
        return Err(ImageError::BadValue {
            what: "volumetric section padding",
        });
    }
    if n_terms == 0 || n_terms > MAX_VOL_TERMS {
        return Err(ImageError::TooMany {
            what: "volumetric terms",
            count: n_terms,
            max: MAX_VOL_TERMS,
        });
    }
    let tool_max_um = r.i32()?;
    let (mut origin_um, mut stroke_um, mut max_correction) = ([0i32; 3], [0i32; 3], [0i32; 3]);
    for k in 0..3 {
        origin_um[k] = r.i32()?;
        stroke_um[k] = r.i32()?;
        max_correction[k] = r.i32()?;
    }
    let mut sensors: Vec<VolSensor, MAX_VOL_SENSORS> = Vec::new();
    for _ in 0..n_sensors {
        let rom = r.array::<8>()?;
        let channel = r.u8()?;
        let pad = r.u8()?;
        let ref_temp = i16::from_le_bytes(r.array()?);
        let min = i16::from_le_bytes(r.array()?);
        let max = i16::from_le_bytes(r.array()?);
        if pad != 0 {
            return Err(ImageError::BadValue {
                what: "volumetric section padding",
            });
        }
        push(
            &mut sensors,
            VolSensor {
                sensor: SensorRef {
                    rom,
                    channel,
                    ref_temp: i32::from(ref_temp),
                },
                min,
                max,
            },
        )?;
    }
    let mut terms: Vec<VolTerm, MAX_VOL_TERMS> = Vec::new();
    for _ in 0..n_terms {
        let [x, sensor, p1, p2] = r.array::<4>()?;
        if p1 != 0 || p2 != 0 {
            return Err(ImageError::BadValue {
                what: "volumetric section padding",
            });
        }
        let coef = [r.i32()?, r.i32()?, r.i32()?];
        push(
            &mut terms,
            VolTerm {
                exps: [x & 3, (x >> 2) & 3, (x >> 4) & 3, x >> 6],
                sensor,
                coef,
            },
        )?;
    }
    m.volumetric = Some(Volumetric::new(&VolumetricSpec {
        slots,
        origin_um,
        stroke_um,
        tool_max_um,
        max_correction,
        sensors: &sensors,
        terms: &terms,
    })?);
    Ok(())
}

/// Section kind 1: fallback models.
fn parse_fallbacks(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let n = r.count("fallbacks", MAX_FALLBACKS)?;
    let _pad = r.array::<3>()?;
    let (n_sensors, n_inputs) = (m.sensors.len(), m.inputs.len());
    for k in 0..n {
        let direction = r.u8()?;
        let excluded = [r.u8()?, r.u8()?];
        let n_terms = usize::from(r.u8()?);
        if usize::from(direction) >= m.directions.len() {
            return Err(ImageError::BadIndex {
                what: "fallback direction",
                index: direction,
            });
        }
        for (j, &s) in excluded.iter().enumerate() {
            // The first slot names a sensor; the second may be NONE.
            if !(j == 1 && s == NONE) && usize::from(s) >= n_sensors {
                return Err(ImageError::BadIndex {
                    what: "fallback excluded sensor",
                    index: s,
                });
            }
        }
        if n_terms == 0 || n_terms > MAX_TERMS {
            return Err(ImageError::TooMany {
                what: "fallback terms",
                count: n_terms,
                max: MAX_TERMS,
            });
        }
        let mut terms: Vec<Term, MAX_TERMS> = Vec::new();
        for _ in 0..n_terms {
            let Term {
                coef,
                input,
                input_power,
                position_power,
            } = r.term()?;
            if input != NONE && usize::from(input) >= n_inputs {
                return Err(ImageError::BadIndex {
                    what: "fallback term input",
                    index: input,
                });
            }
            if input_power > MAX_POWER || position_power != 0 || (input == NONE && input_power != 0)
            {
                return Err(ImageError::BadValue {
                    what: "fallback term power",
                });
            }
            if let Some(inp) = m.inputs.get(usize::from(input)) {
                let reads = |s: u8| match inp.kind {
                    InputKind::SensorRise { a } => a == s,
                    InputKind::SensorDiff { a, b } => a == s || b == s,
                    InputKind::Spindle => false,
                };
                if let Some(&s) = excluded.iter().find(|&&s| s != NONE && reads(s)) {
                    return Err(ImageError::FallbackUsesExcluded {
                        fallback: k as u8,
                        sensor: s,
                    });
                }
            }
            push(
                &mut terms,
                Term {
                    coef,
                    input,
                    input_power,
                    position_power,
                },
            )?;
        }
        m.push_fallback(direction, excluded, &terms)?;
    }
    Ok(())
}

fn sensor_index(i: u8, n: usize) -> Result<u8, ImageError> {
    if usize::from(i) < n {
        Ok(i)
    } else {
        Err(ImageError::BadIndex {
            what: "sensor",
            index: i,
        })
    }
}

fn push<T, const N: usize>(v: &mut Vec<T, N>, x: T) -> Result<(), ImageError> {
    v.push(x).map_err(|_| ImageError::TooMany {
        what: "entries",
        count: N + 1,
        max: N,
    })
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    /// One 8-byte term (tables and fallbacks): coef i32, input, powers, pad;
    /// the caller checks it against what its section allows.
    fn term(&mut self) -> Result<Term, ImageError> {
        let coef = self.i32()?;
        let input = self.u8()?;
        let input_power = self.u8()?;
        let position_power = self.u8()?;
        let _pad = self.u8()?;
        Ok(Term {
            coef,
            input,
            input_power,
            position_power,
        })
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], ImageError> {
        let end = self.at.checked_add(N).ok_or(ImageError::LengthMismatch)?;
        let s = self.b.get(self.at..end).ok_or(ImageError::LengthMismatch)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        self.at = end;
        Ok(a)
    }
    fn u8(&mut self) -> Result<u8, ImageError> {
        Ok(self.array::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, ImageError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    fn u32(&mut self) -> Result<u32, ImageError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn i32(&mut self) -> Result<i32, ImageError> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    fn count(&mut self, what: &'static str, max: usize) -> Result<usize, ImageError> {
        let n = usize::from(self.u8()?);
        if n > max {
            return Err(ImageError::TooMany {
                what,
                count: n,
                max,
            });
        }
        Ok(n)
    }
}

struct Writer<'a> {
    b: &'a mut [u8],
    at: usize,
}

impl Writer<'_> {
    /// Callers checked the total length first (`encoded_len`).
    fn put(&mut self, s: &[u8]) {
        self.b[self.at..self.at + s.len()].copy_from_slice(s);
        self.at += s.len();
    }
}

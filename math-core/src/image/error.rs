//! Why an image is refused ([`ImageError`], one line each for users) or
//! cannot be written ([`EncodeError`]).

use super::format::{
    FIVE_AXIS_FLAGS, FORMAT_VERSION, LOCATION_NAMES, MOTION_LETTERS, SECTION_FALLBACKS,
    SECTION_FIVE_AXIS, SECTION_VOLUMETRIC, UNITS_V1,
};
use crate::limits::{
    MAX_AXES, MAX_CORRECTION, MAX_FOURIER_ORDER, MAX_IMAGE_BYTES, MAX_NET_WEIGHT_Q16,
    MAX_PREDICTION, MAX_RATE, MAX_SENSORS, MAX_TAU_S, MAX_VOL_SENSORS, MAX_VOL_STROKE_UM,
    MAX_VOL_TOOL_UM, MAX_WARMUP_S,
};
use heapless::Vec;

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
    /// `max_rate` outside 1..=[`MAX_RATE`] (0 would freeze the correction).
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
    /// Five-axis section (kind 4) in an image without a volumetric section
    /// (kind 3): the chain needs the linear axes' errors.
    FiveAxisWithoutVolumetric,
    /// Five-axis section: more temperature columns than the volumetric
    /// section has sensors (or than [`MAX_VOL_SENSORS`]).
    FiveAxisSensors {
        count: u8,
        available: u8,
    },
    /// Five-axis section: a Fourier order above [`MAX_FOURIER_ORDER`].
    FiveAxisOrder {
        order: u8,
    },
    /// Five-axis section: pivot or offset beyond ±2^27 µm, or the volumetric
    /// section's positions beyond ±2^28 µm.
    FiveAxisGeometry,
    /// Five-axis section: an A (axis 0) or C (1) range whose minimum is not
    /// below its maximum, or beyond ±720°.
    FiveAxisAngleRange {
        axis: u8,
    },
    /// Five-axis section: a max correction outside 1..=[`MAX_CORRECTION`].
    FiveAxisMaxCorrection {
        direction: u8,
        value: i32,
    },
    /// Five-axis section: an error that can exceed 1 mm / 1 mrad (0–7 the
    /// location errors XOC … COA, 8 + 6·axis + k the component errors
    /// E{X,Y,Z,A,B,C}{A,C}), or a non-zero unused coefficient.
    FiveAxisErrorTooLarge {
        error: u8,
    },
    /// Five-axis section: flag bits this build does not read (bit 0:
    /// location errors in the R-test convention, [`FIVE_AXIS_FLAGS`]).
    FiveAxisFlags {
        flags: u8,
    },
    /// A signature trailer ([`super::signed`]) of another algorithm, with
    /// non-zero padding, or cut short.
    BadSignatureTrailer,
    /// The networks and tables of a direction (or a fallback) can predict
    /// beyond ±[`MAX_PREDICTION`] over the image's own input envelope
    /// (bounded analytically: `image::semantic`).
    PredictionBound {
        direction: u8,
    },
    /// A network's hidden weight or bias beyond ±[`MAX_NET_WEIGHT_Q16`]
    /// (what the quantizer produces at most).
    CoefficientRange {
        net: u8,
    },
    /// A warm-up longer than [`MAX_WARMUP_S`].
    WarmupTooLong {
        value: u32,
    },
    /// A lag time constant of 0 or longer than [`MAX_TAU_S`].
    LagTooLong {
        input: u8,
        value: u32,
    },
}

/// The name of five-axis error `error` (see [`ImageError::FiveAxisErrorTooLarge`]).
fn five_axis_error_name(f: &mut core::fmt::Formatter<'_>, error: u8) -> core::fmt::Result {
    match LOCATION_NAMES.get(usize::from(error)) {
        Some(name) => write!(f, "{name}"),
        None => {
            let k = usize::from(error.saturating_sub(8));
            let letter = MOTION_LETTERS.get(k % 6).copied().unwrap_or('?');
            let axis = if k / 6 == 0 { 'A' } else { 'C' };
            write!(f, "E{letter}{axis}")
        }
    }
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
                "image format version {v} not supported (this build reads 1 to {FORMAT_VERSION})"
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
                MAX_RATE
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
                "image section kind {kind} not known to this build (it reads kinds {SECTION_FALLBACKS}, {SECTION_VOLUMETRIC} and {SECTION_FIVE_AXIS})"
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
                MAX_VOL_STROKE_UM
            ),
            ImageError::VolumetricTool { value } => write!(
                f,
                "volumetric tool-length scale {value} um outside 2..={}",
                MAX_VOL_TOOL_UM
            ),
            ImageError::VolumetricTemperature { sensor } => write!(
                f,
                "volumetric sensor {sensor}: reference or envelope outside -55..125 C, or minimum not below maximum"
            ),
            ImageError::VolumetricMaxCorrection { direction, value } => write!(
                f,
                "volumetric direction {direction}: max correction {value} (0.1 um) outside 1..={MAX_CORRECTION}"
            ),
            ImageError::FiveAxisWithoutVolumetric
            | ImageError::FiveAxisSensors { .. }
            | ImageError::FiveAxisOrder { .. }
            | ImageError::FiveAxisGeometry
            | ImageError::FiveAxisAngleRange { .. }
            | ImageError::FiveAxisMaxCorrection { .. }
            | ImageError::FiveAxisErrorTooLarge { .. }
            | ImageError::FiveAxisFlags { .. } => five_axis_message(self, f),
            ImageError::PredictionBound { direction } => write!(
                f,
                "direction {direction}: the model can predict beyond +-{} mm over its own input envelope (networks and tables bounded analytically)",
                MAX_PREDICTION / 10_000
            ),
            ImageError::CoefficientRange { net } => write!(
                f,
                "net {net}: a hidden weight or bias beyond +-{} (Q16), more than the quantizer produces",
                MAX_NET_WEIGHT_Q16 >> 16
            ),
            ImageError::WarmupTooLong { value } => {
                write!(f, "warm-up {value} s longer than {MAX_WARMUP_S} s")
            }
            ImageError::LagTooLong { input, value } => write!(
                f,
                "input {input}: lag time constant {value} s outside 1..={MAX_TAU_S} s"
            ),
            ImageError::BadSignatureTrailer => write!(
                f,
                "signature trailer malformed (not one Ed25519 signature after the image)"
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

/// Push onto a fixed-capacity vector; a full one is a [`ImageError::TooMany`].
pub(crate) fn push<T, const N: usize>(v: &mut Vec<T, N>, x: T) -> Result<(), ImageError> {
    v.push(x).map_err(|_| ImageError::TooMany {
        what: "entries",
        count: N + 1,
        max: N,
    })
}

/// The message of a five-axis section refusal (kept apart so `fmt` stays short).
fn five_axis_message(e: &ImageError, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
    match *e {
            ImageError::FiveAxisWithoutVolumetric => write!(
                f,
                "five-axis section (kind {SECTION_FIVE_AXIS}) without a volumetric section (kind {SECTION_VOLUMETRIC}): the chain needs the linear axes' errors"
            ),
            ImageError::FiveAxisSensors { count, available } => write!(
                f,
                "five-axis section reads {count} sensors; the volumetric section has {available} (at most {MAX_VOL_SENSORS})"
            ),
            ImageError::FiveAxisOrder { order } => write!(
                f,
                "five-axis section: Fourier order {order} above {MAX_FOURIER_ORDER}"
            ),
            ImageError::FiveAxisGeometry => write!(
                f,
                "five-axis section: pivot or offset beyond +-2^27 um, or volumetric positions beyond +-2^28 um"
            ),
            ImageError::FiveAxisAngleRange { axis } => write!(
                f,
                "five-axis section: range of {} not increasing or beyond +-720 deg",
                if axis == 0 { 'A' } else { 'C' }
            ),
            ImageError::FiveAxisMaxCorrection { direction, value } => write!(
                f,
                "five-axis direction {direction}: max correction {value} (0.1 um) outside 1..={MAX_CORRECTION}"
            ),
            ImageError::FiveAxisErrorTooLarge { error } => {
                write!(f, "five-axis error ")?;
                five_axis_error_name(f, error)?;
                write!(
                    f,
                    " can exceed 1 mm / 1 mrad in the temperature envelope, or has a non-zero unused coefficient"
                )
            }
            ImageError::FiveAxisFlags { flags } => write!(
                f,
                "five-axis section: flags {flags:#04x} not known to this build (it reads {FIVE_AXIS_FLAGS:#04x})"
            ),
            _ => Ok(()),
    }
}

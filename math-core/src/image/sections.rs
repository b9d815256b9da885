//! The typed sections after the tables (format v2): the section list, and
//! one reader per kind (1: fallback models, 3: volumetric correction, 4:
//! five-axis part, 5: envelope policy, format v3 and later, 6: output
//! filter, format v5 and later).

use super::error::{push, ImageError};
use super::format::{
    ENVELOPE_EXTRAPOLATE, ENVELOPE_FALLBACK, ENVELOPE_HOLD, ENVELOPE_VERSION, EXTRAPOLATE_VERSION,
    NONE, OUTPUT_FILTER_VERSION, SECTION_ENVELOPE, SECTION_FALLBACKS, SECTION_FIVE_AXIS,
    SECTION_OUTPUT_FILTER, SECTION_VOLUMETRIC,
};
use super::model::Model;
use super::reader::Reader;
use super::terms::{read_terms, TermRule};
use super::types::{EnvelopeMode, EnvelopePolicy, InputKind, SensorRef};
use crate::five_axis::{FiveAxis, FiveAxisSpec, MAX_FOURIER_ORDER};
use crate::limits::{MAX_FALLBACKS, MAX_SECTIONS, MAX_TERMS, MAX_VOL_SENSORS, MAX_VOL_TERMS};
use crate::volumetric::{VolSensor, VolTerm, Volumetric};
use heapless::Vec;

/// The v2 sections after the tables (see the module docs): each kind at
/// most once, each payload read exactly to its declared length. Kind 5
/// only in a version-3 (or later) image: in a version-2 one it is unknown,
/// as it is to a build that reads only versions 1 and 2; its code 2
/// (extrapolate) only in a version-4 image. Kind 6 likewise only in a
/// version-5 (or later) image.
pub(super) fn parse_sections(
    r: &mut Reader<'_>,
    m: &mut Model,
    version: u16,
) -> Result<(), ImageError> {
    let n = r.count("sections", MAX_SECTIONS)?;
    let _pad = r.array::<3>()?;
    let mut seen = 0u32;
    for _ in 0..n {
        let [kind, _pad] = r.array()?;
        let len = usize::from(r.u16()?);
        let mut payload = r.take(len).ok_or(ImageError::SectionLength { kind })?;
        let bit = 1u32 << (kind % 32);
        // The format each kind came with (unknown in older images).
        let since = match kind {
            SECTION_FALLBACKS | SECTION_VOLUMETRIC | SECTION_FIVE_AXIS => 0,
            SECTION_ENVELOPE => ENVELOPE_VERSION,
            SECTION_OUTPUT_FILTER => OUTPUT_FILTER_VERSION,
            _ => u16::MAX,
        };
        if version < since {
            return Err(ImageError::UnknownSection { kind });
        }
        if seen & bit != 0 {
            return Err(ImageError::DuplicateSection { kind });
        }
        seen |= bit;
        let parsed = match kind {
            SECTION_VOLUMETRIC => parse_volumetric(&mut payload, m),
            SECTION_FIVE_AXIS => parse_five_axis(&mut payload, m),
            SECTION_ENVELOPE => parse_envelope(&mut payload, m, version),
            SECTION_OUTPUT_FILTER => parse_output_filter(&mut payload, m),
            _ => parse_fallbacks(&mut payload, m),
        };
        parsed.map_err(|e| match e {
            ImageError::LengthMismatch => ImageError::SectionLength { kind },
            e => e,
        })?;
        if !payload.is_at_end() {
            return Err(ImageError::SectionLength { kind });
        }
    }
    // Kind 4 leans on kind 3 (its sensors and position ranges), whichever came first.
    if let Some(f) = &m.five_axis {
        f.check_with(m.volumetric.as_ref())?;
    }
    Ok(())
}

const VOL_PADDING: ImageError = ImageError::BadValue {
    what: "volumetric section padding",
};

/// Section kind 3: the volumetric correction (validated by [`Volumetric::new`]).
fn parse_volumetric(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let n_sensors = r.count("volumetric sensors", MAX_VOL_SENSORS)?;
    let pad = r.u8()?;
    let n_terms = usize::from(r.u16()?);
    let slots = r.array::<3>()?;
    let pad2 = r.u8()?;
    if pad != 0 || pad2 != 0 {
        return Err(VOL_PADDING);
    }
    if n_terms == 0 || n_terms > MAX_VOL_TERMS {
        return Err(ImageError::TooMany {
            what: "volumetric terms",
            count: n_terms,
            max: MAX_VOL_TERMS,
        });
    }
    // Read and checked in the model's own section (no copy of its terms
    // on the stack); gone again if it is refused.
    let v = m.volumetric.insert(Volumetric::blank());
    let read = read_volumetric(r, v, slots, n_sensors, n_terms);
    if read.is_err() {
        m.volumetric = None;
    }
    read
}

/// The rest of section kind 3 into `v`, then [`Volumetric::new`]'s checks.
fn read_volumetric(
    r: &mut Reader<'_>,
    v: &mut Volumetric,
    slots: [u8; 3],
    n_sensors: u8,
    n_terms: usize,
) -> Result<(), ImageError> {
    v.slots = slots;
    v.tool_max_um = r.i32()?;
    for ((origin, stroke), max) in v
        .origin_um
        .iter_mut()
        .zip(v.stroke_um.iter_mut())
        .zip(v.max_correction.iter_mut())
    {
        *origin = r.i32()?;
        *stroke = r.i32()?;
        *max = r.i32()?;
    }
    read_vol_sensors(r, n_sensors, &mut v.sensors)?;
    read_vol_terms(r, n_terms, &mut v.terms)?;
    v.check_in_place()
}

/// Volumetric sensor records (16 B): identity as the image's sensors, then
/// reference and envelope as i16.
fn read_vol_sensors(
    r: &mut Reader<'_>,
    n: u8,
    sensors: &mut Vec<VolSensor, MAX_VOL_SENSORS>,
) -> Result<(), ImageError> {
    for _ in 0..n {
        push(sensors, read_vol_sensor(r)?)?;
    }
    Ok(())
}

/// One volumetric sensor record. Out of line, as the loop over at most
/// four of them would otherwise be unrolled (flash is scarce, parsing not hot).
#[inline(never)]
fn read_vol_sensor(r: &mut Reader<'_>) -> Result<VolSensor, ImageError> {
    let rom = r.array::<8>()?;
    let [channel, pad] = r.array()?;
    let ref_temp = r.i16()?;
    let min = r.i16()?;
    let max = r.i16()?;
    if pad != 0 {
        return Err(VOL_PADDING);
    }
    let sensor = SensorRef {
        rom,
        channel,
        ref_temp: i32::from(ref_temp),
    };
    Ok(VolSensor { sensor, min, max })
}

/// Volumetric terms (16 B): packed exponents, sensor, padding, x, y, z.
fn read_vol_terms(
    r: &mut Reader<'_>,
    n: usize,
    terms: &mut Vec<VolTerm, MAX_VOL_TERMS>,
) -> Result<(), ImageError> {
    for _ in 0..n {
        let [x, sensor, p1, p2] = r.array()?;
        if p1 != 0 || p2 != 0 {
            return Err(VOL_PADDING);
        }
        let coef = [r.i32()?, r.i32()?, r.i32()?];
        let exps = [x & 3, (x >> 2) & 3, (x >> 4) & 3, x >> 6];
        push(terms, VolTerm { exps, sensor, coef })?;
    }
    Ok(())
}

/// Section kind 4: the five-axis part (validated by [`FiveAxis::new`];
/// against kind 3 after every section is read).
fn parse_five_axis(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    // The flags byte was padding before the R-test location mode: an old
    // image reads 0 there and is evaluated as before.
    let [n_sensors, order, flags, pad] = r.array()?;
    if pad != 0 {
        return Err(ImageError::BadValue {
            what: "five-axis section padding",
        });
    }
    if usize::from(n_sensors) > MAX_VOL_SENSORS {
        return Err(ImageError::FiveAxisSensors {
            count: n_sensors,
            available: 0,
        });
    }
    if usize::from(order) > MAX_FOURIER_ORDER {
        return Err(ImageError::FiveAxisOrder { order });
    }
    let mut s = FiveAxisSpec {
        n_sensors,
        order,
        flags,
        ..FiveAxisSpec::default()
    };
    r.i32s(&mut s.pivot_a_um)?;
    r.i32s(&mut s.offset_c_um)?;
    r.i32s(&mut s.a_range_mdeg)?;
    r.i32s(&mut s.c_range_mdeg)?;
    r.i32s(&mut s.max_correction)?;
    for row in &mut s.location {
        r.first_i32s(row, 1 + usize::from(n_sensors))?;
    }
    for axis in &mut s.motion {
        for error in axis.iter_mut() {
            // The first `order` (sin, cos) pairs, in order.
            r.first_i32s(error.as_flattened_mut(), 2 * usize::from(order))?;
        }
    }
    m.five_axis = Some(FiveAxis::new(&s)?);
    Ok(())
}

/// Section kind 5: the envelope policy, one 4-byte entry per direction
/// (policy u8, 0, margin u16 raw units); code 2 (extrapolate) only from
/// format v4 on. Whether an extrapolating direction is linear is checked
/// with the semantic limits, once every record is read.
fn parse_envelope(r: &mut Reader<'_>, m: &mut Model, version: u16) -> Result<(), ImageError> {
    let [n, pad @ ..] = r.array::<4>()?;
    if usize::from(n) != m.directions.len() {
        return Err(ImageError::BadValue {
            what: "envelope policy count (one per direction)",
        });
    }
    let mut policies = [EnvelopePolicy::default(); crate::limits::MAX_DIRECTIONS];
    for p in policies.iter_mut().take(usize::from(n)) {
        let [policy, pad2] = r.array()?;
        p.margin = r.u16()?;
        p.mode = match policy {
            ENVELOPE_HOLD => EnvelopeMode::Hold,
            ENVELOPE_FALLBACK => EnvelopeMode::Fallback,
            ENVELOPE_EXTRAPOLATE if version >= EXTRAPOLATE_VERSION => EnvelopeMode::Extrapolate,
            ENVELOPE_EXTRAPOLATE => {
                return Err(ImageError::BadValue {
                    what: "envelope policy extrapolate (format v4 or later only)",
                })
            }
            _ => {
                return Err(ImageError::BadValue {
                    what: "envelope policy",
                })
            }
        };
        if pad != [0; 3] || pad2 != 0 {
            return Err(ImageError::BadValue {
                what: "envelope section padding",
            });
        }
    }
    m.envelope = Some(policies);
    Ok(())
}

/// Section kind 6: the output low-pass, one decay u32 (Q30, per model step;
/// 0: none) per direction, each below 2^30.
#[inline(never)]
fn parse_output_filter(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let [n, pad @ ..] = r.array::<4>()?;
    if usize::from(n) != m.directions.len() || pad != [0; 3] {
        return Err(ImageError::BadValue {
            what: "output filter count (one per direction) or padding",
        });
    }
    let decays = m
        .output_decay_q30
        .insert([0; crate::limits::MAX_DIRECTIONS]);
    for d in decays.iter_mut().take(usize::from(n)) {
        *d = r.u32()?;
        if *d >= 1 << 30 {
            return Err(ImageError::BadValue {
                what: "output filter decay (must be below 2^30)",
            });
        }
    }
    Ok(())
}

/// Section kind 1: fallback models, in priority order.
fn parse_fallbacks(r: &mut Reader<'_>, m: &mut Model) -> Result<(), ImageError> {
    let n = r.count("fallbacks", MAX_FALLBACKS)?;
    let _pad = r.array::<3>()?;
    for fallback in 0..n {
        let [direction, a, b, n_terms] = r.array()?;
        let excluded = [a, b];
        if usize::from(direction) >= m.directions.len() {
            return Err(ImageError::BadIndex {
                what: "fallback direction",
                index: direction,
            });
        }
        // The first slot names a sensor; the second may be NONE.
        for s in core::iter::once(a).chain((b != NONE).then_some(b)) {
            if usize::from(s) >= m.sensors.len() {
                return Err(ImageError::BadIndex {
                    what: "fallback excluded sensor",
                    index: s,
                });
            }
        }
        if n_terms == 0 || usize::from(n_terms) > MAX_TERMS {
            return Err(ImageError::TooMany {
                what: "fallback terms",
                count: usize::from(n_terms),
                max: MAX_TERMS,
            });
        }
        let rule = TermRule {
            n_inputs: m.inputs.len(),
            has_axis: false,
            input_what: "fallback term input",
            power_what: "fallback term power",
            no_variable_what: "fallback term power",
        };
        let terms = read_terms(r, n_terms, &rule, |t| {
            match reads_excluded(m, t.input, excluded) {
                Some(sensor) => Err(ImageError::FallbackUsesExcluded { fallback, sensor }),
                None => Ok(()),
            }
        })?;
        m.push_fallback(direction, excluded, &terms)?;
    }
    Ok(())
}

/// The first of `excluded` that model input `input` reads, if any.
fn reads_excluded(m: &Model, input: u8, excluded: [u8; 2]) -> Option<u8> {
    let inp = m.inputs.get(usize::from(input))?;
    let reads = |s: u8| match inp.kind {
        InputKind::SensorRise { a } => a == s,
        InputKind::SensorDiff { a, b } => a == s || b == s,
        InputKind::Spindle => false,
    };
    excluded.into_iter().find(|&s| s != NONE && reads(s))
}

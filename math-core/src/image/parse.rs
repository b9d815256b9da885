//! [`Model::parse`]: the envelope (length, magic, version, CRC), the header,
//! then one reader per record kind in image order, then the sections and
//! the tables' overflow bound. Each record is read whole before it is
//! checked, and the checks run in the order the module docs list them, so
//! a defective image is refused with the same error whatever changes here.

use super::error::{push, ImageError};
use super::format::{
    crc32, rom_crc8, CRC_LEN, FLAG_FIXED_REFERENCE, FORMAT_VERSION, HEADER_LEN, MAGIC, NONE,
    SECTIONS_VERSION, UNITS_V1,
};
use super::model::Model;
use super::reader::Reader;
use super::sections::parse_sections;
use super::terms::{read_terms, TermRule};
use super::types::{Axis, Direction, InputKind, InputSpec, Lag, Net, SensorRef, Table};
use crate::fixed::{Span, FEATURE_FRAC_BITS};
use crate::limits::*;

/// Longest lag-filter step an image may ask for (one hour).
const MAX_STEP_MS: u32 = 3_600_000;
/// Features are Q8 of the raw unit in an i32: raw values within ±2^23.
const RAW_LIMIT: i32 = 1 << (31 - FEATURE_FRAC_BITS);

/// What the envelope check hands on: the body (every byte before the CRC).
struct Envelope<'a> {
    version: u16,
    flags: u16,
    body: &'a [u8],
    crc: u32,
}

/// The record counts of the header.
struct Counts {
    sensors: u8,
    inputs: u8,
    nets: u8,
    tables: u8,
    directions: u8,
    axes: u8,
}

impl Model {
    /// Parse and validate an image. `bytes` must be exactly the image
    /// (`total_len` bytes): anything after its CRC is refused.
    pub fn parse(bytes: &[u8]) -> Result<Model, ImageError> {
        let mut m = Model::empty(0, 0);
        m.parse_into(bytes)?;
        Ok(m)
    }

    /// [`Model::parse`] into this model, in place (a board keeps no second
    /// model on its stack). On an error the model is left partly filled:
    /// the caller must not use it.
    pub fn parse_into(&mut self, bytes: &[u8]) -> Result<(), ImageError> {
        let env = check_envelope(bytes)?;
        // From here on read only the body: a section running into the CRC is a length error.
        let mut r = Reader::new(env.body, 12);
        let m = self;
        let n = read_header(&mut r, env.flags, m)?;
        read_sensors(&mut r, m, n.sensors)?;
        read_directions(&mut r, m, n.directions)?;
        read_axes(&mut r, m, n.axes)?;
        read_inputs(&mut r, m, n.inputs)?;
        read_nets(&mut r, m, n.nets)?;
        read_tables(&mut r, m, n.tables)?;
        if env.version >= SECTIONS_VERSION {
            parse_sections(&mut r, m, env.version)?;
        }
        if !r.is_at_end() {
            return Err(ImageError::LengthMismatch);
        }
        check_table_weight(m)?;
        super::semantic::check(m)?;
        m.crc = env.crc;
        Ok(())
    }
}

/// The DS18B20's measuring range in its own unit (1/16 °C).
const DS18B20_MIN_SIXTEENTHS: i32 = -55 * 16;
const DS18B20_MAX_SIXTEENTHS: i32 = 125 * 16;

/// Length, magic, version, `total_len` and the CRC-32.
fn check_envelope(bytes: &[u8]) -> Result<Envelope<'_>, ImageError> {
    let min_len = HEADER_LEN + CRC_LEN;
    if bytes.len() < min_len {
        return Err(ImageError::TooShort {
            needed: min_len,
            got: bytes.len(),
        });
    }
    let mut r = Reader::new(bytes, 0);
    if r.array::<4>()? != MAGIC {
        return Err(ImageError::BadMagic);
    }
    let version = r.u16()?;
    if version == 0 || version > FORMAT_VERSION {
        return Err(ImageError::UnsupportedVersion(version));
    }
    let flags = r.u16()?;
    let total_len = usize::try_from(r.u32()?).unwrap_or(usize::MAX);
    if total_len > MAX_IMAGE_BYTES {
        return Err(ImageError::TooLong { len: total_len });
    }
    if total_len < min_len || bytes.len() < total_len {
        return Err(ImageError::TooShort {
            needed: total_len.max(min_len),
            got: bytes.len(),
        });
    }
    if bytes.len() > total_len {
        return Err(ImageError::TrailingBytes {
            image_len: total_len,
            got: bytes.len(),
        });
    }
    let (body, crc_bytes) = bytes
        .split_at_checked(total_len - CRC_LEN)
        .ok_or(ImageError::LengthMismatch)?;
    let stored = Reader::new(crc_bytes, 0).u32()?;
    let computed = crc32(body);
    if stored != computed {
        return Err(ImageError::BadCrc { stored, computed });
    }
    Ok(Envelope {
        version,
        flags,
        body,
        crc: computed,
    })
}

/// The header after `total_len`: `m` emptied with the header's values,
/// and the record counts.
fn read_header(r: &mut Reader<'_>, flags: u16, m: &mut Model) -> Result<Counts, ImageError> {
    let model_version = r.u32()?;
    if model_version == 0 {
        return Err(ImageError::ZeroModelVersion);
    }
    let step_ms = r.u32()?;
    let warmup_s = r.u32()?;
    let n = Counts {
        sensors: r.count("sensors", MAX_SENSORS)?,
        inputs: r.count("inputs", MAX_INPUTS)?,
        nets: r.count("nets", MAX_NETS)?,
        tables: r.count("tables", MAX_TABLES)?,
        directions: r.count("directions", MAX_DIRECTIONS)?,
        axes: r.count("axes", MAX_AXES)?,
    };
    let units = r.u8()?;
    if units != UNITS_V1 {
        return Err(ImageError::UnsupportedUnits(units));
    }
    let _reserved = r.u8()?;
    if step_ms == 0 || step_ms > MAX_STEP_MS {
        return Err(ImageError::BadValue { what: "step_ms" });
    }
    if flags & !FLAG_FIXED_REFERENCE != 0 {
        return Err(ImageError::BadValue { what: "flags" });
    }
    m.clear(model_version, step_ms);
    m.flags = flags;
    m.warmup_s = warmup_s;
    Ok(n)
}

/// Sensor records: bus channel in range, ROM code (if any) valid and unique.
fn read_sensors(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    for sensor in 0..n {
        let rom = r.array::<8>()?;
        let [channel, reserved @ ..] = r.array::<4>()?;
        let ref_temp = r.i32()?;
        if usize::from(channel) >= MAX_SENSORS {
            return Err(ImageError::SensorChannelOutOfRange { sensor, channel });
        }
        if reserved != [0; 3] {
            return Err(ImageError::BadValue {
                what: "sensor record reserved bytes",
            });
        }
        // A reference the sensor can never read would hold the model outside
        // its envelope for good (DS18B20: −55 … +125 °C, 1/16 °C steps).
        if !(DS18B20_MIN_SIXTEENTHS..=DS18B20_MAX_SIXTEENTHS).contains(&ref_temp) {
            return Err(ImageError::BadValue {
                what: "sensor reference temperature (outside the DS18B20's -55...+125 °C)",
            });
        }
        if rom != [0; 8] {
            let [head @ .., check] = rom;
            if rom_crc8(&head) != check {
                return Err(ImageError::BadSensorRom { sensor });
            }
            if let Some(first) = m.sensors.iter().zip(0u8..).find(|(s, _)| s.rom == rom) {
                return Err(ImageError::DuplicateSensorRom {
                    sensor,
                    first: first.1,
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
    Ok(())
}

/// Direction records: max correction and max rate within their limits.
fn read_directions(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    for direction in 0..n {
        let name = r.array::<8>()?;
        let max_correction = r.i32()?;
        let max_rate = r.i32()?;
        if !(1..=MAX_CORRECTION).contains(&max_correction) {
            return Err(ImageError::MaxCorrectionOutOfRange {
                direction,
                value: max_correction,
            });
        }
        if !(1..=MAX_RATE).contains(&max_rate) {
            return Err(ImageError::MaxRateOutOfRange {
                direction,
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
    Ok(())
}

/// Axis records: a range of at least 2 holding the reference position; its
/// normalisation is precomputed.
fn read_axes(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    let slots = m.axis_span.iter_mut().zip(m.axis_ref_q24.iter_mut());
    for ((span_slot, ref_slot), index) in slots.zip(0..n) {
        let axis = Axis {
            name: r.array()?,
            pos_min: r.i32()?,
            pos_max: r.i32()?,
            ref_pos: r.i32()?,
        };
        let bad = ImageError::NonMonotoneRange {
            what: "axis",
            index,
        };
        if i64::from(axis.pos_max) - i64::from(axis.pos_min) < 2
            || !(axis.pos_min..=axis.pos_max).contains(&axis.ref_pos)
        {
            return Err(bad);
        }
        let span = Span::new(axis.pos_min, axis.pos_max).ok_or(bad)?;
        *span_slot = span;
        *ref_slot = span.normalise(axis.ref_pos).0;
        push(&mut m.axes, axis)?;
    }
    Ok(())
}

/// Input records: kind and sensors, lag, and the training envelope (with
/// its precomputed Q24 mapping).
fn read_inputs(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    let n_sensors = m.sensors.len();
    for (span_slot, index) in m.input_span.iter_mut().zip(0..n) {
        let [kind, a, b, lagged] = r.array()?;
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
        let bad = ImageError::NonMonotoneRange {
            what: "input",
            index,
        };
        if i64::from(max) - i64::from(min) < 2 {
            return Err(bad);
        }
        if min <= -RAW_LIMIT || max >= RAW_LIMIT {
            return Err(ImageError::BadValue {
                what: "input range beyond ±2^23 raw units",
            });
        }
        *span_slot = Span::new(min << FEATURE_FRAC_BITS, max << FEATURE_FRAC_BITS).ok_or(bad)?;
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

/// Network records: sizes, direction, input indices, then the weights.
fn read_nets(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    for _ in 0..n {
        let [n_in, n_hidden, direction, _pad] = r.array()?;
        let (n_in, h) = (usize::from(n_in), usize::from(n_hidden));
        if n_in == 0 || n_in > MAX_NET_INPUTS {
            return Err(ImageError::TooMany {
                what: "net inputs",
                count: n_in,
                max: MAX_NET_INPUTS,
            });
        }
        if h == 0 || h > MAX_HIDDEN {
            return Err(ImageError::TooMany {
                what: "hidden neurons",
                count: h,
                max: MAX_HIDDEN,
            });
        }
        if usize::from(direction) >= m.directions.len() {
            return Err(ImageError::BadIndex {
                what: "net direction",
                index: direction,
            });
        }
        let mut net = Net::new(direction, &[], n_hidden);
        for _ in 0..n_in {
            let idx = r.u8()?;
            if usize::from(idx) >= m.inputs.len() {
                return Err(ImageError::BadIndex {
                    what: "net input",
                    index: idx,
                });
            }
            push(&mut net.inputs, idx)?;
        }
        // n_in ≤ MAX_NET_INPUTS and h ≤ MAX_HIDDEN (checked above): `take` takes exactly.
        for row in net.w1.iter_mut().take(h) {
            r.first_i32s(row, n_in)?;
        }
        r.first_i32s(&mut net.b1, h)?;
        r.first_i32s(&mut net.w2, h)?;
        net.b2 = r.i32()?;
        push(&mut m.nets, net)?;
    }
    Ok(())
}

/// Polynomial tables: direction, axis (or none), then the terms.
fn read_tables(r: &mut Reader<'_>, m: &mut Model, n: u8) -> Result<(), ImageError> {
    for _ in 0..n {
        let [direction, axis, n_terms, _pad] = r.array()?;
        if usize::from(direction) >= m.directions.len() {
            return Err(ImageError::BadIndex {
                what: "table direction",
                index: direction,
            });
        }
        if axis != NONE && usize::from(axis) >= m.axes.len() {
            return Err(ImageError::BadIndex {
                what: "table axis",
                index: axis,
            });
        }
        if usize::from(n_terms) > MAX_TERMS {
            return Err(ImageError::TooMany {
                what: "table terms",
                count: usize::from(n_terms),
                max: MAX_TERMS,
            });
        }
        let rule = TermRule {
            n_inputs: m.inputs.len(),
            has_axis: axis != NONE,
            input_what: "term input",
            power_what: "term power",
            no_variable_what: "term power without variable",
        };
        let terms = read_terms(r, n_terms, &rule, |_| Ok(()))?;
        push(
            &mut m.tables,
            Table {
                direction,
                axis,
                terms,
            },
        )?;
    }
    Ok(())
}

/// The overflow bound of eval.rs's TEMP_COMP pair (fixed.rs): per axis,
/// Σ |coef| · max(1, position power) ≤ MAX_AXIS_TABLE_WEIGHT. At most
/// 8 · 32 terms of < 2^31 · 3, so the u64 sum cannot overflow.
fn check_table_weight(m: &Model) -> Result<(), ImageError> {
    let mut weight = [0u64; MAX_AXES];
    for t in &m.tables {
        if let Some(w) = weight.get_mut(usize::from(t.axis)) {
            for term in &t.terms {
                *w += u64::from(term.coef.unsigned_abs()) * u64::from(term.position_power.max(1));
            }
        }
    }
    match weight
        .iter()
        .zip(0u8..)
        .find(|(&w, _)| w > MAX_AXIS_TABLE_WEIGHT)
    {
        Some((_, axis)) => Err(ImageError::TableSumTooLarge { axis }),
        None => Ok(()),
    }
}

//! [`Model::encode`]: the image the parser reads, record kind by record
//! kind (desktop side; a model is validated by parsing its image back).

use super::error::EncodeError;
use super::format::{
    crc32, CRC_LEN, ENVELOPE_EXTRAPOLATE, ENVELOPE_FALLBACK, ENVELOPE_HOLD, ENVELOPE_VERSION,
    EXTRAPOLATE_VERSION, HEADER_LEN, MAGIC, OUTPUT_FILTER_VERSION, SECTIONS_VERSION,
    SECTION_ENVELOPE, SECTION_FALLBACKS, SECTION_FIVE_AXIS, SECTION_OUTPUT_FILTER,
    SECTION_VOLUMETRIC, UNITS_V1,
};
use super::model::Model;
use super::types::{EnvelopeMode, InputKind, Term};
use crate::five_axis::FiveAxis;
use crate::volumetric::Volumetric;
use heapless::Vec;

impl Model {
    /// Size of the v2 sections (0 when there are none: the image is v1).
    fn sections_len(&self) -> usize {
        let fallbacks = self.fallbacks_payload_len().map_or(0, |n| 4 + n);
        let volumetric = self.volumetric.as_ref().map_or(0, |v| 4 + v.encoded_len());
        let five_axis = self.five_axis.as_ref().map_or(0, |f| 4 + f.encoded_len());
        let envelope = self.envelope_payload_len().map_or(0, |n| 4 + n);
        let filter = self.output_filter_payload_len().map_or(0, |n| 4 + n);
        let all = fallbacks + volumetric + five_axis + envelope + filter;
        if all == 0 {
            return 0;
        }
        4 + all
    }

    /// Section kind 6: 4 B, then 4 B per direction.
    fn output_filter_payload_len(&self) -> Option<usize> {
        self.output_decay_q30.map(|_| 4 + 4 * self.directions.len())
    }

    /// Section kind 5: 4 B, then 4 B per direction.
    fn envelope_payload_len(&self) -> Option<usize> {
        self.envelope.map(|_| 4 + 4 * self.directions.len())
    }

    fn fallbacks_payload_len(&self) -> Option<usize> {
        (!self.fallbacks.is_empty())
            .then(|| 4 + self.fallbacks.len() * 4 + self.fallback_terms.len() * 8)
    }

    /// Size of the encoded image in bytes.
    pub fn encoded_len(&self) -> usize {
        let mut n = HEADER_LEN + CRC_LEN;
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
        let too_small = EncodeError::BufferTooSmall { needed: len };
        if out.len() < len {
            return Err(too_small);
        }
        let mut w = Writer {
            out,
            at: 0,
            overflow: false,
        };
        self.write_header(&mut w, len);
        self.write_records(&mut w);
        self.write_nets(&mut w);
        self.write_tables(&mut w);
        self.write_sections(&mut w);
        let crc = crc32(w.written());
        w.put(&crc.to_le_bytes());
        if w.overflow {
            // encoded_len and the writers disagree: refuse rather than cut.
            return Err(too_small);
        }
        self.crc = crc;
        Ok(w.at)
    }

    fn write_header(&self, w: &mut Writer<'_>, len: usize) {
        w.put(&MAGIC);
        // The oldest version that holds the model (format.rs).
        let version: u16 = if self.output_decay_q30.is_some() {
            OUTPUT_FILTER_VERSION
        } else if self.extrapolate_mask() != 0 {
            EXTRAPOLATE_VERSION
        } else if self.envelope.is_some() {
            ENVELOPE_VERSION
        } else if self.sections_len() > 0 {
            SECTIONS_VERSION
        } else {
            1
        };
        w.put(&version.to_le_bytes());
        w.put(&self.flags.to_le_bytes());
        // Far below 4 GiB: every vector of the model is bounded.
        w.put(&u32::try_from(len).unwrap_or(u32::MAX).to_le_bytes());
        w.put(&self.model_version.to_le_bytes());
        w.put(&self.step_ms.to_le_bytes());
        w.put(&self.warmup_s.to_le_bytes());
        w.put(&[
            count_u8(&self.sensors),
            count_u8(&self.inputs),
            count_u8(&self.nets),
            count_u8(&self.tables),
            count_u8(&self.directions),
            count_u8(&self.axes),
            UNITS_V1,
            0,
        ]);
    }

    /// Sensor, direction, axis and input records.
    fn write_records(&self, w: &mut Writer<'_>) {
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
    }

    fn write_nets(&self, w: &mut Writer<'_>) {
        for net in &self.nets {
            let h = usize::from(net.n_hidden);
            w.put(&[count_u8(&net.inputs), net.n_hidden, net.direction, 0]);
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
    }

    fn write_tables(&self, w: &mut Writer<'_>) {
        for t in &self.tables {
            w.put(&[t.direction, t.axis, count_u8(&t.terms), 0]);
            for term in &t.terms {
                write_term(w, term);
            }
        }
    }

    /// The section list (v2 only) and the sections.
    fn write_sections(&self, w: &mut Writer<'_>) {
        if self.sections_len() > 0 {
            let n = u8::from(!self.fallbacks.is_empty())
                + u8::from(self.volumetric.is_some())
                + u8::from(self.five_axis.is_some())
                + u8::from(self.envelope.is_some())
                + u8::from(self.output_decay_q30.is_some());
            w.put(&[n, 0, 0, 0]);
        }
        if let Some(payload) = self.fallbacks_payload_len() {
            w.put(&[SECTION_FALLBACKS, 0]);
            w.put(&len_u16(payload).to_le_bytes());
            w.put(&[count_u8(&self.fallbacks), 0, 0, 0]);
            for (k, f) in self.fallbacks.iter().enumerate() {
                w.put(&[f.direction, f.excluded[0], f.excluded[1], f.n_terms]);
                for term in self.fallback_terms_of(k) {
                    write_term(w, term);
                }
            }
        }
        if let Some(v) = &self.volumetric {
            write_volumetric(w, v);
        }
        if let Some(f) = &self.five_axis {
            write_five_axis(w, f);
        }
        if let (Some(payload), Some(policies)) = (self.envelope_payload_len(), &self.envelope) {
            w.put(&[SECTION_ENVELOPE, 0]);
            w.put(&len_u16(payload).to_le_bytes());
            w.put(&[count_u8(&self.directions), 0, 0, 0]);
            for p in policies.iter().take(self.directions.len()) {
                let code = match p.mode {
                    EnvelopeMode::Hold => ENVELOPE_HOLD,
                    EnvelopeMode::Fallback => ENVELOPE_FALLBACK,
                    EnvelopeMode::Extrapolate => ENVELOPE_EXTRAPOLATE,
                };
                w.put(&[code, 0]);
                w.put(&p.margin.to_le_bytes());
            }
        }
        if let (Some(payload), Some(decays)) =
            (self.output_filter_payload_len(), &self.output_decay_q30)
        {
            w.put(&[SECTION_OUTPUT_FILTER, 0]);
            w.put(&len_u16(payload).to_le_bytes());
            w.put(&[count_u8(&self.directions), 0, 0, 0]);
            for d in decays.iter().take(self.directions.len()) {
                w.put(&d.to_le_bytes());
            }
        }
    }
}

/// One 8-byte term (tables and fallbacks).
fn write_term(w: &mut Writer<'_>, term: &Term) {
    w.put(&term.coef.to_le_bytes());
    w.put(&[term.input, term.input_power, term.position_power, 0]);
}

/// Section kind 3 (layout in the module docs).
fn write_volumetric(w: &mut Writer<'_>, v: &Volumetric) {
    w.put(&[SECTION_VOLUMETRIC, 0]);
    w.put(&len_u16(v.encoded_len()).to_le_bytes());
    w.put(&[count_u8(&v.sensors), 0]);
    w.put(&len_u16(v.terms.len()).to_le_bytes());
    w.put(&[v.slots[0], v.slots[1], v.slots[2], 0]);
    w.put(&v.tool_max_um.to_le_bytes());
    let per_direction = v.origin_um.iter().zip(&v.stroke_um).zip(&v.max_correction);
    for ((origin, stroke), max) in per_direction {
        w.put(&origin.to_le_bytes());
        w.put(&stroke.to_le_bytes());
        w.put(&max.to_le_bytes());
    }
    for s in &v.sensors {
        w.put(&s.sensor.rom);
        w.put(&[s.sensor.channel, 0]);
        // The reference as i16 (Volumetric::new keeps it in −55 … 125 °C):
        // the low two bytes of its little-endian i32.
        let [lo, hi, _, _] = s.sensor.ref_temp.to_le_bytes();
        w.put(&[lo, hi]);
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

/// Section kind 4 (layout in the module docs).
fn write_five_axis(w: &mut Writer<'_>, f: &FiveAxis) {
    w.put(&[SECTION_FIVE_AXIS, 0]);
    w.put(&len_u16(f.encoded_len()).to_le_bytes());
    w.put(&[f.n_sensors, f.order, f.flags, 0]);
    let head = f.pivot_a_um.iter().chain(&f.offset_c_um);
    let head = head.chain(&f.a_range_mdeg).chain(&f.c_range_mdeg);
    for v in head.chain(&f.max_correction) {
        w.put(&v.to_le_bytes());
    }
    for row in &f.location {
        for v in row.iter().take(1 + usize::from(f.n_sensors)) {
            w.put(&v.to_le_bytes());
        }
    }
    for axis in &f.motion {
        for error in axis {
            for v in error.iter().take(usize::from(f.order)).flatten() {
                w.put(&v.to_le_bytes());
            }
        }
    }
}

/// A count the image stores in one byte. Every vector of a model holds at
/// most 255 entries (checked at compile time), so nothing is cut.
fn count_u8<T, const N: usize>(v: &Vec<T, N>) -> u8 {
    const { assert!(N <= 255) };
    u8::try_from(v.len()).unwrap_or(u8::MAX)
}

/// A section length or term count the image stores in two bytes (the
/// largest section, 4,208 B of volumetric terms, is far below 2^16).
fn len_u16(n: usize) -> u16 {
    u16::try_from(n).unwrap_or(u16::MAX)
}

/// Writes into the caller's buffer; a write past its end is recorded in
/// `overflow` instead of panicking (callers check `encoded_len` first).
struct Writer<'a> {
    out: &'a mut [u8],
    at: usize,
    overflow: bool,
}

impl Writer<'_> {
    fn put(&mut self, s: &[u8]) {
        let end = self.at.saturating_add(s.len());
        match self.out.get_mut(self.at..end) {
            Some(dst) => {
                dst.copy_from_slice(s);
                self.at = end;
            }
            None => self.overflow = true,
        }
    }

    fn written(&self) -> &[u8] {
        self.out.get(..self.at).unwrap_or(&[])
    }
}

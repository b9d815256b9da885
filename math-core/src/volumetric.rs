//! The volumetric (geometric-thermal) correction of issue 14: per tool-tip
//! direction x, y, z one polynomial in the normalised axis positions, the
//! normalised tool length and the temperatures of a few sensors, carried by
//! the model image (format v2, section kind 3) and evaluated in integers
//! only. The desktop (`tcomp geometry table` → `tcomp export --geometry`)
//! quantises its f64 polynomial into this form and predicts the board by
//! calling [`Volumetric::evaluate`], the function the firmware runs.
//!
//! ```text
//! e_d = Σ_t q(c_dt · u^a v^b w^c l^e) · s_t           (d = x, y, z)
//!   u = (x − x0)/X, v = (y − y0)/Y, w = (z − z0)/Z    positions in [0, 1]
//!   l = L / L_max                                     tool length in [0, 1]
//!   s_t = 16                     for a constant term  (c in pm)
//!   s_t = T_i − T_ref,i          for a term per kelvin of sensor i (c in pm/K;
//!                                temperatures in 1/16 °C)
//! ```
//!
//! Formats (all integers):
//!
//! | quantity | type | unit / format |
//! |---|---|---|
//! | position (PLC) | i32 | µm (`HR_POSITIONS`), origin x0 and stroke X in µm |
//! | tool length (PLC) | i32 | µm, 0 ..= L_max |
//! | u, v, w, l and their powers | i32 | Q24 in [0, 1] ([`Span`], then halved) |
//! | coefficient c | i32 | pm (10⁻⁶ µm) at full scale of every variable, or pm per kelvin |
//! | temperature, reference, envelope | i32 / i16 | 1/16 °C (the DS18B20 LSB) |
//! | term q(c · monomial) | i64 | pm, rounded once (Q24 → integer) |
//! | accumulator | i64 | 1/16 pm |
//! | correction | i32 | 0.1 µm (the register unit), one rounding from the accumulator |
//!
//! Why nothing overflows (the parser enforces every premise, see
//! `image.rs`, section kind 3): every normalised variable is clamped into
//! [0, 2^24]; a product of two such values rounded back to Q24 stays
//! ≤ 2^24, so every monomial m ≤ 2^24. |c| ≤ 2^31 (any i32), so
//! |c · m| ≤ 2^55 < 2^63 and the rounded term |q| ≤ 2^31 + 1. Temperatures
//! are clamped into the section's envelope, which the parser keeps inside
//! the DS18B20 range −55 … 125 °C (−880 … 2000 sixteenths), as it keeps
//! the reference: |T − T_ref| ≤ 2880 < 2^12, and the constant scale is
//! 16 = 2^4. The rounded terms are summed per scale (constant, or per
//! kelvin of sensor i): at most [`MAX_VOL_TERMS`] = 256 = 2^8 of them,
//! so each sum is < 2^8 · (2^31 + 1) < 2^40; scaled (< 2^12) and added
//! over the 1 + 4 scales — still at most 256 terms in all — they give
//! |acc| ≤ 256 · (2^31 + 1) · 2^12 < 2^52 < 2^63. The final rounding adds 800,000 < 2^20: still < 2^63, and the
//! quotient (< 2^52 / 1.6·10^6 < 2^31) fits the i32 before the clamp to
//! the section's max correction (≤ 10 mm). No bound on the coefficients
//! beyond their i32 type is needed; `math-core/tests/volumetric.rs`
//! evaluates the extreme section (256 terms, every coefficient i32::MIN or
//! i32::MAX, every variable and temperature at its edge) with overflow
//! checks on.
//!
//! Quantisation (what the fixed-point value can differ from the f64
//! polynomial of the same integer coefficients): each variable is within
//! 1 LSB of Q24 (2^-24), each product rounding adds ½ LSB, so a monomial of
//! degree k ≤ 12 is within (k + 3·½)·2^-24 < 2^-20 of its exact value; the
//! term's rounding adds ½ pm (times |ΔT| in K for a per-kelvin term); the
//! final rounding adds ½ of 0.1 µm. [`Volumetric::error_bound_tenth_um`]
//! sums these for a given temperature state (the desktop adds the
//! quantisation of the coefficients themselves).

use crate::fixed::{mul_q24, Span, ONE_Q24};
use crate::image::error::ImageError;
use crate::image::format::NONE;
use crate::image::types::SensorRef;
use crate::limits::{MAX_AXES, MAX_CORRECTION, MAX_SENSORS};
use heapless::Vec;

/// Kept here for their old paths; defined with the other limits.
pub use crate::limits::{
    MAX_VOL_POWER, MAX_VOL_SENSORS, MAX_VOL_STROKE_UM, MAX_VOL_TERMS, MAX_VOL_TOOL_UM,
};

/// The DS18B20's range in 1/16 °C (−55 … 125 °C): envelopes and references stay inside.
pub const TEMP_MIN_16: i32 = -55 * 16;
pub const TEMP_MAX_16: i32 = 125 * 16;
/// Accumulator units (1/16 pm) per output unit (0.1 µm = 10^5 pm).
pub const ACC_PER_TENTH_UM: i64 = 1_600_000;

/// Status bits of one evaluation (input register 186; the application adds
/// the ones about the section and the PLC, see `src/modbus/registers.rs`).
pub mod vstatus {
    /// The correction is computed from valid temperatures at the PLC's positions.
    pub const VALID: u16 = 1 << 0;
    /// No model, or the model has no volumetric section: not available.
    pub const NO_SECTION: u16 = 1 << 1;
    /// A sensor the section reads has no valid value: not available.
    pub const SENSOR_FAULT: u16 = 1 << 2;
    /// The PLC has not written positions since boot: not available.
    pub const NO_POSITIONS: u16 = 1 << 3;
    /// A position was outside origin … origin + stroke and held at the edge.
    pub const POSITION_CLAMPED: u16 = 1 << 4;
    /// The tool length was outside 0 … L_max and held at the edge.
    pub const TOOL_CLAMPED: u16 = 1 << 5;
    /// A temperature was outside the section's envelope and held at its edge.
    pub const TEMPERATURE_CLAMPED: u16 = 1 << 6;
    /// A correction was clamped to the section's max correction.
    pub const CLAMPED: u16 = 1 << 7;
    /// The PLC's registers are older than the timeout, or a sensor value is held.
    pub const STALE: u16 = 1 << 8;
    /// Five-axis section (kind 4): A or C was outside the section's range
    /// and held at its edge.
    pub const ANGLE_CLAMPED: u16 = 1 << 9;
}

/// A sensor the section reads: identity as the image's sensors (ROM code,
/// or all-zero ROM and a bus channel), reference and envelope in 1/16 °C.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VolSensor {
    pub sensor: SensorRef,
    pub min: i16,
    pub max: i16,
}

/// One term: exponents of u, v, w, l; the sensor whose rise multiplies it
/// ([`NONE`]: constant); coefficients x, y, z (pm, or pm per kelvin).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VolTerm {
    pub exps: [u8; 4],
    pub sensor: u8,
    pub coef: [i32; 3],
}

/// The volumetric section, validated ([`Volumetric::new`] is the only way
/// to build one, for the parser and the desktop alike).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Volumetric {
    /// Which PLC position register (index into `HR_POSITIONS`) is X, Y, Z.
    pub slots: [u8; 3],
    /// Position where u (v, w) = 0, µm.
    pub origin_um: [i32; 3],
    /// Stroke, µm: u = 1 at origin + stroke.
    pub stroke_um: [i32; 3],
    /// Tool length where l = 1, µm.
    pub tool_max_um: i32,
    /// Largest correction served per direction x, y, z (0.1 µm).
    pub max_correction: [i32; 3],
    pub sensors: Vec<VolSensor, MAX_VOL_SENSORS>,
    pub terms: Vec<VolTerm, MAX_VOL_TERMS>,
    spans: [Span; 4],
}

/// The parts of a section before validation.
#[derive(Debug, Clone, Copy)]
pub struct VolumetricSpec<'a> {
    pub slots: [u8; 3],
    pub origin_um: [i32; 3],
    pub stroke_um: [i32; 3],
    pub tool_max_um: i32,
    pub max_correction: [i32; 3],
    pub sensors: &'a [VolSensor],
    pub terms: &'a [VolTerm],
}

/// One evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VolOutput {
    /// Correction x, y, z in 0.1 µm (clamped); meaningful only with `VALID`.
    pub corrections: [i32; 3],
    /// The accumulators before the final rounding, 1/16 pm.
    pub acc: [i64; 3],
    /// [`vstatus`] bits.
    pub status: u16,
    /// The tool length used (after clamping), µm.
    pub tool_um: i32,
}

impl Volumetric {
    /// Validate a section: every premise of the overflow argument (module
    /// docs) is checked here, each refusal a named [`ImageError`].
    pub fn new(s: &VolumetricSpec<'_>) -> Result<Volumetric, ImageError> {
        let spans = Self::check(s)?;
        // Capacities checked by `check`.
        let mut sensors = Vec::new();
        let _ = sensors.extend_from_slice(s.sensors);
        let mut terms = Vec::new();
        let _ = terms.extend_from_slice(s.terms);
        Ok(Volumetric {
            slots: s.slots,
            origin_um: s.origin_um,
            stroke_um: s.stroke_um,
            tool_max_um: s.tool_max_um,
            max_correction: s.max_correction,
            sensors,
            terms,
            spans,
        })
    }

    /// An empty, unchecked section for the image parser to fill in place
    /// (then [`Volumetric::check_in_place`]; never used unchecked).
    // Inlined, so that `Option::insert` writes it in the model's own
    // section, not on the parser's stack first (5 KB).
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        Volumetric {
            slots: [0; 3],
            origin_um: [0; 3],
            stroke_um: [0; 3],
            tool_max_um: 0,
            max_correction: [0; 3],
            sensors: Vec::new(),
            terms: Vec::new(),
            spans: [Span::default(); 4],
        }
    }

    /// [`Volumetric::new`]'s checks, in its order, on a section filled in
    /// place (the parser's: no copy of the terms on the stack).
    pub(crate) fn check_in_place(&mut self) -> Result<(), ImageError> {
        self.spans = Self::check(&VolumetricSpec {
            slots: self.slots,
            origin_um: self.origin_um,
            stroke_um: self.stroke_um,
            tool_max_um: self.tool_max_um,
            max_correction: self.max_correction,
            sensors: &self.sensors,
            terms: &self.terms,
        })?;
        Ok(())
    }

    /// The checks of [`Volumetric::new`]; the spans of u, v, w and l.
    fn check(s: &VolumetricSpec<'_>) -> Result<[Span; 4], ImageError> {
        let mut spans = [Span::default(); 4];
        let per_axis = spans
            .iter_mut()
            .zip(s.slots)
            .zip(s.origin_um.iter().zip(s.stroke_um))
            .zip(s.max_correction);
        for ((((span, slot), (&origin, stroke)), max_correction), axis) in per_axis.zip(0u8..) {
            if usize::from(slot) >= MAX_AXES {
                return Err(ImageError::VolumetricAxisSlot { axis, slot });
            }
            let bad_stroke = ImageError::VolumetricStroke {
                axis,
                value: stroke,
            };
            let end = i64::from(origin) + i64::from(stroke);
            if !(2..=MAX_VOL_STROKE_UM).contains(&stroke) || end > i64::from(i32::MAX) {
                return Err(bad_stroke);
            }
            *span = i32::try_from(end)
                .ok()
                .and_then(|end| Span::new(origin, end))
                .ok_or(bad_stroke)?;
            if !(1..=MAX_CORRECTION).contains(&max_correction) {
                return Err(ImageError::VolumetricMaxCorrection {
                    direction: axis,
                    value: max_correction,
                });
            }
        }
        if !(2..=MAX_VOL_TOOL_UM).contains(&s.tool_max_um) {
            return Err(ImageError::VolumetricTool {
                value: s.tool_max_um,
            });
        }
        spans[3] = Span::new(0, s.tool_max_um).ok_or(ImageError::VolumetricTool {
            value: s.tool_max_um,
        })?;
        for (vs, i) in s.sensors.iter().zip(0u8..) {
            if usize::from(vs.sensor.channel) >= MAX_SENSORS {
                return Err(ImageError::SensorChannelOutOfRange {
                    sensor: i,
                    channel: vs.sensor.channel,
                });
            }
            let inside = |t: i32| (TEMP_MIN_16..=TEMP_MAX_16).contains(&t);
            if !inside(vs.sensor.ref_temp)
                || !inside(i32::from(vs.min))
                || !inside(i32::from(vs.max))
                || vs.min >= vs.max
            {
                return Err(ImageError::VolumetricTemperature { sensor: i });
            }
            if usize::from(i) >= MAX_VOL_SENSORS {
                return Err(ImageError::TooMany {
                    what: "volumetric sensors",
                    count: s.sensors.len(),
                    max: MAX_VOL_SENSORS,
                });
            }
        }
        if s.terms.is_empty() || s.terms.len() > MAX_VOL_TERMS {
            return Err(ImageError::TooMany {
                what: "volumetric terms",
                count: s.terms.len(),
                max: MAX_VOL_TERMS,
            });
        }
        for t in s.terms {
            if t.sensor != NONE && usize::from(t.sensor) >= s.sensors.len() {
                return Err(ImageError::BadIndex {
                    what: "volumetric term sensor",
                    index: t.sensor,
                });
            }
            if t.exps.iter().any(|&e| e > MAX_VOL_POWER) {
                return Err(ImageError::BadValue {
                    what: "volumetric term exponent",
                });
            }
        }
        Ok(spans)
    }

    /// Encoded payload length (section kind 3, without the 4-byte section header).
    pub fn encoded_len(&self) -> usize {
        12 + 3 * 12 + 16 * self.sensors.len() + 16 * self.terms.len()
    }

    /// The correction at `positions` (µm, indexed by [`Volumetric::slots`];
    /// a missing slot reads as the origin), tool length `tool_um` (µm) and
    /// `temps` (1/16 °C per section sensor; `None`: invalid). Integers only;
    /// the firmware serves exactly this, the desktop predicts with it.
    pub fn evaluate(&self, positions: &[i32], tool_um: i32, temps: &[Option<i32>]) -> VolOutput {
        let mut out = VolOutput::default();
        let (rise, status) = self.rises(temps);
        out.status |= status;
        let Some(rise) = rise else {
            return out;
        };
        // Powers 0..=3 of u, v, w, l in Q24.
        let mut pow = [[ONE_Q24; 4]; 4];
        #[allow(
            clippy::indexing_slicing,
            reason = "k < 4 = spans.len(); slots and origin_um (len 3) only when k < 3"
        )]
        for (k, p) in pow.iter_mut().enumerate() {
            let raw = if k < 3 {
                positions
                    .get(usize::from(self.slots[k]))
                    .copied()
                    .unwrap_or(self.origin_um[k])
            } else {
                tool_um
            };
            let (x, outside) = self.spans[k].normalise(raw);
            if outside {
                out.status |= if k < 3 {
                    vstatus::POSITION_CLAMPED
                } else {
                    vstatus::TOOL_CLAMPED
                };
            }
            if k == 3 {
                out.tool_um = raw.clamp(0, self.tool_max_um);
            }
            // x ∈ [−1, 1] Q24 → (x + 1)/2 ∈ [0, 1] Q24, rounded.
            let u = (x + ONE_Q24 + 1) >> 1;
            p[1] = u;
            p[2] = mul_q24(u, u);
            p[3] = mul_q24(p[2], u);
        }
        // Sums of the rounded terms (pm) per scale: constant (index 0) and
        // per kelvin of each sensor; scaled once at the end (exactly
        // Σ q·s, the integers are distributive).
        let mut sum = [[0i64; 3]; MAX_VOL_SENSORS + 1];
        for t in &self.terms {
            let [a, b, c, e] = t.exps;
            #[allow(clippy::indexing_slicing, reason = "each index is masked to 0..=3 < 4")]
            let m = mul_q24(
                mul_q24(
                    mul_q24(pow[0][usize::from(a & 3)], pow[1][usize::from(b & 3)]),
                    pow[2][usize::from(c & 3)],
                ),
                pow[3][usize::from(e & 3)],
            );
            let group = if t.sensor == NONE {
                0
            } else {
                usize::from(t.sensor) + 1
            };
            let m = i64::from(m);
            if let Some(g) = sum.get_mut(group) {
                for (a, &c) in g.iter_mut().zip(&t.coef) {
                    *a += (i64::from(c) * m + (1 << 23)) >> 24;
                }
            }
        }
        let mut acc = [0i64; 3];
        #[allow(
            clippy::indexing_slicing,
            reason = "d < 3 = the length of every row of sum"
        )]
        for (d, a) in acc.iter_mut().enumerate() {
            *a = sum[0][d] << 4;
            for (g, r) in sum[1..].iter().zip(&rise) {
                *a += g[d] * r;
            }
        }
        out.acc = acc;
        for ((c, &a), &max) in out
            .corrections
            .iter_mut()
            .zip(&acc)
            .zip(&self.max_correction)
        {
            let v = round_div(a, ACC_PER_TENTH_UM);
            let max = i64::from(max);
            let clamped = v.clamp(-max, max);
            if clamped != v {
                out.status |= vstatus::CLAMPED;
            }
            #[allow(
                clippy::cast_possible_truncation,
                reason = "clamped to ±max_correction, an i32"
            )]
            {
                *c = clamped as i32;
            }
        }
        out.status |= vstatus::VALID;
        out
    }

    /// Temperature rises (1/16 °C) against each sensor's reference, the
    /// temperature clamped into its envelope first (|rise| ≤ 2880); `None`
    /// with [`vstatus::SENSOR_FAULT`] when a sensor has no value. The
    /// five-axis section ([`crate::five_axis`]) scales by these same rises.
    pub(crate) fn rises(&self, temps: &[Option<i32>]) -> (Option<[i64; MAX_VOL_SENSORS]>, u16) {
        let mut status = 0;
        let mut rise = [0i64; MAX_VOL_SENSORS];
        for (i, (s, r)) in self.sensors.iter().zip(rise.iter_mut()).enumerate() {
            let Some(t) = temps.get(i).copied().flatten() else {
                return (None, status | vstatus::SENSOR_FAULT);
            };
            let c = t.clamp(i32::from(s.min), i32::from(s.max));
            if c != t {
                status |= vstatus::TEMPERATURE_CLAMPED;
            }
            *r = i64::from(c - s.sensor.ref_temp);
        }
        (Some(rise), status)
    }

    /// The position of direction `k` (0 x, 1 y, 2 z) the evaluation uses:
    /// the PLC's slot (a missing slot reads as the origin), held inside
    /// origin … origin + stroke. `None` for k > 2.
    pub fn position_used(&self, k: usize, positions: &[i32]) -> Option<i32> {
        let slot = usize::from(*self.slots.get(k)?);
        let origin = *self.origin_um.get(k)?;
        let span = self.spans.get(k)?;
        let raw = positions.get(slot).copied().unwrap_or(origin);
        Some(raw.clamp(span.lo, span.hi))
    }

    /// Bound on |served − exact polynomial of the same integer coefficients|
    /// in 0.1 µm at temperature rises `rise_16` (1/16 °C, as evaluated),
    /// before the clamp (module docs, "Quantisation").
    #[cfg(feature = "std")]
    pub fn error_bound_tenth_um(&self, rise_16: &[i32]) -> f64 {
        let mut pm = [0.0f64; 3];
        for t in &self.terms {
            let degree: u32 = t.exps.iter().map(|&e| u32::from(e)).sum();
            // Each variable within 1 LSB, a power of exponent e within
            // e + (e − 1)/2 LSB, the three combining products ½ LSB each.
            let eps_m = (1.5 * f64::from(degree) + 2.0) / f64::from(ONE_Q24);
            let scale_k = if t.sensor == NONE {
                1.0
            } else {
                f64::from(rise_16.get(usize::from(t.sensor)).copied().unwrap_or(0)).abs() / 16.0
            };
            for (p, &c) in pm.iter_mut().zip(&t.coef) {
                *p += (f64::from(c).abs() * eps_m + 0.5) * scale_k;
            }
        }
        0.5 + pm.iter().fold(0.0f64, |m, &p| m.max(p)) / 1e5
    }
}

/// a / d rounded half away from zero (d > 0).
#[inline]
fn round_div(a: i64, d: i64) -> i64 {
    if a >= 0 {
        (a + d / 2) / d
    } else {
        -((-a + d / 2) / d)
    }
}

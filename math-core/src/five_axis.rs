//! The five-axis part of the volumetric correction (issue 31 item 4, image
//! section kind 4): the rotary axes' errors of a table-tilting XYZ-A(x)-C(z)
//! machine (`shared/formats/rtest.md`, seed 001's chain), evaluated in
//! integers at the PLC's A and C and added to the linear axes' error of
//! the volumetric section (kind 3) at x, y, z. The board serves the sum;
//! the desktop predicts it by calling [`evaluate`], the function the
//! firmware runs.
//!
//! # The chain and what is served
//!
//! The workpiece hangs from the turntable's base through
//! `W = T(pivot_A) · L_A · Rx(a) · E_A(a) · T(offset_C) · L_C · Rz(c) · E_C(c)`
//! (`tcomp_geometry::five_axis`, the same factors): `L_k` the axis's
//! location errors (constant in the angle, linear in the temperatures),
//! `E_k(θ)` its component errors (Fourier series in the angle). To first
//! order an error transform (δ translation, ε small rotation) whose nominal
//! prefix in W has rotation R_k and origin o_k moves the workpiece by
//! R_k·δ + (R_k·ε) × (p − o_k) in the machine frame, at the tool point
//! p = (x, y, z + L). Hence the tool-tip error **in the machine frame**
//! (tool relative to workpiece, along the machine's X, Y, Z):
//!
//! ```text
//! e = e_lin(x, y, z, L, T) − Σ_k [ R_k·δ_k + (R_k·ε_k) × (p − o_k) ]
//!   k = L_A: R = I,           o = pivot_A,                δ = (0, YOA, ZOA), ε = (0, BOA, COA)
//!   k = E_A: R = Rx(a),       o = pivot_A,                δ = (EXA, EYA, EZA)(a), ε = (EAA, EBA, ECA)(a)
//!   k = L_C: R = Rx(a),       o = pivot_A + Rx(a)·offset_C, δ = (XOC, YOC, 0), ε = (AOC, BOC, 0)
//!   k = E_C: R = Rx(a)·Rz(c), o = the same,               δ = (EXC, EYC, EZC)(c), ε = (EAC, EBC, ECC)(c)
//! ```
//!
//! e_lin is the kind-3 polynomial (the linear axes' tool-tip error), which
//! is already in the machine frame. The registers hold e, as they hold
//! e_lin without a five-axis section (at A = C = 0 with no rotary errors
//! the two are bit-identical): **the CNC subtracts e from its X, Y, Z
//! commands** (first order: moving the linear axes by −e cancels the
//! error at the tool point; A and C are not corrected).
//!
//! **R-test location mode** (flag [`FIVE_AXIS_RTEST_LOCATION`], issue 31
//! item 3): an identified model's location errors are a rotation about
//! the actual axis line, zero at A = C = 0 — to first order the axis moves
//! its table by `(I − R(θ))·ξ_L` in the frame it stands on. With the flag
//! the L_A row serves δ, ε = (I − Rx(a))·(0, YOA, ZOA), (I − Rx(a))·(0, BOA,
//! COA) and the L_C row (I − Rz(c))·(XOC, YOC, 0), (I − Rz(c))·(AOC, BOC, 0)
//! (R, o unchanged), so a location error's **thermal drift** `(I − R)·ΔT·d`
//! is served exactly: the slots stay linear in the temperatures. Without
//! the flag (every image before it) the slots are served as written.
//!
//! Location errors (rtest.md names, [`LOCATION_NAMES`]) are `c₀ + Σᵢ cᵢ·ΔTᵢ`
//! over the first `n_sensors` sensors of the kind-3 section (the same
//! rises, clamped into the same envelopes). Component errors are static:
//! `f(θ) = Σ_{k=1..order} a_k·(cos kθ − 1) + b_k·sin kθ` (zero at 0°, as in
//! `tcomp_geometry::five_axis::Fourier`), order ≤ [`MAX_FOURIER_ORDER`].
//!
//! # Formats (all integers)
//!
//! | quantity | type | unit |
//! |---|---|---|
//! | A, C (PLC) | i32 | 0.001° (holding registers 36–39), clamped into the section's ranges |
//! | sin, cos | i32 | Q30 ([`crate::trig`]) |
//! | translation coefficient | i32 | pm (per kelvin: pm/K) |
//! | angle coefficient | i32 | prad (per kelvin: prad/K) |
//! | translation value δ | i64 | pm (rounded once) |
//! | angle value ε | i64 | nrad (rounded once) |
//! | pivot, offset, tool point p, arms | i64 | µm |
//! | rotary sum | i64 | fm (10⁻¹⁵ m): δ·1000 and nrad·µm |
//! | total accumulator | i64 | ½ fm: kind-3's 1/16 pm · 125 + rotary fm · 2 |
//! | correction | i32 | 0.1 µm, one rounding (÷ 2·10⁸), clamped to the max correction |
//!
//! # Why nothing overflows
//!
//! The parser enforces every premise ([`FiveAxis::new`],
//! [`FiveAxis::check_with`]): each location error is at most 1 mm or
//! 1 mrad anywhere in the envelope, `|c₀| + 180·Σ|cᵢ| ≤ 10⁹` (|ΔT| ≤ 180 K
//! by the kind-3 envelope), and each component error
//! `Σ_k 2|a_k| + |b_k| ≤ 10⁹` ([`MAX_ERROR`]); pivot and offset within
//! ±2^27 µm (134 m) per component; the kind-3 section's positions within
//! ±2^28 µm; the tool ≤ 10⁷ µm < 2^24.
//! - location: |16c₀ + Σ cᵢ·riseᵢ| ≤ 16·10⁹ < 2^34 (rise in 1/16 °C);
//!   δ ≤ 10⁹ pm < 2^30, ε ≤ 10⁶ nrad < 2^20.
//! - Fourier: |Σ a_k(cos−1) + b_k·sin| ≤ 10⁹ · 2^30 < 2^60 (Q30 trig),
//!   then the same δ, ε bounds.
//! - rotations: Q30 entries ≤ 2^30; R·δ: three products < 2^60 each, sum
//!   < 2^62; R·ε < 2^52; Rx(a)·offset < 2^58.
//! - R-test mode: (I − R)·v has |·|₂ ≤ 2|v|₂ ≤ 2√2·10⁹ pm < 2^32 (two
//!   non-zero components) or 2√2·10⁶ nrad < 2^22, within `rotate`'s premise.
//! - arms: |p| ≤ 2^28 + 2^24, |o| ≤ 2^27 + 2^28 + 1, so |p − o| < 2^30 µm;
//!   a cross-product component (nrad ≤ 2^21 × µm < 2^30) < 2^52 fm (R-test
//!   location rows: 2^22 nrad, < 2^53); four transforms < 3·2^53 < 2^55 fm,
//!   plus 1000·Σ R·δ < 2^44: the rotary sum < 2^55.
//! - total: kind-3's |acc| < 2^52 (its module docs) · 125 < 2^59, plus
//!   2 · 2^55: < 2^60; the rounding adds 10⁸ < 2^27. The quotient is
//!   clamped in i64 before it becomes an i32.
//!
//! `math-core/tests/five_axis.rs` evaluates the extreme section (every
//! error at its bound, angles and positions at their edges) with overflow
//! checks on.
//!
//! # Quantisation
//!
//! Against the first-order formula in f64 with the same integer
//! coefficients: sin/cos within 0.85·2^-30 (and one more rounding for the
//! products in Rx·Rz), δ within ½ pm, ε within ½ nrad (times |p − o|: 0.5 nm
//! at a 1 m arm), the cross products exact, the final rounding ½ of
//! 0.1 µm. The rotary part is therefore within ½·0.1 µm + 4·(0.5 nm per m
//! of arm + 1 pm) of its exact value (R-test mode: the two location rows
//! each add one rounding of R·ε, ½ nrad, and the location value's ½ nrad
//! counts twice through I − R: 2 nm per m of arm each); the desktop's test checks it against
//! `tcomp_geometry::five_axis::tool_tip_error_linear5`.

use crate::image::error::ImageError;
pub use crate::image::format::{FIVE_AXIS_FLAGS, FIVE_AXIS_RTEST_LOCATION};
use crate::limits::MAX_CORRECTION;
use crate::trig::{sin_cos_mdeg, MDEG_PER_TURN, ONE_Q30};
use crate::volumetric::{vstatus, Volumetric, MAX_VOL_SENSORS, MAX_VOL_TOOL_UM};

/// Kept here for its old path; defined with the other limits.
pub use crate::limits::MAX_FOURIER_ORDER;
/// Largest location or component error anywhere: 10⁹ pm (1 mm) or 10⁹ prad
/// (1 mrad). An error beyond that is a wrong nominal, not a compensation.
pub const MAX_ERROR: u64 = 1_000_000_000;
/// Largest |pivot_A|, |offset_C| component, µm (2^27 ≈ 134 m).
pub const MAX_GEOMETRY_UM: i32 = 1 << 27;
/// The kind-3 section's positions must stay within ±2^28 µm (268 m).
pub const MAX_POSITION_UM: i64 = 1 << 28;
/// Largest |A|, |C| range bound, 0.001° (two turns).
pub const MAX_ANGLE_MDEG: i32 = 720_000;
/// Largest temperature rise the kind-3 envelope allows, K (2880/16).
const MAX_RISE_K: u64 = 180;

/// The eight location errors and the component-error letters, in the
/// section's order (defined with the image format's constants).
pub use crate::image::format::{LOCATION_NAMES, MOTION_LETTERS};
/// Which of [`LOCATION_NAMES`] are angles (prad), the others translations (pm).
const LOCATION_IS_ANGLE: [bool; 8] = [false, false, true, true, false, false, true, true];
/// Bits of input register 334 (what the five-axis evaluation did).
pub mod fstatus {
    /// Registers 180–185 include the five-axis part (and are valid).
    pub const INCLUDED: u16 = 1 << 0;
    /// The image has no five-axis section: 180–185 are the three-axis correction.
    pub const NO_SECTION: u16 = 1 << 1;
    /// The PLC has not written A and C since boot: 180–185 not available.
    pub const NO_ANGLES: u16 = 1 << 2;
    /// A was outside the section's range and held at its edge.
    pub const A_CLAMPED: u16 = 1 << 3;
    /// C was outside the section's range and held at its edge.
    pub const C_CLAMPED: u16 = 1 << 4;
}

/// The five-axis section, validated on its own ([`FiveAxis::new`]) and
/// against the image's kind-3 section ([`FiveAxis::check_with`]).
/// (`non_exhaustive`: built only through [`FiveAxis::new`].)
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct FiveAxis {
    /// Nominal point on the A axis, machine frame, linear axes at zero (µm).
    pub pivot_a_um: [i32; 3],
    /// Nominal C-axis origin relative to `pivot_a`, in the A frame (µm).
    pub offset_c_um: [i32; 3],
    /// Range of A and of C (0.001°): min, max; outside is held at the edge.
    pub a_range_mdeg: [i32; 2],
    pub c_range_mdeg: [i32; 2],
    /// Largest total correction served per direction x, y, z (0.1 µm).
    pub max_correction: [i32; 3],
    /// Temperature columns of the location errors: the first `n_sensors`
    /// sensors of the kind-3 section.
    pub n_sensors: u8,
    /// Fourier order of the component errors (0: none).
    pub order: u8,
    /// [`FIVE_AXIS_RTEST_LOCATION`]: the location slots are in the R-test
    /// convention (see the module docs); 0: the board's `L·R` form.
    pub flags: u8,
    /// Per location error ([`LOCATION_NAMES`]): the constant, then per
    /// kelvin of each sensor (pm or prad; unused columns 0).
    pub location: [[i32; 1 + MAX_VOL_SENSORS]; 8],
    /// Per axis (0: A, 1: C), per component error ([`MOTION_LETTERS`]),
    /// per order k = 1 … order: [a_k (cos), b_k (sin)] (pm or prad; unused 0).
    pub motion: [[[[i32; 2]; MAX_FOURIER_ORDER]; 6]; 2],
}

/// The parts of a section before validation.
#[derive(Debug, Clone, Copy, Default)]
pub struct FiveAxisSpec {
    pub pivot_a_um: [i32; 3],
    pub offset_c_um: [i32; 3],
    pub a_range_mdeg: [i32; 2],
    pub c_range_mdeg: [i32; 2],
    pub max_correction: [i32; 3],
    pub n_sensors: u8,
    pub order: u8,
    pub flags: u8,
    pub location: [[i32; 1 + MAX_VOL_SENSORS]; 8],
    pub motion: [[[[i32; 2]; MAX_FOURIER_ORDER]; 6]; 2],
}

/// One evaluation of the volumetric correction with the five-axis part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FiveOutput {
    /// Total correction x, y, z in 0.1 µm, machine frame (clamped);
    /// meaningful only with [`vstatus::VALID`] in `status`.
    pub corrections: [i32; 3],
    /// The rotary part alone (0.1 µm, clamped the same way).
    pub rotary: [i32; 3],
    /// [`vstatus`] bits of the whole evaluation (kind 3's, with CLAMPED
    /// for the total and ANGLE_CLAMPED).
    pub status: u16,
    /// [`fstatus`] bits.
    pub five_status: u16,
    /// A and C used (after clamping), 0.001°.
    pub angles_mdeg: [i32; 2],
    /// The tool length used (after clamping), µm.
    pub tool_um: i32,
}

impl FiveAxis {
    /// Validate a section on its own: every premise of the overflow
    /// argument that does not depend on the kind-3 section.
    pub fn new(s: &FiveAxisSpec) -> Result<FiveAxis, ImageError> {
        if usize::from(s.order) > MAX_FOURIER_ORDER {
            return Err(ImageError::FiveAxisOrder { order: s.order });
        }
        if s.flags & !FIVE_AXIS_FLAGS != 0 {
            return Err(ImageError::FiveAxisFlags { flags: s.flags });
        }
        if usize::from(s.n_sensors) > MAX_VOL_SENSORS {
            return Err(ImageError::FiveAxisSensors {
                count: s.n_sensors,
                available: 0,
            });
        }
        let geometry_ok = s
            .pivot_a_um
            .iter()
            .chain(&s.offset_c_um)
            .all(|v| v.unsigned_abs() <= MAX_GEOMETRY_UM.unsigned_abs());
        if !geometry_ok {
            return Err(ImageError::FiveAxisGeometry);
        }
        for (range, axis) in [s.a_range_mdeg, s.c_range_mdeg].iter().zip(0u8..) {
            let [lo, hi] = *range;
            if lo >= hi || lo < -MAX_ANGLE_MDEG || hi > MAX_ANGLE_MDEG {
                return Err(ImageError::FiveAxisAngleRange { axis });
            }
        }
        for (&m, direction) in s.max_correction.iter().zip(0u8..) {
            if !(1..=MAX_CORRECTION).contains(&m) {
                return Err(ImageError::FiveAxisMaxCorrection {
                    direction,
                    value: m,
                });
            }
        }
        let n = usize::from(s.n_sensors);
        for (row, error) in s.location.iter().zip(0u8..) {
            // |c₀| + 180 · Σ|cᵢ| over the used columns.
            if !within_bound(row, 1 + n, location_weight) {
                return Err(ImageError::FiveAxisErrorTooLarge { error });
            }
        }
        let order = usize::from(s.order);
        for (axis_terms, axis) in s.motion.iter().zip(0u8..) {
            for (terms, e) in axis_terms.iter().zip(0u8..) {
                // Σ 2|a_k| + |b_k| over the orders used.
                if !within_bound(terms.as_flattened(), 2 * order, fourier_weight) {
                    return Err(ImageError::FiveAxisErrorTooLarge {
                        error: 8 + 6 * axis + e,
                    });
                }
            }
        }
        Ok(FiveAxis {
            pivot_a_um: s.pivot_a_um,
            offset_c_um: s.offset_c_um,
            a_range_mdeg: s.a_range_mdeg,
            c_range_mdeg: s.c_range_mdeg,
            max_correction: s.max_correction,
            n_sensors: s.n_sensors,
            order: s.order,
            flags: s.flags,
            location: s.location,
            motion: s.motion,
        })
    }

    /// The premises that need the image's kind-3 section: it exists, has at
    /// least `n_sensors` sensors, and its positions stay within ±2^28 µm.
    pub fn check_with(&self, vol: Option<&Volumetric>) -> Result<(), ImageError> {
        let Some(v) = vol else {
            return Err(ImageError::FiveAxisWithoutVolumetric);
        };
        if usize::from(self.n_sensors) > v.sensors.len() {
            return Err(ImageError::FiveAxisSensors {
                count: self.n_sensors,
                available: u8::try_from(v.sensors.len()).unwrap_or(u8::MAX),
            });
        }
        let inside = v.origin_um.iter().zip(&v.stroke_um).all(|(&o, &s)| {
            let (lo, hi) = (i64::from(o), i64::from(o) + i64::from(s));
            lo >= -MAX_POSITION_UM && hi <= MAX_POSITION_UM
        });
        if !inside || v.tool_max_um > MAX_VOL_TOOL_UM {
            return Err(ImageError::FiveAxisGeometry);
        }
        Ok(())
    }

    /// Encoded payload length (section kind 4, without the section header).
    pub fn encoded_len(&self) -> usize {
        4 + 24 + 16 + 12 + 32 * (1 + usize::from(self.n_sensors)) + 96 * usize::from(self.order)
    }

    #[inline(never)]
    /// Location error values at temperature rises `rise` (1/16 °C): each
    /// translation in pm, each angle in nrad.
    fn location_values(&self, rise: &[i64; MAX_VOL_SENSORS]) -> [i64; 8] {
        let n = usize::from(self.n_sensors);
        let mut out = [0i64; 8];
        for ((o, row), &angle) in out.iter_mut().zip(&self.location).zip(&LOCATION_IS_ANGLE) {
            let (constant, per_k) = row.split_first().unwrap_or((&0, &[]));
            let v16 = per_k
                .iter()
                .zip(rise)
                .take(n)
                .fold(16 * i64::from(*constant), |acc, (&c, &r)| {
                    acc + i64::from(c) * r
                });
            *o = if angle {
                round_div(v16, 16_000)
            } else {
                round_shift(v16, 4)
            };
        }
        out
    }

    /// Component errors of one axis at `angle_mdeg`: [δx, δy, δz] pm and
    /// [εx, εy, εz] nrad.
    fn motion_values(&self, axis: usize, angle_mdeg: i32) -> ([i64; 3], [i64; 3]) {
        let mut acc = [0i64; 6];
        let turn = angle_mdeg.rem_euclid(MDEG_PER_TURN);
        let Some(terms) = self.motion.get(axis) else {
            return ([0; 3], [0; 3]);
        };
        for k in 0..usize::from(self.order).min(MAX_FOURIER_ORDER) {
            // (k + 1) · turn < 4 · 360,000: no overflow.
            let mult = i32::try_from(k + 1).unwrap_or(1);
            let (s, c) = sin_cos_mdeg(turn * mult);
            let (s, cm1) = (i64::from(s), i64::from(c) - i64::from(ONE_Q30));
            for (a, t) in acc.iter_mut().zip(terms) {
                if let Some([ak, bk]) = t.get(k) {
                    *a += i64::from(*ak) * cm1 + i64::from(*bk) * s;
                }
            }
        }
        let [dx, dy, dz, ex, ey, ez] = acc;
        let t = |v: i64| round_shift(v, 30);
        let r = |v: i64| round_div(v, 1000 << 30);
        ([t(dx), t(dy), t(dz)], [r(ex), r(ey), r(ez)])
    }
}

/// Σ weight(k)·|cₖ| over the first `used` coefficients ≤ [`MAX_ERROR`],
/// and every later one zero. Out of line (and the weight a function
/// pointer): called for 32 rows, it would otherwise be unrolled.
#[inline(never)]
fn within_bound(c: &[i32], used: usize, weight: fn(usize) -> u64) -> bool {
    let mut sum = 0u64;
    for (k, v) in c.iter().enumerate() {
        let a = u64::from(v.unsigned_abs());
        if k < used {
            sum += weight(k) * a;
        } else if a != 0 {
            return false;
        }
    }
    sum <= MAX_ERROR
}

/// A location row: the constant, then slopes per kelvin (|ΔT| ≤ 180 K).
fn location_weight(k: usize) -> u64 {
    if k == 0 {
        1
    } else {
        MAX_RISE_K
    }
}

/// A Fourier row: cos, sin, cos, … (|cos kθ − 1| ≤ 2, |sin kθ| ≤ 1).
fn fourier_weight(k: usize) -> u64 {
    if k.is_multiple_of(2) {
        2
    } else {
        1
    }
}

/// A 3 × 3 rotation in Q30.
type Rot = [[i64; 3]; 3];

/// One error transform of the chain: nominal rotation (None: the
/// identity) and origin of its prefix, δ (pm), ε (nrad).
type Transform<'a> = (Option<&'a Rot>, &'a [i64; 3], [i64; 3], [i64; 3]);

/// R · v, rounded from Q30 (|v| < 2^32 per component: < 2^63).
fn rotate(r: &Rot, v: &[i64; 3]) -> [i64; 3] {
    r.map(|row| round_shift(row[0] * v[0] + row[1] * v[1] + row[2] * v[2], 30))
}

/// (I − R)·(u, v) for a rotation by (cos, sin) in Q30 in the plane of
/// (u, v): one rounding of R·v per component, as [`rotate`] would give
/// (|u|, |v| < 2^32: the sums < 2^63).
fn i_minus_r(c: i64, s: i64, u: i64, v: i64) -> (i64, i64) {
    (
        u - round_shift(c * u - s * v, 30),
        v - round_shift(s * u + c * v, 30),
    )
}

/// a × b.
fn cross(a: &[i64; 3], b: &[i64; 3]) -> [i64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(never)]
/// The rotary part Σ_k [R_k·δ_k·1000 + (R_k·ε_k) × (p − o_k)] in fm, at
/// the tool point `p` (µm) and the angles used.
fn rotary_sum_fm(
    f: &FiveAxis,
    p: [i64; 3],
    a: i32,
    c: i32,
    rise: &[i64; MAX_VOL_SENSORS],
) -> [i64; 3] {
    let (sa, ca) = sin_cos_mdeg(a);
    let (sc, cc) = sin_cos_mdeg(c);
    let (sa, ca, sc, cc) = (i64::from(sa), i64::from(ca), i64::from(sc), i64::from(cc));
    let one = i64::from(ONE_Q30);
    let rx: Rot = [[one, 0, 0], [0, ca, -sa], [0, sa, ca]];
    let q = |x: i64, y: i64| round_shift(x * y, 30);
    let rxz: Rot = [
        [cc, -sc, 0],
        [q(ca, sc), q(ca, cc), -sa],
        [q(sa, sc), q(sa, cc), ca],
    ];
    let pivot = f.pivot_a_um.map(i64::from);
    let off = rotate(&rx, &f.offset_c_um.map(i64::from));
    let o_c = [pivot[0] + off[0], pivot[1] + off[1], pivot[2] + off[2]];
    let [xoc, yoc, aoc, boc, yoa, zoa, boa, coa] = f.location_values(rise);
    let (da, ea) = f.motion_values(0, a);
    let (dc, ec) = f.motion_values(1, c);
    let (mut la, mut lc) = (
        ([0, yoa, zoa], [0, boa, coa]),
        ([xoc, yoc, 0], [aoc, boc, 0]),
    );
    if f.flags & FIVE_AXIS_RTEST_LOCATION != 0 {
        // R-test convention: the axis turns about its actual line, so its
        // location error moves the table by (I − R(θ))·ξ_L in its base
        // frame: A's in the y-z plane, C's in the x-y plane (the component
        // along the axis is 0).
        let (ya, za) = i_minus_r(ca, sa, yoa, zoa);
        let (ba, ga) = i_minus_r(ca, sa, boa, coa);
        la = ([0, ya, za], [0, ba, ga]);
        let (xc, yc) = i_minus_r(cc, sc, xoc, yoc);
        let (ac, bc) = i_minus_r(cc, sc, aoc, boc);
        lc = ([xc, yc, 0], [ac, bc, 0]);
    }
    // L_A's prefix is the identity: no rotation (rotate would return v).
    let transforms: [Transform<'_>; 4] = [
        (None, &pivot, la.0, la.1),
        (Some(&rx), &pivot, da, ea),
        (Some(&rx), &o_c, lc.0, lc.1),
        (Some(&rxz), &o_c, dc, ec),
    ];
    let mut sum = [0i64; 3];
    for (r, o, delta, eps) in transforms {
        let (rd, re) = match r {
            Some(r) => (rotate(r, &delta), rotate(r, &eps)),
            None => (delta, eps),
        };
        let arm = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        let x = cross(&re, &arm);
        for ((s, d), x) in sum.iter_mut().zip(rd).zip(x) {
            *s += 1000 * d + x;
        }
    }
    sum
}

/// The volumetric correction with the five-axis part at `positions`
/// (µm, the kind-3 section's slots), tool length `tool_um`, `angles_mdeg`
/// = [A, C] (0.001°) and `temps` (1/16 °C per kind-3 sensor). Integers
/// only, no panics; the firmware serves exactly this, the desktop
/// predicts with it. `f` must have passed [`FiveAxis::check_with`] `vol`
/// (the parser does this); otherwise the result is still total, without
/// the overflow guarantee.
#[inline(never)]
pub fn evaluate(
    vol: &Volumetric,
    f: &FiveAxis,
    positions: &[i32],
    tool_um: i32,
    angles_mdeg: [i32; 2],
    temps: &[Option<i32>],
) -> FiveOutput {
    let lin = vol.evaluate(positions, tool_um, temps);
    let [a_raw, c_raw] = angles_mdeg;
    // max then min, not clamp: total even for a range the parser would refuse.
    let a = a_raw.max(f.a_range_mdeg[0]).min(f.a_range_mdeg[1]);
    let c = c_raw.max(f.c_range_mdeg[0]).min(f.c_range_mdeg[1]);
    let mut out = FiveOutput {
        status: lin.status & !vstatus::CLAMPED,
        angles_mdeg: [a, c],
        tool_um: lin.tool_um,
        ..FiveOutput::default()
    };
    if a != a_raw {
        out.five_status |= fstatus::A_CLAMPED;
    }
    if c != c_raw {
        out.five_status |= fstatus::C_CLAMPED;
    }
    if a != a_raw || c != c_raw {
        out.status |= vstatus::ANGLE_CLAMPED;
    }
    let (Some(rise), true) = (vol.rises(temps).0, lin.status & vstatus::VALID != 0) else {
        return out;
    };
    let pos = |k: usize| i64::from(vol.position_used(k, positions).unwrap_or(0));
    let p = [pos(0), pos(1), pos(2) + i64::from(lin.tool_um)];
    let rot = rotary_sum_fm(f, p, a, c, &rise);
    for (d, ((corr, rpart), max)) in out
        .corrections
        .iter_mut()
        .zip(out.rotary.iter_mut())
        .zip(&f.max_correction)
        .enumerate()
    {
        let r_half_fm = -2 * rot.get(d).copied().unwrap_or(0);
        let total = lin.acc.get(d).copied().unwrap_or(0) * 125 + r_half_fm;
        let max = i64::from(*max);
        let v = round_div(total, HALF_FM_PER_TENTH_UM);
        if v.clamp(-max, max) != v {
            out.status |= vstatus::CLAMPED;
        }
        *corr = clamp_i32(v, max);
        *rpart = clamp_i32(round_div(r_half_fm, HALF_FM_PER_TENTH_UM), max);
    }
    out.five_status |= fstatus::INCLUDED;
    out
}

/// ½ fm per 0.1 µm (the total accumulator's unit per register unit).
pub const HALF_FM_PER_TENTH_UM: i64 = 200_000_000;

/// `v` clamped to ±max (max ≤ MAX_CORRECTION) as an i32.
fn clamp_i32(v: i64, max: i64) -> i32 {
    i32::try_from(v.clamp(-max, max)).unwrap_or(0)
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

/// a / 2^s rounded (ties up).
#[inline(always)]
fn round_shift(a: i64, s: u32) -> i64 {
    (a + (1 << (s - 1))) >> s
}

//! Sine and cosine of an angle in 0.001° (the unit of the PLC's rotary
//! positions), in integers only: the board and the desktop call this one
//! function, so a five-axis correction ([`crate::five_axis`]) agrees bit
//! for bit wherever it is evaluated.
//!
//! Why hand-written: `micromath` (and `libm`) work in floating point;
//! `micromath`'s `sin`/`cos` are f32 approximations (about 1e-3 relative,
//! coarser than the µrad that matters for a 1 m arm), and a float result
//! is only bit-identical across targets if every operation, its rounding
//! and the compiler's contraction (FMA) agree. The rest of the core is
//! integer precisely so that this never has to be argued; the same holds
//! here.
//!
//! Scheme (the textbook one): reduce the angle exactly to [0°, 360°)
//! (`rem_euclid` on the integer), take the quadrant and then the octant
//! (sin and cos of 90° − t swap), so the kernel only sees
//! t ∈ [0°, 45°]; convert t to radians in Q32 (x = t · π/180000 by one
//! 64-bit product with a 48-bit-scaled constant), and evaluate the Taylor
//! polynomials by Horner in Q32 with i64 products:
//!
//! ```text
//! sin x = x · (1 + y·(−1/3! + y·(1/5! + y·(−1/7! + y·(1/9! − y/11!)))))     y = x²
//! cos x = 1 + y·(−1/2! + y·(1/4! + y·(−1/6! + y·(1/8! + y·(−1/10! + y/12!))))))
//! ```
//!
//! Error bound ([`SIN_COS_MAX_ERROR`]): on x ≤ π/4 the first dropped terms
//! are x¹³/13! < 7·10⁻¹² and x¹⁴/14! < 4·10⁻¹³ (< 0.03 LSB of Q32); x
//! carries ≤ 0.85 LSB of Q32 (its rounding and the constant's), which
//! passes into sin and cos with a factor ≤ 1; each Horner product adds
//! ½ LSB and each coefficient ½ LSB, damped by the powers of y ≤ 0.62
//! that follow them: the kernel is within 1.4 LSB of Q32 (measured: 1.36),
//! i.e. 0.35 LSB of Q30, and the final rounding to Q30 adds ½ LSB:
//! ≤ 0.85 · 2^-30 ≈ 7.9·10⁻¹⁰ in all (a 1 m arm: 0.8 nm).
//! `math-core/tests/trig.rs` checks every one of the 360,000 inputs of a
//! turn against f64 (any other i32 reduces exactly onto one of them) and
//! a property test with overflow checks on.
//!
//! Overflow: t < 2^16 and the constant < 2^33, so t·K < 2^49; x < 2^32 ·
//! 0.79 < 2^31.7, so x² < 2^63.3 is formed in u64 and y = x² >> 32 < 2^31.3; every Horner accumulator stays below
//! 2^31 in magnitude (|coefficient + y·…| ≤ ½ · 2^32), so each product
//! is below 2^62.3 < 2^63; the final x · q (|q| < 2^28.7) < 2^61.

/// One in Q30, the output format.
pub const ONE_Q30: i32 = 1 << 30;
/// 0.001° per full turn.
pub const MDEG_PER_TURN: i32 = 360_000;
const MDEG_QUARTER: i32 = 90_000;
const MDEG_EIGHTH: i32 = 45_000;

/// Largest |sin_cos_mdeg(a) − (sin, cos)(a · π/180000)| in units of
/// 2^-30, over every i32 (the module docs derive it; a test checks every
/// input of a turn). 0.85 LSB ≈ 7.9·10⁻¹⁰.
pub const SIN_COS_MAX_ERROR: f64 = 0.85;

/// π/180000 · 2^48, rounded (radians per 0.001°, scaled so that
/// t · K >> 16 is Q32).
const RAD_PER_MDEG_Q48: i64 = 4_912_665_106;

/// 1/n! in Q32 for the sine's odd and the cosine's even terms.
const S3: i64 = 715_827_883;
const S5: i64 = 35_791_394;
const S7: i64 = 852_176;
const S9: i64 = 11_836;
const S11: i64 = 108;
const C2: i64 = 2_147_483_648;
const C4: i64 = 178_956_971;
const C6: i64 = 5_965_232;
const C8: i64 = 106_522;
const C10: i64 = 1_184;
const C12: i64 = 9;
const ONE_Q32: i64 = 1 << 32;

/// a · b / 2^32, rounded (to nearest, ties up).
#[inline(always)]
fn mul_q32(a: i64, b: i64) -> i64 {
    (a * b + (1 << 31)) >> 32
}

/// (sin t, cos t) in Q32 for t ∈ [0, 45000] (0.001°).
#[inline]
fn kernel(t: i32) -> (i64, i64) {
    let x = (i64::from(t) * RAD_PER_MDEG_Q48 + (1 << 15)) >> 16;
    // x ≥ 0 and x < 2^31.7: the square needs the u64's top bit.
    let xu = x.unsigned_abs();
    let y = i64::try_from((xu * xu + (1 << 31)) >> 32).unwrap_or(i64::MAX);
    let mut p = S9 - mul_q32(y, S11);
    p = -S7 + mul_q32(y, p);
    p = S5 + mul_q32(y, p);
    p = -S3 + mul_q32(y, p);
    let s = x + mul_q32(x, mul_q32(y, p));
    let mut q = -C10 + mul_q32(y, C12);
    q = C8 + mul_q32(y, q);
    q = -C6 + mul_q32(y, q);
    q = C4 + mul_q32(y, q);
    q = -C2 + mul_q32(y, q);
    let c = ONE_Q32 + mul_q32(y, q);
    (s, c)
}

/// Q32 in [−1, 1] → Q30, rounded.
#[inline(always)]
#[allow(
    clippy::cast_possible_truncation,
    reason = "|v| <= 2^32 (plus < 1 LSB): the result is within ±2^30"
)]
fn to_q30(v: i64) -> i32 {
    ((v + 2) >> 2) as i32
}

/// (sin, cos) of `angle_mdeg` (0.001°, any i32) in Q30. Total: no input
/// panics or overflows. sin(0) = 0 and cos(0) = 2^30 exactly, and the
/// values at multiples of 90° are exact. Out of line: called up to ten
/// times per five-axis evaluation; inlined it costs flash for nothing.
#[inline(never)]
pub fn sin_cos_mdeg(angle_mdeg: i32) -> (i32, i32) {
    let r = angle_mdeg.rem_euclid(MDEG_PER_TURN);
    let quadrant = r / MDEG_QUARTER;
    let t = r % MDEG_QUARTER;
    let (s, c) = if t <= MDEG_EIGHTH {
        kernel(t)
    } else {
        let (s, c) = kernel(MDEG_QUARTER - t);
        (c, s)
    };
    let (s, c) = (to_q30(s), to_q30(c));
    match quadrant {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

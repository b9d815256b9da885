//! Reference measurements: per-direction correction terms updated from a
//! probe reading at a fixed gauge (issue 28), and the operator's re-zero.
//!
//! The board serves `model + c(t) − z` where `model` is the compensator's
//! served correction, `c(t)` the estimated error of the model at time `t`
//! and `z` the re-zero offset. Integers only, no panics, no heap; the
//! desktop (`tcomp replay --reference-every`) runs this very code.
//!
//! **The rule: a two-state Kalman filter** on the model's error
//! `e = measured − model`, state `x = [b, s]`: a bias `b` (nm) and a drift
//! rate `s` (nm/h). Between references both relax to 0 (Ornstein–Uhlenbeck
//! processes, so a stale estimate fades back to the model alone):
//!
//! ```text
//! α = exp(−Δ/τ_b), β = exp(−Δ/τ_s), Δh = Δ in hours
//! b(t) = α·(b + s·Δh)       s(t) = β·s
//! F = [[α, α·Δh], [0, β]]   Q = diag(σ_b²·(1 − α²), σ_s²·(1 − β²))
//! P(t) = F·P·Fᵀ + Q
//! ```
//!
//! `σ_b` is the stationary spread of the model's error (its process noise
//! per unit time is `2σ_b²/τ_b`), `σ_s` that of the drift rate (`σ_s = 0`:
//! bias only). A reference `y` (the probe reading at the gauge) against the
//! served model output `m` at that moment gives the innovation
//! `ν = y − m − b(t)` with variance `S = P_bb(t) + σ_r²` (`σ_r`: the probe's
//! noise). It is **refused** (state unchanged, refused count + 1) when
//! `|ν| > gate_abs` or `ν² > (k·√S)²`: a chip on the gauge, a probe out of
//! range. **A refused reading confirmed by the next one is a step, not an
//! outlier**: when the reference before was refused and this one passes
//! `gate_abs` and agrees with it (`(ν − ν_prev)² ≤ k²·2σ_r²`, two readings
//! of the same error), the `k·√S` test is waived: after a speed change the
//! model's error can move by more than `k·√S` (P knows only the time since
//! the last reference), and without this a clean probe kept being refused
//! while the model alone would have served better. Otherwise `K = P(t)·Hᵀ/S` with `H = [1, 0]`,
//! `b ← b(t) + clamp(K_b·ν, ±max_step)`, `s ← s(t) + clamp(K_s·ν, ±max_step per h)`,
//! then `b`, `s` are clamped to their bounds and
//! `P ← (I − K·H)·P(t)` (for a scalar observation: `P_bb·σ_r²/S`,
//! `P_bs·σ_r²/S`, `P_ss − P_bs²/S`).
//!
//! **Why it cannot make things much worse than the model alone**: each
//! accepted reference moves the estimate by at most `max_step`, only by the
//! share `P/(P + σ_r²)` its uncertainty justifies, and the estimate decays
//! back to 0 with `τ_b` (`τ_s`) when no reference comes, so with references
//! far apart the board serves the model alone again.
//!
//! **Re-zero** (operator touch-off): `z ← m + c(t)` at that moment, so the
//! served value `m + c − z` restarts from 0 there and afterwards follows
//! the change of model + estimate; references keep working in the model's
//! frame (the gauge does not move with the operator's zero).
//!
//! Units: readings and corrections in 0.1 µm (as the compensator's
//! outputs), internally nm; time in ms since boot (as `StepInput::now_ms`).
//!
//! **Overflow argument**: parameters are clamped to their limits
//! ([`ReferenceParams::sanitised`]): σ ≤ [`MAX_SIGMA_NM`] = 10^6 nm, so
//! every variance ≤ [`MAX_VAR`] = 10^12 (nm², nm²/h, nm²/h²); Δ used for
//! the drift ≤ 41·τ_b ≤ 4.1·10^11 ms (beyond it α = 0); bias and rate
//! ≤ 10^7. The propagation forms `P_bb·H² + 2·P_bs·Δ·H + P_ss·Δ²`
//! (H = 3.6·10^6 ms/h) ≤ 10^12·(1.3·10^13 + 3·10^18 + 1.7·10^23) < 2^128/2
//! in i128, then divides by H² before the Q30 factors (≤ 2^30) multiply.
//! Every result is clamped to its bound before it is stored.

/// Largest σ (nm; nm/h for the rate) a parameter may state: 1 mm.
pub const MAX_SIGMA_NM: u32 = 1_000_000;
/// Largest variance entry kept (nm², nm²/h, (nm/h)²).
pub const MAX_VAR: i64 = 1_000_000_000_000;
/// Largest bias / re-zero offset / drift rate bound: 10 mm (nm, nm/h).
pub const MAX_TERM_NM: i32 = 10_000_000;
/// Largest time constant, s (about 116 days).
pub const MAX_TAU_S: u32 = 10_000_000;
/// Serialised state: version byte.
pub const STATE_VERSION: u8 = 1;
/// Serialised state length, bytes.
pub const STATE_BYTES: usize = 58;

const MS_PER_H: i128 = 3_600_000;
const Q30: i64 = 1 << 30;
/// exp(−1) in Q30.
const E_INV_Q30: u32 = 395_007_542;

/// Parameters of the update rule (the board's settings; `tcomp replay`'s flags).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReferenceParams {
    /// Probe noise σ_r of one averaged reading, nm.
    pub sigma_ref_nm: u32,
    /// Stationary σ_b of the model's error (bias), nm.
    pub sigma_bias_nm: u32,
    /// Correlation time τ_b of the model's error, s (≥ 1).
    pub tau_bias_s: u32,
    /// Stationary σ_s of the drift rate, nm/h (0: bias only).
    pub sigma_rate_nm_h: u32,
    /// Correlation time τ_s of the drift rate, s (≥ 1).
    pub tau_rate_s: u32,
    /// Gate: refuse |ν| > k·√S, k in tenths (40 = 4σ); 0 disables this test.
    pub gate_k_x10: u16,
    /// Gate: refuse |ν| above this, nm (0 disables this test).
    pub gate_abs_nm: u32,
    /// Largest change of the bias by one reference, nm (of the rate: nm/h).
    pub max_step_nm: u32,
    /// Bound on |b|, nm (|z| is bounded by [`MAX_TERM_NM`]).
    pub max_bias_nm: u32,
    /// Bound on |s|, nm/h.
    pub max_rate_nm_h: u32,
}

impl ReferenceParams {
    /// Defaults, tuned on FL_THERMAL's last 20 % (80–100 %, never scored):
    /// see BENCHMARKS.md "Closing the loop with the probe (issue 28)".
    pub const DEFAULT: ReferenceParams = ReferenceParams {
        sigma_ref_nm: 300,
        sigma_bias_nm: 3_000,
        tau_bias_s: 4 * 3600,
        sigma_rate_nm_h: 2_000,
        tau_rate_s: 2 * 3600,
        gate_k_x10: 40,
        gate_abs_nm: 30_000,
        max_step_nm: 20_000,
        max_bias_nm: 50_000,
        max_rate_nm_h: 20_000,
    };

    /// Every field clamped into the range the overflow argument covers.
    pub fn sanitised(&self) -> ReferenceParams {
        let term = MAX_TERM_NM as u32;
        ReferenceParams {
            sigma_ref_nm: self.sigma_ref_nm.min(MAX_SIGMA_NM),
            sigma_bias_nm: self.sigma_bias_nm.min(MAX_SIGMA_NM),
            tau_bias_s: self.tau_bias_s.clamp(1, MAX_TAU_S),
            sigma_rate_nm_h: self.sigma_rate_nm_h.min(MAX_SIGMA_NM),
            tau_rate_s: self.tau_rate_s.clamp(1, MAX_TAU_S),
            gate_k_x10: self.gate_k_x10,
            gate_abs_nm: self.gate_abs_nm.min(term),
            max_step_nm: self.max_step_nm.min(term),
            max_bias_nm: self.max_bias_nm.min(term),
            max_rate_nm_h: self.max_rate_nm_h.min(term),
        }
    }
}

impl Default for ReferenceParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What one reference did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceOutcome {
    /// Used: the innovation (0.1 µm) and the change of the served correction (0.1 µm).
    Accepted { innovation: i32, step: i32 },
    /// Refused by the gate; nothing but the refused count changed.
    Refused { innovation: i32 },
}

/// Why serialised state was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StateError {
    Length,
    Version,
    OutOfBounds,
}

/// One direction's reference state (a few bytes: [`STATE_BYTES`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReferenceState {
    /// Bias b at `last_ms`, nm.
    pub bias_nm: i32,
    /// Drift rate s at `last_ms`, nm/h.
    pub rate_nm_h: i32,
    /// Re-zero offset z, nm.
    pub zero_nm: i32,
    /// Covariance [P_bb, P_bs, P_ss] at `last_ms` (nm², nm²/h, (nm/h)²).
    pub p: [i64; 3],
    /// Time of the last accepted reference, ms; `None` before the first
    /// (then `p` is the prior).
    pub last_ms: Option<u64>,
    /// Innovation of the last reference (accepted or refused), nm.
    pub last_innovation_nm: i32,
    pub accepted: u16,
    pub refused: u16,
    /// The last reference was refused (its innovation is
    /// `last_innovation_nm`): the next one may confirm it.
    pub last_refused: bool,
}

#[allow(
    clippy::cast_possible_truncation,
    reason = "clamped to ±bound, which is an i64"
)]
// Not inlined: i128 arithmetic expands to long sequences on a Cortex-M4
// (flash size; the result is the same).
#[inline(never)]
fn clamp_i128(v: i128, bound: i64) -> i64 {
    v.clamp(-i128::from(bound), i128::from(bound)) as i64
}

/// Division rounding to nearest (ties away from zero); `d > 0`.
// Not inlined: i128 arithmetic expands to long sequences on a Cortex-M4
// (flash size; the result is the same).
#[inline(never)]
#[allow(
    clippy::cast_possible_wrap,
    reason = "n + d/2 < 2^127 where the i128 form did not overflow: the quotient fits an i128"
)]
fn div_round(n: i128, d: i128) -> i128 {
    if d <= 0 {
        return 0;
    }
    let half = d.unsigned_abs() / 2;
    let q = udiv_u128(n.unsigned_abs() + half, d.unsigned_abs()) as i128;
    if n >= 0 {
        q
    } else {
        -q
    }
}

/// `n / d` (`d > 0`): the one 128-bit division of this module. A Cortex-M4
/// has no 128-bit division routine to call, so LLVM expands every `/` on
/// u128/i128 into a long inline loop (≈ 0.5–0.9 KB each); the module's
/// divisions all come here so the board carries that loop once (flash
/// size; the quotient is the same).
#[inline(never)]
fn udiv_u128(n: u128, d: u128) -> u128 {
    n / d
}

/// exp(−num/den) in Q30 (0 ≤ result ≤ 2^30); den = 0 → 1.
#[allow(
    clippy::cast_possible_truncation,
    reason = "r < 40·2^30 fits a u64, f < 2^30, the result ≤ 2^30 fits a u32"
)]
pub fn exp_neg_q30(num: u64, den: u64) -> u32 {
    if den == 0 {
        return 1 << 30;
    }
    // ratio in Q30; ≥ 40 gives < 2^-57: 0 in Q30.
    let r = udiv_u128(u128::from(num) << 30, u128::from(den));
    if r >= 40 << 30 {
        return 0;
    }
    let r = r as u64;
    let k = r >> 30;
    let f = (r & ((1 << 30) - 1)) as i64; // Q30, in [0, 1)
                                          // exp(−f) by Horner to degree 12 (error < 1/13! ≈ 2^-32).
    let mut t: i64 = Q30;
    for n in (1..=12i64).rev() {
        t = Q30 - (f * t / n + (1 << 29)) / Q30;
    }
    let ek = crate::fixed::decay_pow_q30(E_INV_Q30, k);
    let ek = if k == 0 { 1 << 30 } else { u64::from(ek) };
    ((ek * t.clamp(0, Q30) as u64 + (1 << 29)) >> 30) as u32
}

// Not inlined: i128 arithmetic expands to long sequences on a Cortex-M4
// (flash size; the result is the same).
#[inline(never)]
fn mul_q30(v: i128, q: u32) -> i128 {
    (v * i128::from(q) + (1 << 29)) >> 30
}

/// The predicted state at `now_ms` (no update): (b, s, P).
#[allow(
    clippy::cast_possible_truncation,
    reason = "products of two Q30 factors ≤ 2^30 fit a u32"
)]
fn predict(st: &ReferenceState, p: &ReferenceParams, now_ms: u64) -> (i64, i64, [i64; 3]) {
    let Some(t0) = st.last_ms else {
        return (i64::from(st.bias_nm), i64::from(st.rate_nm_h), st.p);
    };
    let dt = now_ms.saturating_sub(t0);
    let tau_b = u64::from(p.tau_bias_s) * 1000;
    let tau_s = u64::from(p.tau_rate_s) * 1000;
    let a = exp_neg_q30(dt, tau_b);
    let be = exp_neg_q30(dt, tau_s);
    // Beyond 41 τ_b, α = 0 anyway: bound Δ for the products.
    let dt = i128::from(dt.min(tau_b.saturating_mul(41)));
    let (b, s) = (i128::from(st.bias_nm), i128::from(st.rate_nm_h));
    let max_b = i64::from(p.max_bias_nm);
    let max_s = i64::from(p.max_rate_nm_h);
    let b_t = clamp_i128(mul_q30(b + div_round(s * dt, MS_PER_H), a), max_b);
    let s_t = clamp_i128(mul_q30(s, be), max_s);
    let [pbb, pbs, pss] = st.p.map(i128::from);
    let h = MS_PER_H;
    let sum = div_round(pbb * h * h + 2 * pbs * dt * h + pss * dt * dt, h * h);
    let sig_b2 = i128::from(p.sigma_bias_nm) * i128::from(p.sigma_bias_nm);
    let sig_s2 = i128::from(p.sigma_rate_nm_h) * i128::from(p.sigma_rate_nm_h);
    let a2 = mul_q30(i128::from(a), a) as u32; // ≤ 2^30
    let b2 = mul_q30(i128::from(be), be) as u32;
    let ab = mul_q30(i128::from(a), be) as u32;
    let q_bb = mul_q30(sig_b2, (Q30 as u32).saturating_sub(a2));
    let q_ss = mul_q30(sig_s2, (Q30 as u32).saturating_sub(b2));
    let pbb_t = clamp_i128(
        mul_q30(sum.min(i128::from(MAX_VAR) * 4), a2) + q_bb,
        MAX_VAR,
    )
    .max(0);
    let pbs_t = clamp_i128(mul_q30(div_round(pbs * h + pss * dt, h), ab), MAX_VAR);
    let pss_t = clamp_i128(mul_q30(pss, b2) + q_ss, MAX_VAR).max(0);
    (b_t, s_t, consistent([pbb_t, pbs_t, pss_t]))
}

/// Keep P positive semi-definite: |P_bs| ≤ √(P_bb·P_ss).
fn consistent(p: [i64; 3]) -> [i64; 3] {
    let [bb, bs, ss] = p;
    let (bb, ss) = (bb.max(0), ss.max(0));
    let lim = isqrt(i128::from(bb) * i128::from(ss));
    [bb, bs.clamp(-lim, lim), ss]
}

#[allow(clippy::cast_possible_truncation, reason = "taken with min(i64::MAX)")]
fn isqrt(v: i128) -> i64 {
    if v <= 0 {
        return 0;
    }
    // Newton from above; v < 2^80 here, result < 2^40.
    let mut x = v;
    let mut y = (x + 1) / 2;
    while y < x {
        x = y;
        // 0 < x ≤ v: both non-negative, so the unsigned quotient is v / x.
        y = (x + udiv_u128(v.unsigned_abs(), x.unsigned_abs()) as i128) / 2;
    }
    x.min(i128::from(i64::MAX)) as i64
}

#[allow(clippy::cast_possible_truncation, reason = "clamped to the i32 range")]
fn to_01um(nm: i64) -> i32 {
    div_round(i128::from(nm), 100).clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32
}

/// The probe's reference temperature for its own drift: 20 °C (ISO 1), in 1/16 °C.
pub const PROBE_DRIFT_REF_16: i32 = 20 * 16;

/// A probe reading (0.1 µm) with the probe's own temperature drift removed:
/// `reading − k·(T − 20 °C)`, `T` in 1/16 °C (the DS18B20's unit) and `k`
/// in nm/K, rounded to 0.1 µm (ties away from zero); saturating. The board
/// and `tcomp record` both use it.
#[allow(clippy::cast_possible_truncation, reason = "clamped to the i32 range")]
pub fn remove_probe_drift(reading: i32, temp_16: i32, drift_nm_per_k: i32) -> i32 {
    // k·ΔT16/16 nm = k·ΔT16/1600 tenths of a µm.
    let d = i128::from(drift_nm_per_k) * (i128::from(temp_16) - i128::from(PROBE_DRIFT_REF_16));
    let v = i128::from(reading) - div_round(d, 1600);
    v.clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32
}

impl ReferenceState {
    /// A fresh state: no terms, the prior covariance of `params`.
    pub fn new(params: &ReferenceParams) -> Self {
        let p = params.sanitised();
        let v = |s: u32| (i64::from(s) * i64::from(s)).min(MAX_VAR);
        ReferenceState {
            p: [v(p.sigma_bias_nm), 0, v(p.sigma_rate_nm_h)],
            ..Default::default()
        }
    }

    /// The predicted terms at `now_ms`: bias b(t) (nm) and drift rate s(t) (nm/h).
    pub fn terms_at(&self, params: &ReferenceParams, now_ms: u64) -> (i64, i64) {
        let p = params.sanitised();
        let (b, s, _) = predict(self, &p, now_ms);
        (b, s)
    }

    /// The estimated model error c(t) − z at `now_ms`, nm.
    pub fn term_nm(&self, params: &ReferenceParams, now_ms: u64) -> i64 {
        let p = params.sanitised();
        let (b, _, _) = predict(self, &p, now_ms);
        b - i64::from(self.zero_nm)
    }

    /// The correction to serve at `now_ms`, 0.1 µm: the compensator's served
    /// `model` (0.1 µm) plus c(t) − z, clamped to ±`max_correction`.
    pub fn serve(
        &self,
        params: &ReferenceParams,
        now_ms: u64,
        model: i32,
        max_correction: i32,
    ) -> i32 {
        let total = i64::from(model) * 100 + self.term_nm(params, now_ms);
        let m = max_correction.max(0);
        to_01um(total).clamp(-m, m)
    }

    /// One reference: `reading` (probe at the gauge, 0.1 µm, in the model's
    /// frame) against the compensator's served `model` (0.1 µm) at `now_ms`.
    #[allow(
        clippy::cast_possible_truncation,
        reason = "clamped to the i32 range or to bounds ≤ MAX_TERM_NM < i32::MAX"
    )]
    pub fn reference(
        &mut self,
        params: &ReferenceParams,
        now_ms: u64,
        model: i32,
        reading: i32,
    ) -> ReferenceOutcome {
        let p = params.sanitised();
        let (b_t, s_t, [pbb, pbs, pss]) = predict(self, &p, now_ms);
        let nu = (i128::from(reading) - i128::from(model)) * 100 - i128::from(b_t);
        let nu_nm = nu.clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32;
        let r = i128::from(p.sigma_ref_nm) * i128::from(p.sigma_ref_nm);
        let s = (i128::from(pbb) + r).max(1);
        let k2 = i128::from(p.gate_k_x10) * i128::from(p.gate_k_x10);
        let d = i128::from(nu_nm) - i128::from(self.last_innovation_nm);
        let confirmed = self.last_refused && d * d * 100 <= k2 * 2 * r;
        let refused = (p.gate_abs_nm > 0 && nu.abs() > i128::from(p.gate_abs_nm))
            || (k2 > 0 && nu * nu * 100 > k2 * s && !confirmed);
        self.last_innovation_nm = nu_nm;
        self.last_refused = refused;
        let innovation = to_01um(nu_nm.into());
        if refused {
            self.refused = self.refused.saturating_add(1);
            return ReferenceOutcome::Refused { innovation };
        }
        let before = to_01um(b_t - i64::from(self.zero_nm));
        let step = i128::from(p.max_step_nm);
        let db = div_round(i128::from(pbb) * nu, s).clamp(-step, step);
        let ds = div_round(i128::from(pbs) * nu, s).clamp(-step, step);
        self.bias_nm = clamp_i128(i128::from(b_t) + db, p.max_bias_nm.into()) as i32;
        self.rate_nm_h = clamp_i128(i128::from(s_t) + ds, p.max_rate_nm_h.into()) as i32;
        let (pbb, pbs, pss) = (i128::from(pbb), i128::from(pbs), i128::from(pss));
        self.p = consistent([
            clamp_i128(div_round(pbb * r, s), MAX_VAR),
            clamp_i128(div_round(pbs * r, s), MAX_VAR),
            clamp_i128(pss - div_round(pbs * pbs, s), MAX_VAR),
        ]);
        self.last_ms = Some(now_ms);
        self.accepted = self.accepted.saturating_add(1);
        let after = to_01um(i64::from(self.bias_nm) - i64::from(self.zero_nm));
        ReferenceOutcome::Accepted {
            innovation,
            step: after.saturating_sub(before),
        }
    }

    /// Operator touch-off at `now_ms` with the compensator serving `model`
    /// (0.1 µm): the served correction restarts from 0 here.
    #[allow(
        clippy::cast_possible_truncation,
        reason = "clamped to MAX_TERM_NM < i32::MAX"
    )]
    pub fn rezero(&mut self, params: &ReferenceParams, now_ms: u64, model: i32) {
        let p = params.sanitised();
        let (b_t, _, _) = predict(self, &p, now_ms);
        let z = i128::from(model) * 100 + i128::from(b_t);
        // The whole served value at that moment: bounded like a term (10 mm),
        // not like the bias.
        self.zero_nm = clamp_i128(z, MAX_TERM_NM.into()) as i32;
    }

    /// Little-endian: version, flags (bit 0: `last_ms` present, bit 1:
    /// `last_refused`), bias, rate,
    /// zero, last innovation (i32), P (3 × i64), last_ms (u64), accepted,
    /// refused (u16).
    #[allow(
        clippy::indexing_slicing,
        reason = "constant offsets, all below STATE_BYTES"
    )]
    pub fn to_bytes(&self) -> [u8; STATE_BYTES] {
        let mut o = [0u8; STATE_BYTES];
        o[0] = STATE_VERSION;
        o[1] = u8::from(self.last_ms.is_some()) | (u8::from(self.last_refused) << 1);
        o[2..6].copy_from_slice(&self.bias_nm.to_le_bytes());
        o[6..10].copy_from_slice(&self.rate_nm_h.to_le_bytes());
        o[10..14].copy_from_slice(&self.zero_nm.to_le_bytes());
        o[14..18].copy_from_slice(&self.last_innovation_nm.to_le_bytes());
        for (i, v) in self.p.iter().enumerate() {
            o[18 + 8 * i..26 + 8 * i].copy_from_slice(&v.to_le_bytes());
        }
        o[42..50].copy_from_slice(&self.last_ms.unwrap_or(0).to_le_bytes());
        o[50..52].copy_from_slice(&self.accepted.to_le_bytes());
        o[52..54].copy_from_slice(&self.refused.to_le_bytes());
        // 54..58 reserved (0).
        o
    }

    /// Inverse of [`to_bytes`](Self::to_bytes), refusing another version,
    /// length, or terms outside the bounds the overflow argument needs.
    #[allow(
        clippy::indexing_slicing,
        clippy::cast_possible_truncation,
        reason = "length checked equal to STATE_BYTES first; u64 as i64 reinterprets the stored i64"
    )]
    pub fn from_bytes(b: &[u8]) -> Result<Self, StateError> {
        if b.len() != STATE_BYTES {
            return Err(StateError::Length);
        }
        if b[0] != STATE_VERSION {
            return Err(StateError::Version);
        }
        let i32_at = |i: usize| i32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let u64_at = |i: usize| {
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[i..i + 8]);
            u64::from_le_bytes(a)
        };
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        if b[1] > 3 || (b[1] & 1 == 0 && u64_at(42) != 0) || b[54..58].iter().any(|&x| x != 0) {
            return Err(StateError::OutOfBounds);
        }
        let st = ReferenceState {
            bias_nm: i32_at(2),
            rate_nm_h: i32_at(6),
            zero_nm: i32_at(10),
            last_innovation_nm: i32_at(14),
            p: [u64_at(18) as i64, u64_at(26) as i64, u64_at(34) as i64],
            last_ms: (b[1] & 1 == 1).then(|| u64_at(42)),
            accepted: u16_at(50),
            refused: u16_at(52),
            last_refused: b[1] & 2 == 2,
        };
        let term_ok = |v: i32| (-MAX_TERM_NM..=MAX_TERM_NM).contains(&v);
        let var_ok = |v: i64| (0..=MAX_VAR).contains(&v);
        if !term_ok(st.bias_nm)
            || !term_ok(st.rate_nm_h)
            || !term_ok(st.zero_nm)
            || !var_ok(st.p[0])
            || !var_ok(st.p[2])
            || consistent(st.p) != st.p
        {
            return Err(StateError::OutOfBounds);
        }
        Ok(st)
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
mod tests {
    use super::*;

    const H: u64 = 3_600_000;

    /// The signed formula `div_round` stood for before its one shared
    /// unsigned division: rounding to nearest, ties away from zero.
    fn div_round_signed(n: i128, d: i128) -> i128 {
        if n >= 0 {
            (n + d / 2) / d
        } else {
            -((-n + d / 2) / d)
        }
    }

    #[test]
    fn shared_division_gives_the_signed_quotients() {
        let ns = [
            0,
            1,
            -1,
            5,
            -5,
            7,
            -7,
            1799,
            -1800,
            1800,
            123_456_789_012_345,
        ];
        let ds = [1, 2, 3, 100, 1600, 3_600_000, 12_960_000_000_000, 1 << 70];
        for &n in &ns {
            for &d in &ds {
                for n in [n, n * 1_000_003, n << 60] {
                    assert_eq!(div_round(n, d), div_round_signed(n, d), "{n} / {d}");
                }
            }
        }
        assert_eq!(div_round(5, 2), 3);
        assert_eq!(div_round(-5, 2), -3);
        assert_eq!(div_round(7, 0), 0);
        // isqrt: the largest x with x² ≤ v, up to v near 2^80.
        for v in [
            1i128,
            2,
            3,
            4,
            15,
            16,
            17,
            1 << 40,
            (1 << 80) - 1,
            999_999_999_999_999,
        ] {
            let x = i128::from(isqrt(v));
            assert!(x * x <= v && (x + 1) * (x + 1) > v, "isqrt({v}) = {x}");
        }
        // exp(−r) in Q30 at ratios that use the 128-bit quotient's full width.
        assert_eq!(exp_neg_q30(0, 7), 1 << 30);
        assert_eq!(exp_neg_q30(u64::MAX, 1), 0);
        let e1 = f64::from(exp_neg_q30(H, H)) / f64::from(1u32 << 30);
        assert!((e1 - (-1f64).exp()).abs() < 1e-8, "{e1}");
    }

    /// Bias only, σ_b 6 µm, τ_b 4 h (the tests' figures assume these, not the tuned defaults).
    fn params() -> ReferenceParams {
        ReferenceParams {
            sigma_bias_nm: 6_000,
            tau_bias_s: 4 * 3600,
            sigma_rate_nm_h: 0,
            tau_rate_s: 3600,
            ..ReferenceParams::DEFAULT
        }
    }

    #[test]
    fn exp_matches_float() {
        for &(n, d) in &[
            (0u64, 1u64),
            (1, 1),
            (1, 2),
            (3, 1),
            (7, 3),
            (39, 1),
            (100, 1),
            (1, 1000),
        ] {
            let want = (-(n as f64) / d as f64).exp() * (1u64 << 30) as f64;
            let got = f64::from(exp_neg_q30(n, d));
            assert!((got - want).abs() <= 4.0, "{n}/{d}: {got} vs {want}");
        }
        assert_eq!(exp_neg_q30(5, 0), 1 << 30);
        assert_eq!(exp_neg_q30(u64::MAX, 1), 0);
    }

    #[test]
    fn first_reference_pulls_bias_by_the_kalman_share() {
        let p = params();
        let mut st = ReferenceState::new(&p);
        // Model serves 10 µm, probe reads 13 µm: innovation 3 µm.
        let out = st.reference(&p, H, 100, 130);
        let ReferenceOutcome::Accepted { innovation, step } = out else {
            panic!("{out:?}")
        };
        assert_eq!(innovation, 30);
        // K = σ_b²/(σ_b² + σ_r²) = 36/36.09: step ≈ 2.99 µm.
        assert_eq!(step, 30);
        assert!((st.bias_nm - 2_993).abs() <= 1, "{}", st.bias_nm);
        assert_eq!(st.serve(&p, H, 100, 100_000), 130);
        // P shrinks to about σ_r².
        assert!(st.p[0] < 90_000 && st.p[0] > 89_000, "{:?}", st.p);
    }

    #[test]
    fn bias_fades_back_to_the_model_alone() {
        let p = params();
        let mut st = ReferenceState::new(&p);
        st.reference(&p, H, 0, 50);
        let t1 = st.term_nm(&p, H + u64::from(p.tau_bias_s) * 1000);
        assert!((t1 - (f64::from(st.bias_nm) / core::f64::consts::E) as i64).abs() <= 2);
        assert_eq!(st.term_nm(&p, H + 1000 * H), 0);
    }

    #[test]
    fn step_is_bounded() {
        let p = ReferenceParams {
            max_step_nm: 1_000,
            gate_abs_nm: 0,
            gate_k_x10: 0,
            ..params()
        };
        let mut st = ReferenceState::new(&p);
        let out = st.reference(&p, H, 0, 250);
        assert_eq!(
            out,
            ReferenceOutcome::Accepted {
                innovation: 250,
                step: 10
            }
        );
        assert_eq!(st.bias_nm, 1_000);
    }

    #[test]
    fn outliers_are_refused_and_change_nothing() {
        let p = params();
        let mut st = ReferenceState::new(&p);
        st.reference(&p, H, 0, 20);
        // Right after a reference P is small: 4σ of ~0.4 µm refuses 5 µm.
        let before = st;
        let out = st.reference(&p, H + 1000, 0, 70);
        assert!(matches!(out, ReferenceOutcome::Refused { .. }), "{out:?}");
        assert_eq!(st.refused, 1);
        let unchanged = |st: &ReferenceState| ReferenceState {
            refused: 0,
            last_innovation_nm: before.last_innovation_nm,
            last_refused: false,
            ..*st
        };
        assert_eq!(unchanged(&st), before);
        // +50 µm an hour later: above the absolute gate.
        let out = st.reference(&p, 2 * H, 0, 520);
        assert!(matches!(out, ReferenceOutcome::Refused { innovation } if innovation > 490));
        assert_eq!(st.refused, 2);
        assert_eq!(unchanged(&st), before);
    }

    #[test]
    fn rezero_restarts_served_correction_from_zero() {
        let p = params();
        let mut st = ReferenceState::new(&p);
        st.reference(&p, H, 100, 140);
        st.rezero(&p, 2 * H, 150);
        assert_eq!(st.serve(&p, 2 * H, 150, 100_000), 0);
        // Later the served value follows the model's change (+ the fading bias).
        let later = st.serve(&p, 3 * H, 180, 100_000);
        let term = st.term_nm(&p, 3 * H);
        assert_eq!(i64::from(later), (18_000 + term + 50) / 100);
        // 18 − 15 µm of model change, bias 3.99 µm faded from 3.11 to 2.42 µm.
        assert_eq!(later, 23);
        // A reference after the re-zero works in the model's frame.
        st.reference(&p, 3 * H, 180, 180);
        assert_eq!(st.accepted, 2);
    }

    #[test]
    fn drift_term_follows_a_ramp() {
        let p = ReferenceParams {
            sigma_rate_nm_h: 2_000,
            tau_rate_s: 8 * 3600,
            ..params()
        };
        let mut st = ReferenceState::new(&p);
        // The model's error grows 1 µm per hour.
        for k in 1..=8u64 {
            st.reference(&p, k * H, 0, (10 * k) as i32);
        }
        assert!(st.rate_nm_h > 300, "{}", st.rate_nm_h);
        let bias_only = {
            let q = params();
            let mut s = ReferenceState::new(&q);
            for k in 1..=8u64 {
                s.reference(&q, k * H, 0, (10 * k) as i32);
            }
            s.term_nm(&q, 8 * H + H / 2)
        };
        let with_rate = st.term_nm(&p, 8 * H + H / 2);
        // Truth half an hour later: 8.5 µm.
        assert!((8_500 - with_rate).abs() < (8_500 - bias_only).abs());
    }

    #[test]
    fn probe_drift_is_removed_about_20_degrees() {
        // 0.5 µm/K, 30 °C: 5 µm too much.
        assert_eq!(remove_probe_drift(120, 30 * 16, 500), 70);
        assert_eq!(remove_probe_drift(120, 20 * 16, 500), 120);
        // 10 °C: 5 µm too little; 1/16 K steps round to 0.1 µm.
        assert_eq!(remove_probe_drift(0, 10 * 16, 500), 50);
        assert_eq!(remove_probe_drift(0, 20 * 16 + 1, 500), 0);
        assert_eq!(remove_probe_drift(0, 20 * 16 + 2, 500), -1);
        assert_eq!(remove_probe_drift(i32::MIN, 125 * 16, 32_767), i32::MIN);
    }

    #[test]
    fn bytes_round_trip_and_refusals() {
        let p = ReferenceParams {
            sigma_rate_nm_h: 1_000,
            ..params()
        };
        let mut st = ReferenceState::new(&p);
        st.reference(&p, H, 10, 40);
        st.reference(&p, 2 * H, 10, 900);
        st.rezero(&p, 3 * H, -20);
        let b = st.to_bytes();
        assert_eq!(ReferenceState::from_bytes(&b), Ok(st));
        assert_eq!(
            ReferenceState::from_bytes(&b[..10]),
            Err(StateError::Length)
        );
        let mut v = b;
        v[0] = 2;
        assert_eq!(ReferenceState::from_bytes(&v), Err(StateError::Version));
        let mut v = b;
        v[18..26].copy_from_slice(&(-5i64).to_le_bytes());
        assert_eq!(ReferenceState::from_bytes(&v), Err(StateError::OutOfBounds));
        let mut v = b;
        v[2..6].copy_from_slice(&i32::MAX.to_le_bytes());
        assert_eq!(ReferenceState::from_bytes(&v), Err(StateError::OutOfBounds));
        let fresh = ReferenceState::new(&p);
        assert_eq!(ReferenceState::from_bytes(&fresh.to_bytes()), Ok(fresh));
    }
}

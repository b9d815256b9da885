//! From the R-test convention (`model`: component errors in **fixed**
//! directions, location errors as a rotation about the actual axis line,
//! every error zero at A = C = 0) to the board's convention (`five_axis`,
//! image section kind 4: location errors constant in the angle, component
//! errors in the **rotating** frame, after the axis's nominal rotation).
//!
//! To first order, axis k at angle θ (rotation R(θ) about its direction)
//! moves its table by a twist ξ = (δ, ε) at the axis origin, in the frame
//! the axis stands on:
//!
//! ```text
//! R-test:  ξ(θ) = (I − R(θ))·ξ_L + E_fixed(θ)          zero at θ = 0
//! board:   ξ(θ) = ξ_Lb + R(θ)·E_rot(θ)                  ξ_Lb at θ = 0
//! ```
//!
//! Equal for every θ needs ξ_Lb = ξ(0) = 0 and
//! `E_rot(θ) = R(θ)ᵀ·[(I − R(θ))·ξ_L + E_fixed(θ)]`. Rotating by θ turns
//! harmonic h into h − 1 and h + 1 (cos θ·cos hθ = ½cos(h−1)θ + ½cos(h+1)θ
//! …), so a fixed-frame series of order n is exactly a rotating-frame
//! series of order n + 1 (the location part: order 1), zero at θ = 0 like
//! the board's basis `a_h(cos hθ − 1) + b_h sin hθ`. The conversion is
//! exact up to the board's order ([`MAX_FOURIER_ORDER`]); higher harmonics
//! are dropped and their RMS over a turn reported.
//!
//! The board's location slots therefore stay zero for a static model
//! (an image any five-axis firmware reads). A drifting location error
//! `(I − R(θ))·(ξ_L + Σ ΔT_k·d_k)` is a product of a temperature and the
//! angle, which the board's `L·R` slots and static Fourier terms cannot
//! hold; for a model with drift [`to_board`] uses the section's R-test
//! location mode instead (flag `FIVE_AXIS_RTEST_LOCATION`: the board
//! serves the slots as `(I − R(θ))·ξ_L(T)`): the slots carry the
//! identified ξ_L and its per-kelvin drift as they are, and the Fourier
//! terms only `E_rot = Rᵀ·E_fixed`. Both forms are exact to first order.

use anyhow::{bail, Result};
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;
use thermocomp_core::five_axis::MAX_FOURIER_ORDER;

use super::model::{
    nominal_chain, reading_sensitivity, Axis5, Location, RotaryModel, LOCATION_NAMES,
};
use crate::board5;
use crate::five_axis::Fourier;

/// A trigonometric polynomial `c0 + Σ_h α_h cos hθ + β_h sin hθ` (h ≥ 1).
#[derive(Clone, Debug, Default, PartialEq)]
struct Trig {
    c0: f64,
    cos: Vec<f64>,
    sin: Vec<f64>,
}

impl Trig {
    fn constant(v: f64) -> Trig {
        Trig {
            c0: v,
            ..Default::default()
        }
    }
    /// `Σ a_h(cos hθ − 1) + b_h sin hθ` written out.
    fn from_fourier(f: &Fourier) -> Trig {
        Trig {
            c0: -f.cos.iter().sum::<f64>(),
            cos: f.cos.clone(),
            sin: f.sin.clone(),
        }
    }
    fn add_cos(&mut self, h: usize, v: f64) {
        if h == 0 {
            self.c0 += v;
        } else {
            if self.cos.len() < h {
                self.cos.resize(h, 0.0);
            }
            self.cos[h - 1] += v;
        }
    }
    fn add_sin(&mut self, h: usize, v: f64) {
        if h > 0 {
            if self.sin.len() < h {
                self.sin.resize(h, 0.0);
            }
            self.sin[h - 1] += v;
        }
    }
    fn coef(v: &[f64], h: usize) -> f64 {
        v.get(h - 1).copied().unwrap_or(0.0)
    }
    fn order(&self) -> usize {
        self.cos.len().max(self.sin.len())
    }
    /// `s · self`.
    fn scaled(&self, s: f64) -> Trig {
        Trig {
            c0: s * self.c0,
            cos: self.cos.iter().map(|v| s * v).collect(),
            sin: self.sin.iter().map(|v| s * v).collect(),
        }
    }
    fn plus(&self, o: &Trig) -> Trig {
        let mut r = self.clone();
        r.c0 += o.c0;
        for h in 1..=o.order() {
            r.add_cos(h, Self::coef(&o.cos, h));
            r.add_sin(h, Self::coef(&o.sin, h));
        }
        r
    }
    /// `cos θ · self`, exactly.
    fn times_cos(&self) -> Trig {
        let mut r = Trig::default();
        r.add_cos(1, self.c0);
        for h in 1..=self.order() {
            let (a, b) = (Self::coef(&self.cos, h), Self::coef(&self.sin, h));
            r.add_cos(h - 1, a / 2.0);
            r.add_cos(h + 1, a / 2.0);
            r.add_sin(h + 1, b / 2.0);
            r.add_sin(h - 1, b / 2.0);
        }
        r
    }
    /// `sin θ · self`, exactly.
    fn times_sin(&self) -> Trig {
        let mut r = Trig::default();
        r.add_sin(1, self.c0);
        for h in 1..=self.order() {
            let (a, b) = (Self::coef(&self.cos, h), Self::coef(&self.sin, h));
            r.add_sin(h + 1, a / 2.0);
            r.add_sin(h - 1, -a / 2.0);
            r.add_cos(h - 1, b / 2.0);
            r.add_cos(h + 1, -b / 2.0);
        }
        r
    }
    /// The board's basis up to `max_order` (the constant is implied by the
    /// zero at θ = 0), and the RMS over a turn of the harmonics dropped.
    fn to_fourier(&self, max_order: usize) -> (Fourier, f64) {
        let n = self.order().min(max_order);
        let f = Fourier {
            cos: (1..=n).map(|h| Self::coef(&self.cos, h)).collect(),
            sin: (1..=n).map(|h| Self::coef(&self.sin, h)).collect(),
        };
        // dropped part: Σ α_h(cos hθ − 1) + β_h sin hθ over h > n; its
        // mean square is (Σα)² + ½Σ(α² + β²) (orthogonal harmonics).
        let (mut sum_a, mut sq) = (0.0, 0.0);
        for h in n + 1..=self.order() {
            let (a, b) = (Self::coef(&self.cos, h), Self::coef(&self.sin, h));
            sum_a += a;
            sq += 0.5 * (a * a + b * b);
        }
        (f, (sum_a * sum_a + sq).sqrt())
    }
}

/// The two axes perpendicular to `axis`, (i, j) with R(θ)·e_i = cos θ·e_i + sin θ·e_j.
fn plane(axis: Axis5) -> (usize, usize) {
    match axis {
        Axis5::A => (1, 2),
        Axis5::C => (0, 1),
    }
}

/// `R(θ)·v` (`transpose`: `R(θ)ᵀ·v`) for a vector of trig polynomials.
fn rotate(axis: Axis5, v: &[Trig; 3], transpose: bool) -> [Trig; 3] {
    let (i, j) = plane(axis);
    let s = if transpose { 1.0 } else { -1.0 };
    let mut r = v.clone();
    // R: (c·vi − s·vj, s·vi + c·vj); Rᵀ: (c·vi + s·vj, −s·vi + c·vj)
    r[i] = v[i].times_cos().plus(&v[j].times_sin().scaled(s));
    r[j] = v[i].times_sin().scaled(-s).plus(&v[j].times_cos());
    r
}

/// (axis, index in δx, δy, δz, εx, εy, εz) of each of [`super::model::LOCATION_NAMES`].
const LOC_SLOT: [(Axis5, usize); 8] = [
    (Axis5::C, 0),
    (Axis5::C, 1),
    (Axis5::C, 3),
    (Axis5::C, 4),
    (Axis5::A, 1),
    (Axis5::A, 2),
    (Axis5::A, 4),
    (Axis5::A, 5),
];

/// The location errors of `axis` as its six twist components (µm, µrad).
fn location_twist(l: &Location, axis: Axis5) -> [f64; 6] {
    let mut t = [0.0; 6];
    for (v, (ax, k)) in l.to_array().into_iter().zip(LOC_SLOT) {
        if ax == axis {
            t[k] = v;
        }
    }
    t
}

/// A rotary model in the board's convention, with what the conversion dropped.
#[derive(Clone, Debug)]
pub struct BoardConversion {
    pub model: board5::RotaryModel,
    /// Per component error (EXA … ECC): RMS over a full turn of the
    /// harmonics above the board's order (µm or µrad); zero when exact.
    pub truncated_rms: BTreeMap<String, f64>,
    /// Highest harmonic the rotating-frame series needs (before truncation).
    pub order_needed: usize,
}

impl BoardConversion {
    /// Largest truncated RMS of the translations (µm) and of the angles (µrad).
    pub fn worst_truncation(&self) -> (f64, f64) {
        let mut w = (0.0f64, 0.0f64);
        for (name, v) in &self.truncated_rms {
            let angle = matches!(name.as_bytes().get(1), Some(b'A' | b'B' | b'C'));
            if angle {
                w.1 = w.1.max(*v);
            } else {
                w.0 = w.0.max(*v);
            }
        }
        w
    }
}

/// The location slots of the R-test mode: each error's value and its
/// per-kelvin drift, one column per drift sensor (board5's JSON form).
fn rtest_slots(m: &RotaryModel) -> Result<BTreeMap<String, board5::LocationValue>> {
    let mut seen = std::collections::BTreeSet::new();
    for d in &m.drift {
        if !seen.insert(d.sensor.as_str()) {
            bail!("the rotary model drifts with sensor {} twice", d.sensor);
        }
    }
    let value = m.location.to_array();
    let slopes: Vec<[f64; 8]> = m.drift.iter().map(|d| d.per_kelvin.to_array()).collect();
    Ok((LOCATION_NAMES.iter().enumerate())
        .map(|(i, name)| {
            let l = board5::Location {
                value: value[i],
                per_k: slopes.iter().map(|s| s[i]).collect(),
            };
            (name.to_string(), board5::LocationValue::Thermal(l))
        })
        .collect())
}

/// Convert an identified (R-test convention) model to the board's
/// convention, harmonics above `max_order` (≤ [`MAX_FOURIER_ORDER`]) dropped.
/// A model with drift keeps its location errors in the section's R-test
/// location mode (see the module docs).
pub fn to_board(m: &RotaryModel, max_order: usize) -> Result<BoardConversion> {
    m.check()?;
    if max_order > MAX_FOURIER_ORDER {
        bail!("the board takes Fourier orders up to {MAX_FOURIER_ORDER}, not {max_order}");
    }
    let rtest = !m.drift.is_empty();
    let location = if rtest {
        rtest_slots(m)?
    } else {
        BTreeMap::new()
    };
    let mut motion = BTreeMap::new();
    let mut truncated_rms = BTreeMap::new();
    let mut order_needed = 0;
    for axis in [Axis5::A, Axis5::C] {
        let names = axis.names();
        // In the R-test mode the board applies (I − R) to the slots itself.
        let loc = if rtest {
            [0.0; 6]
        } else {
            location_twist(&m.location, axis)
        };
        // fixed-frame twist (I − R)·ξ_L + E_fixed, translations then angles
        let mut fixed: [[Trig; 3]; 2] = Default::default();
        for part in 0..2 {
            let l: [Trig; 3] = std::array::from_fn(|k| Trig::constant(loc[3 * part + k]));
            let rl = rotate(axis, &l, false);
            for k in 0..3 {
                let comp = (m.components.get(names[3 * part + k]))
                    .map_or_else(Trig::default, Trig::from_fourier);
                fixed[part][k] = l[k].plus(&rl[k].scaled(-1.0)).plus(&comp);
            }
        }
        for part in 0..2 {
            let rot = rotate(axis, &fixed[part], true);
            for k in 0..3 {
                let name = names[3 * part + k];
                order_needed = order_needed.max(rot[k].order());
                let (f, dropped) = rot[k].to_fourier(max_order);
                truncated_rms.insert(name.to_string(), dropped);
                if f.cos.iter().chain(&f.sin).any(|v| *v != 0.0) {
                    motion.insert(name.to_string(), f);
                }
            }
        }
    }
    Ok(BoardConversion {
        model: board5::RotaryModel {
            pivot_a_mm: m.pivot_a_mm,
            offset_c_mm: m.offset_c_mm,
            sensors: m.drift.iter().map(|d| d.sensor.clone()).collect(),
            t_ref_c: m.drift.iter().map(|d| d.reference_c).collect(),
            location,
            motion,
            rtest_location: rtest,
        },
        truncated_rms,
        order_needed,
    })
}

/// The rotary part of the tool-tip error to first order **in the machine
/// frame** (the board's registers' frame and sign), f64, for a model in
/// the R-test convention: tool point `p_mm` (machine frame, linear axes'
/// errors not included), A and C in degrees, location errors `loc`.
pub fn rotary_error_machine(
    m: &RotaryModel,
    loc: &Location,
    p_mm: [f64; 3],
    a: f64,
    c: f64,
) -> Vector3<f64> {
    let w0 = nominal_chain(m.pivot_a_mm, m.offset_c_mm, a, c);
    let nest = w0.inverse() * Point3::from(Vector3::from(p_mm));
    let s = reading_sensitivity(m.pivot_a_mm, m.offset_c_mm, nest.coords.into(), a, c);
    let mut d = Vector3::zeros();
    for (axis, sens, deg) in [(Axis5::A, &s.a, a), (Axis5::C, &s.c, c)] {
        let l = location_twist(loc, axis);
        let r = axis.rotation(deg);
        let (dl, el) = (
            Vector3::new(l[0], l[1], l[2]),
            Vector3::new(l[3], l[4], l[5]),
        );
        let (dl, el) = (dl - r * dl, el - r * el);
        let comp = m.components_at(axis, deg);
        for k in 0..6 {
            let lk = if k < 3 { dl[k] } else { el[k - 3] };
            d += sens[k] * (lk + comp[k]);
        }
    }
    w0.rotation * d
}

#[cfg(test)]
#[path = "frames_tests.rs"]
mod tests;

//! The volumetric correction as the board will serve it (seed 001 s31–s32,
//! issue 14 item 4, desktop half): per tool-tip direction one polynomial in
//! the normalised axis positions u = x/X, v = y/Y, w = z/Z and the tool
//! length L (m), with a constant part and one part per kelvin of each
//! selected sensor:
//!
//! ```text
//! e_d(x, y, z, L, T) = Σ_m (c_dm + Σ_i s_dmi·(T_i − T_ref,i)) · u^a v^b w^c L^e
//! ```
//!
//! To first order in the errors the tool-tip error *is* such a polynomial:
//! each error function is a polynomial of its own axis (degree ≤ 3 here) and
//! its Abbe arm is linear in the other positions and the tool offset, so the
//! monomials needed are a, b, c ≤ 3, e ≤ 1, a + b + c + e ≤ 4 (52 of them).
//! The coefficients are found by least squares on a grid fine enough to
//! make the fit exact (5 levels per axis for degree 4), then checked against
//! the kinematics on other points; terms below 1 nm are dropped and the
//! largest dropped sum is reported. The tool sits on the spindle axis at
//! (0, 0, L): the usual tool-length offset of the CNC.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::errors::GeometricErrors;
use super::kinematics::{tool_tip_error_linear, Structure};
use super::thermal::ThermalModel;

/// Exponents (a, b, c, e) of u, v, w and L [m].
pub type Monomial = [u8; 4];

/// Largest exponent per position, total degree, and tool-length degree.
const MAX_AXIS_POWER: u8 = 3;
const MAX_TOTAL: u8 = 4;

/// Terms smaller than this at the stroke's end are dropped [µm].
pub const DROP_BELOW_UM: f64 = 1e-3;

fn monomials() -> Vec<Monomial> {
    let mut out = Vec::new();
    for e in 0..=1u8 {
        for a in 0..=MAX_AXIS_POWER {
            for b in 0..=MAX_AXIS_POWER {
                for c in 0..=MAX_AXIS_POWER {
                    if a + b + c + e <= MAX_TOTAL {
                        out.push([a, b, c, e]);
                    }
                }
            }
        }
    }
    out
}

fn monomial_value(m: &Monomial, u: [f64; 3], l_m: f64) -> f64 {
    u[0].powi(i32::from(m[0]))
        * u[1].powi(i32::from(m[1]))
        * u[2].powi(i32::from(m[2]))
        * l_m.powi(i32::from(m[3]))
}

/// One polynomial term: coefficient per direction [µm], for the constant
/// part or per kelvin of one sensor.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct VolTerm {
    pub monomial: Monomial,
    /// `None`: the constant part; `Some(i)`: per kelvin of sensor i.
    pub sensor: Option<usize>,
    pub coef_um: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct VolumetricPoly {
    pub structure: String,
    pub stroke_mm: [f64; 3],
    pub sensors: Vec<String>,
    pub t_ref_c: Vec<f64>,
    pub terms: Vec<VolTerm>,
    /// Largest |first-order kinematics − polynomial| on the check points,
    /// after dropping small terms [µm].
    pub max_fit_error_um: f64,
    /// Errors of the model the identification did not determine (identify
    /// --partial): `export --geometry` refuses the table unless
    /// `unobservable_accepted` (`geometry table --allow-unobservable`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unobservable_terms: Vec<String>,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub unobservable_accepted: bool,
    /// The adequacy verdict of the model the table was built from (issue
    /// 49; `geometry table` copies it): `export --geometry` refuses
    /// `false` unless `--accept-inadequate`, warns when absent (unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequate: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequacy: Option<crate::adequacy::Adequacy>,
}

impl VolumetricPoly {
    /// Tool-tip error [µm] (workpiece frame) at `pos_mm`, tool length `tool_mm`.
    pub fn eval(&self, pos_mm: [f64; 3], tool_mm: f64, temps: &[f64]) -> [f64; 3] {
        let u = [0, 1, 2].map(|k| pos_mm[k] / self.stroke_mm[k]);
        let mut out = [0.0; 3];
        for t in &self.terms {
            let scale = match t.sensor {
                None => 1.0,
                Some(i) => temps.get(i).copied().unwrap_or(0.0) - self.t_ref_c[i],
            };
            let m = monomial_value(&t.monomial, u, tool_mm / 1e3) * scale;
            for k in 0..3 {
                out[k] += t.coef_um[k] * m;
            }
        }
        out
    }
}

/// Grid levels per axis: enough distinct points for degree 4 in each.
const LEVELS: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
const TOOLS_MM: [f64; 2] = [0.0, 250.0];

/// Fit one errors set (first-order tool-tip error) as polynomial coefficients.
fn fit_part(
    st: &Structure,
    e: &GeometricErrors,
    stroke: [f64; 3],
    mons: &[Monomial],
) -> Result<Vec<[f64; 3]>> {
    let mut rows = Vec::new();
    let mut ys: [Vec<f64>; 3] = Default::default();
    for &fx in &LEVELS {
        for &fy in &LEVELS {
            for &fz in &LEVELS {
                for &l in &TOOLS_MM {
                    let u = [fx, fy, fz];
                    let pos = [0, 1, 2].map(|k| u[k] * stroke[k]);
                    let d = tool_tip_error_linear(st, e, pos, [0.0, 0.0, l]);
                    rows.push(
                        mons.iter()
                            .map(|m| monomial_value(m, u, l / 1e3))
                            .collect::<Vec<_>>(),
                    );
                    for k in 0..3 {
                        ys[k].push(d[k]);
                    }
                }
            }
        }
    }
    let mut out = vec![[0.0; 3]; mons.len()];
    for (k, y) in ys.iter().enumerate() {
        let c = tcomp_numerics::linalg::least_squares(&rows, y, false, 0.0)?;
        for (o, v) in out.iter_mut().zip(c) {
            o[k] = v;
        }
    }
    Ok(out)
}

/// The volumetric polynomial of a thermal model (constant part at the
/// reference temperatures plus one part per kelvin of each sensor), or of
/// static errors (`thermal` None).
pub fn build(
    st: &Structure,
    stroke: [f64; 3],
    errors: &GeometricErrors,
    thermal: Option<&ThermalModel>,
) -> Result<VolumetricPoly> {
    if stroke.iter().any(|s| !(*s > 0.0)) {
        bail!("volumetric table: every stroke must be positive");
    }
    let mons = monomials();
    let mut parts: Vec<(Option<usize>, GeometricErrors)> = Vec::new();
    let (sensors, t_ref) = match thermal {
        Some(m) => {
            parts.push((None, m.basis.errors(&m.base)));
            for (i, s) in m.slopes.iter().enumerate() {
                parts.push((Some(i), m.basis.errors(s)));
            }
            (m.sensors.clone(), m.t_ref.clone())
        }
        None => {
            parts.push((None, errors.clone()));
            (Vec::new(), Vec::new())
        }
    };
    let mut terms = Vec::new();
    for (sensor, e) in &parts {
        let coefs = fit_part(st, e, stroke, &mons)?;
        // Per kelvin parts are dropped at 1 nm per 10 K of swing.
        let limit = if sensor.is_some() {
            DROP_BELOW_UM / 10.0
        } else {
            DROP_BELOW_UM
        };
        for (m, c) in mons.iter().zip(coefs) {
            // At the stroke's end every monomial is ≤ 1 (L ≤ 0.25 m), so |c| bounds the term.
            if c.iter().any(|v| v.abs() >= limit) {
                terms.push(VolTerm {
                    monomial: *m,
                    sensor: *sensor,
                    coef_um: c,
                });
            }
        }
    }
    let mut poly = VolumetricPoly {
        structure: st.to_string(),
        stroke_mm: stroke,
        sensors,
        t_ref_c: t_ref.clone(),
        terms,
        max_fit_error_um: 0.0,
        unobservable_terms: Vec::new(),
        unobservable_accepted: false,
        adequate: None,
        adequacy: None,
    };
    // Check on points off the fitting grid, at the reference and 5 K above it.
    let mut worst = 0.0f64;
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                let f = |n: usize| 0.1 + 0.27 * n as f64;
                let pos = [f(i) * stroke[0], f(j) * stroke[1], f(k) * stroke[2]];
                let tool = 40.0 + 50.0 * i as f64;
                for dt in [0.0, 5.0] {
                    let temps: Vec<f64> = t_ref.iter().map(|t| t + dt).collect();
                    let e = match thermal {
                        Some(m) => m.errors_at(&temps),
                        None => errors.clone(),
                    };
                    let want = tool_tip_error_linear(st, &e, pos, [0.0, 0.0, tool]);
                    let got = poly.eval(pos, tool, &temps);
                    for c in 0..3 {
                        worst = worst.max((want[c] - got[c]).abs());
                    }
                }
            }
        }
    }
    poly.max_fit_error_um = worst;
    Ok(poly)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{random_errors, ErrorSizes};
    use tcomp_numerics::rng::Rng;

    #[test]
    fn the_polynomial_reproduces_the_first_order_kinematics() {
        let stroke = [800.0, 500.0, 400.0];
        let e = random_errors(stroke, &ErrorSizes::default(), &mut Rng::new(9));
        for s in ["XY/Z", "X/YZ", "/XYZ"] {
            let st = Structure::parse(s).unwrap();
            let p = build(&st, stroke, &e, None).unwrap();
            assert!(p.max_fit_error_um < 0.01, "{s}: {}", p.max_fit_error_um);
            assert!(
                p.terms.len() <= 3 * 52 && p.terms.len() > 10,
                "{}",
                p.terms.len()
            );
            // And it is not trivially zero.
            let v = p.eval([700.0, 100.0, 350.0], 120.0, &[]);
            let w = tool_tip_error_linear(&st, &e, [700.0, 100.0, 350.0], [0.0, 0.0, 120.0]);
            assert!(w.norm() > 1.0);
            for k in 0..3 {
                assert!((v[k] - w[k]).abs() < 0.01);
            }
        }
        assert_eq!(monomials().len(), 52);
    }
}

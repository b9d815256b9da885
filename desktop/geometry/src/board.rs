//! The volumetric polynomial on the board (issue 14 item 4, desktop half of
//! the board slice): quantise `tcomp geometry table`'s f64 polynomial into
//! the model image's section kind 3 (`thermocomp_core::volumetric`), report
//! what the quantisation costs, and predict what the board serves by
//! calling the very function the firmware runs.
//!
//! Quantisation: every variable is rescaled to [0, 1] at full scale (the
//! strokes as in the f64 polynomial, the tool length by `tool_max_mm`), so
//! a coefficient becomes the term's value at full scale: c · L_max^e (L in
//! m), in pm (per kelvin for a temperature term), rounded to the pm. The
//! reference temperatures are rounded to 1/16 °C, strokes to the µm.

use anyhow::{bail, Result};
use serde::Serialize;
use thermocomp_core::image::{Model, SensorRef, NONE};
use thermocomp_core::volumetric::{
    VolOutput, VolSensor, VolTerm, Volumetric, VolumetricSpec, MAX_VOL_SENSORS, MAX_VOL_TERMS,
    TEMP_MAX_16, TEMP_MIN_16,
};

use super::volumetric::VolumetricPoly;

/// How the section is laid out on the board.
#[derive(Clone, Debug)]
pub struct BoardOptions {
    /// Board channel of each of the polynomial's sensors (in its order).
    pub channels: Vec<u8>,
    /// PLC position slot (index into HR_POSITIONS) of X, Y, Z.
    pub slots: [u8; 3],
    /// Machine position (mm) where each axis's normalised position is 0.
    pub origin_mm: [f64; 3],
    /// Tool length at full scale (mm); longer tools are held there (flagged).
    pub tool_max_mm: f64,
    /// Largest correction served per direction (µm).
    pub max_correction_um: f64,
}

/// What the quantisation costs, over a grid of positions, tool lengths
/// and temperature states (for `tcomp export --geometry` and its `--json`).
#[derive(Clone, Debug, Serialize)]
pub struct QuantisationReport {
    pub terms: usize,
    pub sensors: usize,
    pub section_bytes: usize,
    pub grid_points: usize,
    /// Largest |served − f64 polynomial| (µm), the served value in 0.1 µm.
    pub max_error_um: f64,
    /// The same before the final rounding to 0.1 µm (µm).
    pub max_error_before_rounding_um: f64,
    /// The stated bound on that error at the grid's worst temperature state (µm):
    /// the core's bound plus the rounding of coefficients, strokes and references.
    pub bound_um: f64,
}

/// The section for `poly` (refusing, with one line naming the limit, what
/// the board cannot hold).
pub fn quantize(poly: &VolumetricPoly, o: &BoardOptions) -> Result<Volumetric> {
    if !poly.unobservable_terms.is_empty() && !poly.unobservable_accepted {
        bail!(
            "the volumetric table comes from a model whose lines did not determine {} (unobservable); make it with `geometry table --allow-unobservable` to serve it anyway",
            poly.unobservable_terms.join(", ")
        );
    }
    if poly.sensors.len() != o.channels.len() {
        bail!(
            "the volumetric polynomial reads {} sensor(s) but {} board channel(s) were given",
            poly.sensors.len(),
            o.channels.len()
        );
    }
    if poly.sensors.len() > MAX_VOL_SENSORS {
        bail!(
            "the volumetric polynomial reads {} sensors; the board's section takes at most {MAX_VOL_SENSORS} (MAX_VOL_SENSORS)",
            poly.sensors.len()
        );
    }
    if poly.terms.len() > MAX_VOL_TERMS {
        bail!(
            "the volumetric polynomial has {} terms; the board's section takes at most {MAX_VOL_TERMS} (MAX_VOL_TERMS)",
            poly.terms.len()
        );
    }
    if poly.terms.is_empty() {
        bail!("the volumetric polynomial has no terms");
    }
    if !(o.tool_max_mm > 0.0) {
        bail!("--tool-max-mm must be positive");
    }
    let to_i32 = |v: f64, what: &str| -> Result<i32> {
        let r = v.round();
        if !(r.is_finite() && r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX)) {
            bail!("volumetric {what}: {v} does not fit the board's 32-bit field");
        }
        Ok(r as i32)
    };
    let mut stroke_um = [0i32; 3];
    let mut origin_um = [0i32; 3];
    for k in 0..3 {
        stroke_um[k] = to_i32(poly.stroke_mm[k] * 1e3, "stroke (µm)")?;
        origin_um[k] = to_i32(o.origin_mm[k] * 1e3, "origin (µm)")?;
    }
    let tool_max_um = to_i32(o.tool_max_mm * 1e3, "tool-length scale (µm)")?;
    let mc = to_i32(o.max_correction_um * 10.0, "max correction (0.1 µm)")?;
    let mut sensors = Vec::new();
    for (i, (&ch, &t)) in o.channels.iter().zip(&poly.t_ref_c).enumerate() {
        let r = (t * 16.0).round();
        if !(r >= f64::from(TEMP_MIN_16) && r <= f64::from(TEMP_MAX_16)) {
            bail!(
                "volumetric sensor {}: reference {t} °C outside the DS18B20's -55..125 °C",
                poly.sensors[i]
            );
        }
        sensors.push(VolSensor {
            sensor: SensorRef {
                rom: [0; 8],
                channel: ch,
                ref_temp: r as i32,
            },
            min: TEMP_MIN_16 as i16,
            max: TEMP_MAX_16 as i16,
        });
    }
    let l_m = o.tool_max_mm / 1e3;
    let mut terms = Vec::new();
    for t in &poly.terms {
        if t.monomial.iter().any(|&e| e > 3) {
            bail!(
                "volumetric term {:?}: an exponent above 3, the board's highest",
                t.monomial
            );
        }
        let full = l_m.powi(i32::from(t.monomial[3]));
        let mut coef = [0i32; 3];
        for d in 0..3 {
            let pm = t.coef_um[d] * 1e6 * full;
            coef[d] = to_i32(pm, "coefficient (pm at full scale)").map_err(|_| {
                anyhow::anyhow!(
                    "volumetric term {:?}: {:.1} µm at full scale beyond the board's ±2147 µm per coefficient (i32 pm)",
                    t.monomial,
                    pm / 1e6
                )
            })?;
        }
        let sensor = match t.sensor {
            None => NONE,
            Some(i) if i < poly.sensors.len() => i as u8,
            Some(i) => bail!(
                "volumetric term names sensor {i}; the polynomial has {}",
                poly.sensors.len()
            ),
        };
        terms.push(VolTerm {
            exps: t.monomial,
            sensor,
            coef,
        });
    }
    Volumetric::new(&VolumetricSpec {
        slots: o.slots,
        origin_um,
        stroke_um,
        tool_max_um,
        max_correction: [mc; 3],
        sensors: &sensors,
        terms: &terms,
    })
    .map_err(|e| anyhow::anyhow!("volumetric section: {e}"))
}

/// What the board serves for its image at these PLC positions (µm, the six
/// HR_POSITIONS slots), tool length (µm) and section-sensor temperatures
/// (1/16 °C): the core's own function. `None` when the image has no section.
pub fn predict(
    model: &Model,
    positions_um: &[i32],
    tool_um: i32,
    temps_16: &[Option<i32>],
) -> Option<VolOutput> {
    model
        .volumetric
        .as_ref()
        .map(|v| v.evaluate(positions_um, tool_um, temps_16))
}

/// Max |served − f64 polynomial| over a 6×6×6 grid of positions (inside
/// the strokes), three tool lengths and three temperature states
/// (reference, +7.5 K, −4 K on every sensor).
pub fn quantisation_report(
    poly: &VolumetricPoly,
    v: &Volumetric,
    o: &BoardOptions,
) -> QuantisationReport {
    let mut worst = 0.0f64;
    let mut worst_pre = 0.0f64;
    let mut points = 0usize;
    let levels = [0.0, 0.13, 0.37, 0.5, 0.81, 1.0];
    let states: [f64; 3] = [0.0, 7.5, -4.0];
    let mut bound = 0.0f64;
    for dt in states {
        // As the board reads them: 1/16 °C.
        let temps_16: Vec<i32> = poly
            .t_ref_c
            .iter()
            .map(|t| ((t + dt) * 16.0).round() as i32)
            .collect();
        let temps_c: Vec<f64> = temps_16.iter().map(|&t| f64::from(t) / 16.0).collect();
        let rises: Vec<i32> = v
            .sensors
            .iter()
            .zip(&temps_16)
            .map(|(s, &t)| t - s.sensor.ref_temp)
            .collect();
        bound = bound.max(bound_um(poly, v, &rises, o));
        let opt: Vec<Option<i32>> = temps_16.iter().map(|&t| Some(t)).collect();
        for &fx in &levels {
            for &fy in &levels {
                for &fz in &levels {
                    for tool_frac in [0.0, 0.4, 1.0] {
                        let f = [fx, fy, fz];
                        let mut pos = [0i32; 6];
                        let mut pos_mm = [0.0f64; 3];
                        for k in 0..3 {
                            let rel = (f[k] * f64::from(v.stroke_um[k])).round() as i32;
                            pos[usize::from(v.slots[k])] = v.origin_um[k] + rel;
                            pos_mm[k] = f64::from(rel) / 1e3;
                        }
                        let tool_um = (tool_frac * f64::from(v.tool_max_um)).round() as i32;
                        let want = poly.eval(pos_mm, f64::from(tool_um) / 1e3, &temps_c);
                        let out = v.evaluate(&pos, tool_um, &opt);
                        for d in 0..3 {
                            let served = f64::from(out.corrections[d]) / 10.0;
                            let pre = out.acc[d] as f64 / 16e6;
                            worst = worst.max((served - want[d]).abs());
                            worst_pre = worst_pre.max((pre - want[d]).abs());
                        }
                        points += 1;
                    }
                }
            }
        }
    }
    QuantisationReport {
        terms: v.terms.len(),
        sensors: v.sensors.len(),
        section_bytes: 4 + v.encoded_len(),
        grid_points: points,
        max_error_um: worst,
        max_error_before_rounding_um: worst_pre,
        bound_um: bound,
    }
}

/// The stated bound (µm) at temperature rises `rises` (1/16 °C): the core's
/// (variables, products, terms, final rounding) plus, per term, half a pm
/// of coefficient rounding, the stroke rounding (≤ ½ µm of stroke moves a
/// variable by ≤ ½/stroke, a monomial by its degree times that) and the
/// reference rounding (≤ 1/32 K, as stored, times a per-kelvin coefficient).
/// `geometry predict` states it per pose; of `o` only `tool_max_mm` is read.
pub fn bound_um(poly: &VolumetricPoly, v: &Volumetric, rises: &[i32], o: &BoardOptions) -> f64 {
    let core = v.error_bound_tenth_um(rises) / 10.0;
    let mut extra = [0.0f64; 3];
    for (t, q) in poly.terms.iter().zip(&v.terms) {
        let scale_k = match t.sensor {
            None => 1.0,
            Some(i) => f64::from(rises.get(i).copied().unwrap_or(0)).abs() / 16.0,
        };
        let full = (o.tool_max_mm / 1e3).powi(i32::from(t.monomial[3]));
        for d in 0..3 {
            let c_um = (t.coef_um[d] * full).abs();
            let mut e = 0.5e-6 * scale_k;
            for k in 0..3 {
                let du = 0.5 / f64::from(v.stroke_um[k])
                    + (poly.stroke_mm[k] * 1e3 - f64::from(v.stroke_um[k])).abs()
                        / f64::from(v.stroke_um[k]);
                e += c_um * f64::from(q.exps[k]) * du * scale_k;
            }
            if let Some(i) = t.sensor {
                // The reference as stored (1/16 °C) against the f64 one.
                let stored = v
                    .sensors
                    .get(i)
                    .map_or(0.0, |s| f64::from(s.sensor.ref_temp) / 16.0);
                e += c_um * (poly.t_ref_c.get(i).copied().unwrap_or(stored) - stored).abs();
            }
            extra[d] += e;
        }
    }
    core + extra.iter().fold(0.0f64, |m, &x| m.max(x))
}

//! `tcomp export --rotary` (desktop half): an identified rotary model
//! (`identify-rotary --model-out`, R-test convention) → the board's
//! convention ([`super::frames::to_board`]) → image section kind 4
//! ([`crate::board5::quantize_five_axis`]), with what it costs: the
//! harmonics dropped and the served rotary part against the model's f64
//! first-order prediction over a grid of poses (and, for a model whose
//! location errors drift, of temperature states).

use anyhow::{bail, Result};
use serde::Serialize;
use thermocomp_core::five_axis::{self, fstatus, FiveAxis, MAX_FOURIER_ORDER};
use thermocomp_core::volumetric::{vstatus, Volumetric};

use super::frames::{rotary_error_machine, to_board};
use super::model::RotaryModel;
use crate::board5::{quantize_five_axis, FiveAxisOptions};
use crate::volumetric::VolumetricPoly;

/// What building the five-axis section cost (export's summary and `--json`).
#[derive(Clone, Debug, Serialize)]
pub struct FiveAxisReport {
    /// Fourier order on the board, and the order the exact conversion needs.
    pub order: u8,
    /// The section's R-test location mode (a model with drift): the
    /// location slots carry ξ_L and its per-kelvin drift, served as
    /// (I − R(θ))·ξ_L(T).
    pub rtest_location: bool,
    /// Sensors the location errors drift with (empty: static).
    pub drift_sensors: Vec<String>,
    pub order_needed: usize,
    /// Largest RMS over a turn of the harmonics dropped above the board's
    /// order: translations (µm), angles (µrad). Zero when exact.
    pub truncated_rms_um: f64,
    pub truncated_rms_urad: f64,
    pub section_bytes: usize,
    pub grid_points: usize,
    /// Largest |served rotary part − the model's f64 first-order one| (µm).
    pub max_error_um: f64,
    /// Its stated bound (µm): ½ of 0.1 µm, ½ nrad on the longest arm per
    /// transform, the pm roundings and the Q30 trig.
    pub bound_um: f64,
}

/// The section for `m` beside the volumetric section `vol` (its sensors
/// `vol_sensors`). `allow_unobservable`: accept a model whose
/// identification left terms undetermined (they are then served as zero).
pub fn rotary_section(
    m: &RotaryModel,
    vol: &Volumetric,
    vol_sensors: &[String],
    o: &FiveAxisOptions,
    allow_unobservable: bool,
) -> Result<(FiveAxis, FiveAxisReport)> {
    if !m.unobservable.is_empty() && !allow_unobservable {
        bail!(
            "the R-test files did not determine {} (marked unobservable); its values are not the machine's. Give --allow-unobservable to serve it anyway",
            m.unobservable.join(", ")
        );
    }
    let conv = to_board(m, MAX_FOURIER_ORDER)?;
    let f = quantize_five_axis(&conv.model, vol, vol_sensors, o)?;
    let (truncated_rms_um, truncated_rms_urad) = conv.worst_truncation();
    let (grid_points, max_error_um, bound_um) = served_vs_model(m, vol, vol_sensors, &f)?;
    Ok((
        f.clone(),
        FiveAxisReport {
            order: f.order,
            rtest_location: conv.model.rtest_location,
            drift_sensors: conv.model.sensors.clone(),
            order_needed: conv.order_needed,
            truncated_rms_um,
            truncated_rms_urad,
            section_bytes: 4 + f.encoded_len(),
            grid_points,
            max_error_um,
            bound_um,
        },
    ))
}

/// Temperature states of the served-vs-model grid, K against each
/// section sensor's reference: the reference, all warm, mixed signs.
const STATES_K: [[f64; 4]; 3] = [[0.0; 4], [6.0, 4.5, 3.0, 5.0], [-3.0, 5.5, 1.5, -2.0]];

/// Served rotary part against [`rotary_error_machine`] over 4³ positions
/// in the section's strokes × two tools × A every 30° × C every 45° (inside
/// the section's ranges) × the temperature states of [`STATES_K`] (one,
/// the reference, for a model without drift): (points, worst µm, bound µm).
pub fn served_vs_model(
    m: &RotaryModel,
    vol: &Volumetric,
    vol_sensors: &[String],
    f: &FiveAxis,
) -> Result<(usize, f64, f64)> {
    let states = if m.drift.is_empty() {
        1
    } else {
        STATES_K.len()
    };
    let levels = [0.05, 0.35, 0.65, 0.95];
    let (mut points, mut worst, mut arm, mut dt_max) = (0usize, 0.0f64, 0.0f64, 0.0f64);
    let in_range = |v: i32, r: [i32; 2]| (r[0]..=r[1]).contains(&v);
    for dk in STATES_K.iter().take(states) {
        // As the board reads them (1/16 °C), and the same in °C by name.
        let temps: Vec<Option<i32>> = (vol.sensors.iter().zip(dk))
            .map(|(s, d)| Some(s.sensor.ref_temp + (d * 16.0).round() as i32))
            .collect();
        let by_name: std::collections::BTreeMap<String, f64> = (vol_sensors.iter().zip(&temps))
            .map(|(n, t)| {
                let bare = n.strip_prefix("T_").unwrap_or(n);
                (bare.to_string(), f64::from(t.unwrap_or(0)) / 16.0)
            })
            .collect();
        let loc = m.location_at(&by_name)?;
        for d in &m.drift {
            let now = by_name.get(&d.sensor).copied().unwrap_or(d.reference_c);
            dt_max = dt_max.max((now - d.reference_c).abs());
        }
        for (i, j, k) in itertools_3(&levels) {
            let pos: [i32; 3] = std::array::from_fn(|d| {
                let l = [i, j, k][d];
                vol.origin_um[d] + (l * f64::from(vol.stroke_um[d])).round() as i32
            });
            let mut positions = [0i32; thermocomp_core::limits::MAX_AXES];
            for d in 0..3 {
                positions[usize::from(vol.slots[d])] = pos[d];
            }
            for tool_um in [100_000, vol.tool_max_um.min(250_000)] {
                for a in (-3..=3)
                    .map(|n| 30_000 * n)
                    .filter(|a| in_range(*a, f.a_range_mdeg))
                {
                    for c in (0..8)
                        .map(|n| 45_000 * n)
                        .filter(|c| in_range(*c, f.c_range_mdeg))
                    {
                        let out = five_axis::evaluate(vol, f, &positions, tool_um, [a, c], &temps);
                        if out.status & vstatus::VALID == 0
                            || out.five_status & fstatus::INCLUDED == 0
                        {
                            continue;
                        }
                        let p_mm = [
                            f64::from(pos[0]) / 1e3,
                            f64::from(pos[1]) / 1e3,
                            f64::from(pos[2] + out.tool_um) / 1e3,
                        ];
                        let (ad, cd) = (f64::from(a) / 1e3, f64::from(c) / 1e3);
                        let want = rotary_error_machine(m, &loc, p_mm, ad, cd);
                        for d in 0..3 {
                            worst = worst.max((f64::from(out.rotary[d]) / 10.0 - want[d]).abs());
                        }
                        let pivot = m.pivot_a_mm.map(|v| v / 1e3);
                        let r = ((p_mm[0] / 1e3 - pivot[0]).powi(2)
                            + (p_mm[1] / 1e3 - pivot[1]).powi(2)
                            + (p_mm[2] / 1e3 - pivot[2]).powi(2))
                        .sqrt();
                        arm = arm.max(r + m.offset_c_mm.iter().map(|v| v.abs()).sum::<f64>() / 1e3);
                        points += 1;
                    }
                }
            }
        }
    }
    Ok((points, worst, stated_bound(f, arm, dt_max)))
}

/// The stated bound (µm) of served against the model's f64 at arms up to
/// `arm` (m) and temperatures up to `dt_max` (K) from the references: ½ of
/// 0.1 µm; per transform ½ nrad × arm (0.5 nm/m), δ's pm roundings and the
/// Q30 trig (2^-30 × errors ≤ 1 mm: 1 pm) — four transforms. The R-test
/// location mode: 1.5 nrad more per location row (the value's ½ nrad
/// twice through I − R, one rounding of R·ε); the per-kelvin slopes'
/// roundings (½ pm/K, ½ prad/K × arm) over eight location errors.
pub fn stated_bound(f: &FiveAxis, arm: f64, dt_max: f64) -> f64 {
    let mut b = 0.05 + 4.0 * (0.0005 * arm + 0.002);
    if f.flags & five_axis::FIVE_AXIS_RTEST_LOCATION != 0 {
        b += 2.0 * (0.0015 * arm + 0.002);
    }
    b + 8.0 * 5e-7 * dt_max * (1.0 + arm)
}

/// Append to the volumetric polynomial (kind 3) the sensors the rotary
/// model drifts with and it does not read (no terms: the polynomial is
/// unchanged), so the five-axis section finds them among its first
/// columns. Their reference is the drift's. Names compare without `T_`.
pub fn add_drift_sensors(poly: &mut VolumetricPoly, m: &RotaryModel) -> Result<()> {
    let bare = |n: &str| n.strip_prefix("T_").unwrap_or(n).to_string();
    for d in &m.drift {
        if !poly.sensors.iter().any(|s| bare(s) == bare(&d.sensor)) {
            poly.sensors.push(d.sensor.clone());
            poly.t_ref_c.push(d.reference_c);
        }
    }
    let max = thermocomp_core::limits::MAX_VOL_SENSORS;
    if poly.sensors.len() > max {
        bail!(
            "the volumetric polynomial and the rotary drift read {} sensors together ({}); the board's section takes at most {max}",
            poly.sensors.len(),
            poly.sensors.join(", ")
        );
    }
    Ok(())
}

fn itertools_3(l: &[f64]) -> Vec<(f64, f64, f64)> {
    let mut v = Vec::new();
    for &i in l {
        for &j in l {
            for &k in l {
                v.push((i, j, k));
            }
        }
    }
    v
}

//! Temperature dependence of the geometric errors (seed 001, s11–s22): every
//! unknown of the identification (a polynomial coefficient of one error
//! term, or a squareness) becomes a linear function of selected sensor
//! temperatures, θ(T) = θ₀ + Σ_i k_i·(T_i − T_ref,i), fitted from lines
//! measured at several temperature states: identify each state, then one
//! least-squares regression per unknown over the states. Held-out states
//! (leave one out) are scored on their own line readings.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::errors::{GeometricErrors, Term};
use super::identify::{identify, residual_rms, Basis, Degrees, LineObs};
use super::kinematics::Structure;

/// One temperature state: its lines and mean sensor temperatures.
#[derive(Clone, Debug)]
pub struct State {
    pub name: String,
    pub lines: Vec<LineObs>,
    pub temps: Vec<f64>,
}

#[derive(Clone, Debug)]
pub struct ThermalModel {
    pub basis: Basis,
    pub sensors: Vec<String>,
    pub t_ref: Vec<f64>,
    /// θ₀ (basis order).
    pub base: Vec<f64>,
    /// `slopes[i][j]`: dθ_j / dT_i.
    pub slopes: Vec<Vec<f64>>,
}

impl ThermalModel {
    pub fn params_at(&self, temps: &[f64]) -> Vec<f64> {
        let mut p = self.base.clone();
        for (i, s) in self.slopes.iter().enumerate() {
            let dt = temps[i] - self.t_ref[i];
            for (pj, sj) in p.iter_mut().zip(s) {
                *pj += sj * dt;
            }
        }
        p
    }
    pub fn errors_at(&self, temps: &[f64]) -> GeometricErrors {
        self.basis.errors(&self.params_at(temps))
    }
}

/// Fit θ₀ and the slopes from states (≥ sensors + 2 so the fit has a residual).
pub fn fit(
    st: &Structure,
    states: &[State],
    sensors: &[String],
    degrees: Degrees,
    stroke_mm: [f64; 3],
) -> Result<ThermalModel> {
    let m = sensors.len();
    if states.len() < m + 2 {
        bail!(
            "{} temperature states for {m} sensors: need at least {} (one more than the unknowns per error coefficient)",
            states.len(),
            m + 2
        );
    }
    let ids = states
        .iter()
        .map(|s| identify(st, &s.lines, degrees, stroke_mm))
        .collect::<Result<Vec<_>>>()?;
    if let Some((s, id)) = states
        .iter()
        .zip(&ids)
        .find(|(_, id)| id.rank < id.basis.columns.len())
    {
        bail!(
            "state {}: its lines give rank {} of {}; every state needs the full plan",
            s.name,
            id.rank,
            id.basis.columns.len()
        );
    }
    let basis = ids[0].basis.clone();
    let n = basis.columns.len();
    let t_ref: Vec<f64> = (0..m)
        .map(|i| states.iter().map(|s| s.temps[i]).sum::<f64>() / states.len() as f64)
        .collect();
    let phi = DMatrix::from_fn(states.len(), m + 1, |r, c| {
        if c == 0 {
            1.0
        } else {
            states[r].temps[c - 1] - t_ref[c - 1]
        }
    });
    let svd = phi.clone().svd(true, true);
    let mut base = vec![0.0; n];
    let mut slopes = vec![vec![0.0; n]; m];
    for j in 0..n {
        let y = DVector::from_iterator(states.len(), ids.iter().map(|id| id.params[j]));
        let b = svd
            .solve(&y, 1e-12)
            .map_err(|e| anyhow::anyhow!("thermal regression: {e}"))?;
        base[j] = b[0];
        for i in 0..m {
            slopes[i][j] = b[i + 1];
        }
    }
    Ok(ThermalModel {
        basis,
        sensors: sensors.to_vec(),
        t_ref,
        base,
        slopes,
    })
}

/// One held-out state's line residual [µm RMS]: the model fitted without it,
/// with and without its temperature terms.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOut {
    pub state: String,
    pub temps: Vec<f64>,
    /// The geometry of the other states' mean, no temperature terms.
    pub static_rms_um: f64,
    pub thermal_rms_um: f64,
    /// The state's own identification (the floor: noise and model error).
    pub own_fit_rms_um: f64,
}

pub fn leave_one_out(
    st: &Structure,
    states: &[State],
    sensors: &[String],
    degrees: Degrees,
    stroke_mm: [f64; 3],
) -> Result<Vec<HeldOut>> {
    let mut out = Vec::new();
    for h in 0..states.len() {
        let train: Vec<State> = states
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != h)
            .map(|(_, s)| s.clone())
            .collect();
        let model = fit(st, &train, sensors, degrees, stroke_mm)?;
        let s = &states[h];
        let own = identify(st, &s.lines, degrees, stroke_mm)?;
        out.push(HeldOut {
            state: s.name.clone(),
            temps: s.temps.clone(),
            static_rms_um: residual_rms(st, &model.basis, &s.lines, &model.base),
            thermal_rms_um: residual_rms(st, &model.basis, &s.lines, &model.params_at(&s.temps)),
            own_fit_rms_um: own.residual_rms_um,
        });
    }
    Ok(out)
}

/// Sensitivity of each term's value at the end of its stroke to each sensor
/// [µm/K or µrad/K], and of the squareness.
pub fn sensitivities(model: &ThermalModel) -> Vec<(String, Vec<f64>)> {
    let at = |temps: &[f64]| model.errors_at(temps);
    let e0 = at(&model.t_ref);
    let mut rows: Vec<(String, Vec<f64>)> = Term::all()
        .map(|t| {
            let l = model.basis.stroke_mm[t.axis.index()];
            let v = (0..model.sensors.len())
                .map(|i| {
                    let mut tt = model.t_ref.clone();
                    tt[i] += 1.0;
                    at(&tt).value(t, l) - e0.value(t, l)
                })
                .collect();
            (t.name(), v)
        })
        .collect();
    for (k, name) in super::errors::SQUARENESS_NAMES.iter().enumerate() {
        let v = (0..model.sensors.len())
            .map(|i| {
                let mut tt = model.t_ref.clone();
                tt[i] += 1.0;
                at(&tt).squareness.get(k) - e0.squareness.get(k)
            })
            .collect();
        rows.push((name.to_string(), v));
    }
    rows
}

/// One tool-tip measurement (seed 001 s21): the error vector of the tool
/// point relative to the workpiece [µm] at axis positions `pos_mm` with tool
/// offset `tool_mm`, e.g. from a touch probe on an artefact or a tracker.
#[derive(Clone, Debug)]
pub struct ToolTipObs {
    pub pos_mm: [f64; 3],
    pub tool_mm: [f64; 3],
    pub error_um: [f64; 3],
}

/// Tool-tip measurements at one temperature state (another ambient
/// temperature or duty cycle than the line measurements).
#[derive(Clone, Debug)]
pub struct CalibrationState {
    pub temps: Vec<f64>,
    pub points: Vec<ToolTipObs>,
}

/// Seed 001 s22: keep the fitted temperature slopes, re-optimise the bias
/// terms θ₀ so the model's tool-tip predictions match the measurements at
/// the calibration states (least squares over every reading, first-order
/// kinematics, SVD: directions the readings cannot see stay as the lines
/// fitted them).
pub fn optimise_bias(
    st: &Structure,
    model: &ThermalModel,
    calibration: &[CalibrationState],
) -> Result<ThermalModel> {
    let mut rows = Vec::new();
    let mut y = Vec::new();
    for c in calibration {
        if c.temps.len() != model.sensors.len() {
            bail!(
                "calibration state with {} temperatures for {} sensors",
                c.temps.len(),
                model.sensors.len()
            );
        }
        let p = model.params_at(&c.temps);
        for o in &c.points {
            for (k, e) in o.error_um.iter().enumerate() {
                let mut dir = [0.0; 3];
                dir[k] = 1.0;
                let row = model.basis.row(st, dir, o.pos_mm, o.tool_mm);
                let predicted: f64 = row.iter().zip(&p).map(|(a, b)| a * b).sum();
                rows.push(row);
                y.push(e - predicted);
            }
        }
    }
    if rows.is_empty() {
        bail!("bias optimisation: no tool-tip measurements");
    }
    let delta = tcomp_numerics::linalg::least_squares(&rows, &y, false, 0.0)?;
    let mut out = model.clone();
    for (b, d) in out.base.iter_mut().zip(&delta) {
        *b += d;
    }
    Ok(out)
}

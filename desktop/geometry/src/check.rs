//! Volumetric check (issue 14, item 5): the tool-tip error a model predicts
//! against the error "measured" on a held-out grid of positions (and rotary
//! angles, and temperature states), before and after compensation.
//!
//! "Measured" is the truth machine's exact tool-tip error plus reading noise
//! (simulation; a real check would read a tracker or ball bar here). The
//! truth is taken in the identification's reference convention
//! ([`to_reference_convention`]): the straightness end-point lines and the
//! frame orientation that 14 lines cannot see are a choice of workpiece
//! datum, which a part program sets by probing anyway.

use anyhow::{anyhow, bail, Result};
use nalgebra::Vector3;
use plotters::prelude::*;
use serde::Serialize;
use std::path::Path;

use super::errors::GeometricErrors;
use super::five_axis::{tool_tip_error_exact5, RotaryPos, Turntable};
use super::identify::to_reference_convention;
use super::kinematics::Structure;
use tcomp_numerics::rng::Rng;

/// One compared point.
#[derive(Clone, Debug)]
pub struct Compared {
    pub state: String,
    pub measured: Vector3<f64>,
    pub predicted: Vector3<f64>,
}

/// Before / after figures over a set of points [µm].
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Figures {
    pub points: usize,
    /// Length of the measured tool-tip error vector: RMS and max.
    pub before_rms_um: f64,
    pub before_max_um: f64,
    /// Length of measured minus predicted (what is left after compensation).
    pub after_rms_um: f64,
    pub after_max_um: f64,
    pub reduction_pct: f64,
    /// RMS of the residual per direction x, y, z (workpiece frame).
    pub after_rms_xyz_um: [f64; 3],
}

pub fn figures(points: &[&Compared]) -> Figures {
    let n = points.len().max(1) as f64;
    let (mut b2, mut a2, mut bm, mut am) = (0.0, 0.0, 0.0f64, 0.0f64);
    let mut xyz = [0.0; 3];
    for p in points {
        let r = p.measured - p.predicted;
        b2 += p.measured.norm_squared();
        a2 += r.norm_squared();
        bm = bm.max(p.measured.norm());
        am = am.max(r.norm());
        for k in 0..3 {
            xyz[k] += r[k] * r[k];
        }
    }
    let (before, after) = ((b2 / n).sqrt(), (a2 / n).sqrt());
    Figures {
        points: points.len(),
        before_rms_um: before,
        before_max_um: bm,
        after_rms_um: after,
        after_max_um: am,
        reduction_pct: if before > 0.0 {
            100.0 * (1.0 - after / before)
        } else {
            0.0
        },
        after_rms_xyz_um: xyz.map(|v| (v / n).sqrt()),
    }
}

/// The held-out grid: 6 positions per axis off the 14-line plan's 3×3×3
/// grid (5 %, 23 %, … 95 % of each stroke), two tools, and with a turntable
/// A ∈ {−30°, 0°, 30°} × C ∈ {0°, 90°, 180°, 270°}.
pub struct Grid {
    pub positions: Vec<[f64; 3]>,
    pub rotary: Vec<RotaryPos>,
    pub tools: Vec<[f64; 3]>,
}

impl Grid {
    pub fn held_out(stroke: [f64; 3], five_axis: bool) -> Grid {
        let f = |m: usize, l: f64| l * (0.05 + 0.18 * m as f64);
        let mut positions = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                for k in 0..6 {
                    positions.push([f(i, stroke[0]), f(j, stroke[1]), f(k, stroke[2])]);
                }
            }
        }
        let rotary = if five_axis {
            let mut r = Vec::new();
            for a_deg in [-30.0, 0.0, 30.0] {
                for c_deg in [0.0, 90.0, 180.0, 270.0] {
                    r.push(RotaryPos { a_deg, c_deg });
                }
            }
            r
        } else {
            vec![RotaryPos::default()]
        };
        Grid {
            positions,
            rotary,
            tools: vec![[0.0, 0.0, 120.0], [40.0, -60.0, 180.0]],
        }
    }
}

/// A machine as the check sees it: linear errors, optional turntable.
pub struct MachineErrors<'a> {
    pub linear: &'a GeometricErrors,
    pub turntable: Option<&'a Turntable>,
}

/// Compare `model` with `truth` (plus N(0, noise²) per reading and
/// direction) over `grid`; `state` labels the points.
#[allow(clippy::too_many_arguments)]
pub fn compare(
    st: &Structure,
    truth: &MachineErrors,
    model: &MachineErrors,
    stroke: [f64; 3],
    grid: &Grid,
    noise_um: f64,
    state: &str,
    rng: &mut Rng,
) -> Vec<Compared> {
    let conv = to_reference_convention(truth.linear, stroke);
    let none = Turntable::default();
    let (tt, tm) = (
        truth.turntable.unwrap_or(&none),
        model.turntable.unwrap_or(&none),
    );
    let mut out = Vec::new();
    for pos in &grid.positions {
        for r in &grid.rotary {
            for tool in &grid.tools {
                let t = tool_tip_error_exact5(st, &conv, tt, *pos, *r, *tool);
                let noise = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise_um;
                let p = tool_tip_error_exact5(st, model.linear, tm, *pos, *r, *tool);
                out.push(Compared {
                    state: state.to_string(),
                    measured: t + noise,
                    predicted: p,
                });
            }
        }
    }
    out
}

/// Two panels: predicted against measured per direction (a perfect model
/// lies on the diagonal), and the error length per point before and after.
pub fn plot(path: &Path, title: &str, points: &[Compared]) -> Result<()> {
    if points.is_empty() {
        bail!("{title}: nothing to plot");
    }
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let root = SVGBackend::new(path, (1200, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (left, right) = root.split_horizontally(600);
    let lim = points
        .iter()
        .flat_map(|p| (0..3).flat_map(move |k| [p.measured[k].abs(), p.predicted[k].abs()]))
        .fold(1e-3f64, f64::max)
        * 1.05;
    let mut c = ChartBuilder::on(&left)
        .caption(
            format!("{title}: predicted vs measured"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(-lim..lim, -lim..lim)
        .map_err(|e| err(&e))?;
    c.configure_mesh()
        .x_desc("measured tool-tip error (µm)")
        .y_desc("predicted (µm)")
        .draw()
        .map_err(|e| err(&e))?;
    c.draw_series(LineSeries::new(vec![(-lim, -lim), (lim, lim)], &BLACK))
        .map_err(|e| err(&e))?;
    for (k, (name, color)) in [("x", RED), ("y", GREEN), ("z", BLUE)]
        .into_iter()
        .enumerate()
    {
        c.draw_series(
            points
                .iter()
                .map(|p| Circle::new((p.measured[k], p.predicted[k]), 2, color.mix(0.5).filled())),
        )
        .map_err(|e| err(&e))?
        .label(name)
        .legend(move |(x, y)| Circle::new((x + 8, y), 3, color.filled()));
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    let before: Vec<(f64, f64)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, p.measured.norm()))
        .collect();
    let after: Vec<(f64, f64)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, (p.measured - p.predicted).norm()))
        .collect();
    let ymax = before.iter().map(|p| p.1).fold(1e-3, f64::max) * 1.05;
    let mut c = ChartBuilder::on(&right)
        .caption("tool-tip error length per grid point", ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..points.len() as f64, 0.0..ymax)
        .map_err(|e| err(&e))?;
    c.configure_mesh()
        .x_desc("grid point")
        .y_desc("µm")
        .draw()
        .map_err(|e| err(&e))?;
    for (name, pts, color) in [
        ("before (uncompensated)", before, RED),
        ("after compensation", after, BLUE),
    ] {
        c.draw_series(
            pts.iter()
                .map(|&(x, y)| Circle::new((x, y), 1, color.mix(0.6).filled())),
        )
        .map_err(|e| err(&e))?
        .label(name)
        .legend(move |(x, y)| Circle::new((x + 8, y), 3, color.filled()));
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// The simulated thermal check (seed 001 s11–s22 end to end): a machine
/// whose errors change with three temperatures; its 14 lines at `states`
/// temperature states (uniform 20–32 °C per sensor); `thermal::fit`; then
/// `held_out` unseen states on the held-out grid. The "static" model is the
/// geometry identified at the training states' mean temperatures without
/// temperature terms (what a purely geometric compensation would serve).
pub struct ThermalCheck {
    pub points: Vec<Compared>,
    pub static_points: Vec<Compared>,
    /// With the bias terms optimised on tool-tip readings at `bias_states`
    /// other states (s21–s22); empty when there are none.
    pub bias_points: Vec<Compared>,
    pub states: Vec<(String, Vec<f64>)>,
}

pub fn thermal_sim(
    states: usize,
    held_out: usize,
    bias_states: usize,
    noise_um: f64,
    seed: u64,
) -> Result<ThermalCheck> {
    use super::lines::{average_runs, plan14};
    use super::sim::{measure_state, MeasurementSetup, ThermalMachine};
    use super::thermal::{fit, State};
    if states < 5 {
        bail!("--states must be at least 5 (three sensors + 2, so the fit has a residual)");
    }
    if held_out == 0 {
        bail!("--held-out must be at least 1");
    }
    let st = Structure::parse("XY/Z")?;
    let stroke = [800.0, 500.0, 400.0];
    let mut rng = Rng::new(seed);
    let sensors = ["xscrew", "column", "bed"];
    let machine = ThermalMachine::random(stroke, &sensors, &mut rng);
    let setup = MeasurementSetup {
        noise_um,
        ..Default::default()
    };
    let plan = plan14(stroke, 100.0, 100.0);
    let mut train = Vec::new();
    for k in 1..=states {
        let temps: Vec<f64> = (0..3).map(|_| rng.range(20.0, 32.0)).collect();
        let name = format!("S{k}");
        let files = measure_state(&st, &machine, &temps, &name, &plan, &setup, &mut rng);
        let avg = average_runs(&files)?;
        train.push(State {
            name,
            lines: avg.iter().map(|a| a.obs.clone()).collect(),
            temps,
        });
    }
    let names: Vec<String> = sensors.iter().map(|s| s.to_string()).collect();
    let degrees = super::identify::Degrees::default();
    let model = fit(&st, &train, &names, degrees, stroke)?;
    let mean: Vec<f64> = (0..3)
        .map(|i| train.iter().map(|s| s.temps[i]).sum::<f64>() / train.len() as f64)
        .collect();
    let static_errors = model.errors_at(&mean);
    // s21: tool-tip readings on a coarse 3×3×3 grid (10/50/90 % of the
    // strokes, the two tools) at other temperature states; s22: the bias
    // terms re-optimised on them.
    let mut calibration = Vec::new();
    for _ in 0..bias_states {
        let temps: Vec<f64> = (0..3).map(|_| rng.range(20.0, 32.0)).collect();
        let conv = super::identify::to_reference_convention(&machine.at(&temps), stroke);
        let mut pts = Vec::new();
        for fx in [0.1, 0.5, 0.9] {
            for fy in [0.1, 0.5, 0.9] {
                for fz in [0.1, 0.5, 0.9] {
                    let pos = [fx * stroke[0], fy * stroke[1], fz * stroke[2]];
                    for tool in [[0.0, 0.0, 120.0], [40.0, -60.0, 180.0]] {
                        let e = super::kinematics::tool_tip_error_exact(&st, &conv, pos, tool);
                        let n = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise_um;
                        let m = e + n;
                        pts.push(super::thermal::ToolTipObs {
                            pos_mm: pos,
                            tool_mm: tool,
                            error_um: [m.x, m.y, m.z],
                        });
                    }
                }
            }
        }
        calibration.push(super::thermal::CalibrationState { temps, points: pts });
    }
    let biased = if calibration.is_empty() {
        None
    } else {
        Some(super::thermal::optimise_bias(&st, &model, &calibration)?)
    };
    let grid = Grid::held_out(stroke, false);
    let (mut points, mut static_points, mut held) = (Vec::new(), Vec::new(), Vec::new());
    let mut bias_points = Vec::new();
    for k in 1..=held_out {
        let temps: Vec<f64> = (0..3).map(|_| rng.range(20.0, 32.0)).collect();
        let name = format!("H{k}");
        let truth = machine.at(&temps);
        let predicted = model.errors_at(&temps);
        let t = MachineErrors {
            linear: &truth,
            turntable: None,
        };
        // The same noise draws for both models: one seed per state.
        let state_seed = seed.wrapping_mul(1000).wrapping_add(k as u64);
        let m = MachineErrors {
            linear: &predicted,
            turntable: None,
        };
        points.extend(compare(
            &st,
            &t,
            &m,
            stroke,
            &grid,
            noise_um,
            &name,
            &mut Rng::new(state_seed),
        ));
        let s = MachineErrors {
            linear: &static_errors,
            turntable: None,
        };
        static_points.extend(compare(
            &st,
            &t,
            &s,
            stroke,
            &grid,
            noise_um,
            &name,
            &mut Rng::new(state_seed),
        ));
        if let Some(b) = &biased {
            let e = b.errors_at(&temps);
            let m = MachineErrors {
                linear: &e,
                turntable: None,
            };
            bias_points.extend(compare(
                &st,
                &t,
                &m,
                stroke,
                &grid,
                noise_um,
                &name,
                &mut Rng::new(state_seed),
            ));
        }
        held.push((name, temps));
    }
    Ok(ThermalCheck {
        points,
        static_points,
        bias_points,
        states: held,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{random_errors, ErrorSizes};

    #[test]
    fn a_perfect_model_leaves_only_the_noise_and_a_zero_model_leaves_everything() {
        let st = Structure::parse("XY/Z").unwrap();
        let stroke = [500.0, 400.0, 300.0];
        let mut rng = Rng::new(4);
        let truth = random_errors(stroke, &ErrorSizes::default(), &mut rng);
        let conv = to_reference_convention(&truth, stroke);
        let grid = Grid::held_out(stroke, false);
        let t = MachineErrors {
            linear: &truth,
            turntable: None,
        };
        let perfect = MachineErrors {
            linear: &conv,
            turntable: None,
        };
        let pts = compare(&st, &t, &perfect, stroke, &grid, 0.5, "S", &mut rng);
        let f = figures(&pts.iter().collect::<Vec<_>>());
        assert_eq!(f.points, 6 * 6 * 6 * 2);
        // Residual = the noise: 0.5 µm per direction → √3·0.5 = 0.87 µm in length.
        assert!((f.after_rms_um - 0.866).abs() < 0.08, "{f:?}");
        assert!(f.before_rms_um > 5.0 * f.after_rms_um, "{f:?}");
        let zero = GeometricErrors::zero();
        let z = MachineErrors {
            linear: &zero,
            turntable: None,
        };
        let pts = compare(&st, &t, &z, stroke, &grid, 0.0, "S", &mut rng);
        let f = figures(&pts.iter().collect::<Vec<_>>());
        assert!((f.after_rms_um - f.before_rms_um).abs() < 1e-9 && f.reduction_pct.abs() < 1e-9);
        let dir = tempfile::tempdir().unwrap();
        let svg = dir.path().join("check.svg");
        plot(&svg, "test", &pts).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.contains("<svg") && text.contains("predicted vs measured"));
    }

    #[test]
    fn temperature_terms_beat_static_geometry_on_held_out_states() {
        let c = thermal_sim(8, 3, 3, 0.5, 3).unwrap();
        let t = figures(&c.points.iter().collect::<Vec<_>>());
        let s = figures(&c.static_points.iter().collect::<Vec<_>>());
        assert_eq!(t.points, 3 * 432);
        assert!(t.reduction_pct >= 90.0, "thermal model: {t:?}");
        assert!(
            t.after_rms_um < 0.8 * s.after_rms_um,
            "thermal {t:?} vs static {s:?}"
        );
    }
}

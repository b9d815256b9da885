//! A second truth model for the open-world benchmark of `diagnose fit`,
//! written apart from `tcomp_thermal::sim` on purpose: other topology (a
//! vertical-spindle machining centre: a distributed spindle housing and a
//! distributed column as finite-difference bars, a bed, a coolant tank with
//! a thermostat), backward-Euler stepping, its own heat laws and its own
//! effects, DS18B20 noise and 1/16 °C quantisation, probe noise. Runs are
//! written as measured data sets are: `T_T0…T_T9`, `T_ambient`,
//! `spindle_rpm`, `feed_activity`, `dx_um`, `dz_um`, no `coolant_on`.

use nalgebra::{DMatrix, DVector};

use tcomp_data::runcsv::Run;
use tcomp_numerics::rng::Rng;

/// Segments of the spindle housing bar (nose first) and of the column bar
/// (bottom first).
const HOUSING: usize = 10;
const COLUMN: usize = 8;
/// Node indices: housing 0..10, column 10..18, bed 18, table 19, tank 20.
const BED: usize = HOUSING + COLUMN;
const TABLE: usize = BED + 1;
const TANK: usize = BED + 2;
const NODES: usize = BED + 3;
/// Sensor sites (node per sensor `T_T<i>`).
const SITES: [usize; 10] = [1, 3, 5, 8, 10, 13, 17, BED, TABLE, TANK];
/// The truth machine's maximum spindle speed [rpm].
pub const N_MAX: f64 = 12000.0;

/// An effect of the truth model (its own implementations).
#[derive(Clone, Debug, PartialEq)]
pub enum TruthEffect {
    /// Sensor `sensor` reads `step_c` more from `at_s` on (re-glued, cable).
    SensorStep {
        sensor: usize,
        step_c: f64,
        at_s: f64,
    },
    /// Sensor `sensor` follows its site through a contact resistance.
    SensorLag { sensor: usize, tau_s: f64 },
    /// The chiller runs bang-bang with hysteresis `band_c` instead of holding.
    ChillerCycling { band_c: f64, power_w: f64 },
    /// Extra bearing heat `k_w·(n/n_max)^p` (preload growing with speed).
    BearingNonlinear { k_w: f64, p: f64 },
    /// The air at the machine drifts by `rate_c_per_h` beyond `T_ambient`.
    AmbientDrift { rate_c_per_h: f64 },
    /// A timer-driven chiller: the coolant (tank) follows a sawtooth (slow
    /// rise over 80 % of the period, fast pull-down) or, `square`, an on/off
    /// cycle of ± `amp_c` about the set point, period `period_s`.
    ChillerWave {
        period_s: f64,
        amp_c: f64,
        square: bool,
        phase: f64,
    },
    /// The shop's HVAC cycles the air at the machine by ± `amp_c`
    /// (a triangle: compressor on/off), period `period_s`; `T_ambient`
    /// hangs away from the outlet and does not see it.
    HvacCycle {
        period_s: f64,
        amp_c: f64,
        phase: f64,
    },
}

/// Periodic effect kinds (`bench-diagnose --periodic-only`); drawn only
/// there, so the other benches' cases stay as they were.
pub const PERIODIC_EFFECTS: [&str; 3] = ["chiller_sawtooth", "chiller_onoff", "hvac"];

/// One cycle of a periodic effect at phase `x` (cycles), in −1..1.
pub fn wave(x: f64, shape: &str) -> f64 {
    let u = x.rem_euclid(1.0);
    match shape {
        // slow rise over 80 %, pull-down over 20 %
        "sawtooth" if u < 0.8 => -1.0 + 2.0 * u / 0.8,
        "sawtooth" => 1.0 - 2.0 * (u - 0.8) / 0.2,
        "square" if u < 0.5 => 1.0,
        "square" => -1.0,
        _ => 1.0 - 4.0 * (u - 0.5).abs(),
    }
}

impl TruthEffect {
    /// The diagnosis name this effect should be found as.
    pub fn diagnosis_name(&self) -> &'static str {
        match self {
            TruthEffect::SensorStep { .. } => "sensor_offset",
            TruthEffect::SensorLag { .. } => "sensor_lag",
            TruthEffect::ChillerCycling { .. } => "coolant",
            TruthEffect::BearingNonlinear { .. } => "bearing_nonlinear",
            TruthEffect::AmbientDrift { .. } => "ambient_drift",
            TruthEffect::ChillerWave { .. } | TruthEffect::HvacCycle { .. } => "periodic",
        }
    }

    pub fn describe(&self) -> String {
        format!("{self:?}")
    }

    /// A random effect of this kind at a strength a careful engineer would
    /// care about (visible above sensor noise, not dominating).
    pub fn random(kind: &str, g: &mut Rng, hours: f64) -> TruthEffect {
        let u = |g: &mut Rng, a: f64, b: f64| a + (b - a) * g.uniform();
        let sign = if g.uniform() < 0.5 { -1.0 } else { 1.0 };
        match kind {
            "sensor_offset" => TruthEffect::SensorStep {
                sensor: (g.uniform() * SITES.len() as f64) as usize % SITES.len(),
                step_c: sign * u(g, 0.3, 1.5),
                at_s: u(g, 0.15, 0.85) * hours * 3600.0,
            },
            "sensor_lag" => TruthEffect::SensorLag {
                sensor: (g.uniform() * 7.0) as usize % 7,
                tau_s: u(g, 150.0, 900.0),
            },
            "coolant" => TruthEffect::ChillerCycling {
                band_c: u(g, 0.5, 1.5),
                power_w: u(g, 600.0, 1200.0),
            },
            "bearing_nonlinear" => TruthEffect::BearingNonlinear {
                k_w: u(g, 40.0, 120.0),
                p: u(g, 2.5, 3.2),
            },
            "chiller_sawtooth" | "chiller_onoff" => TruthEffect::ChillerWave {
                period_s: (u(g, 600f64.ln(), 3600f64.ln())).exp(),
                amp_c: u(g, 0.3, 1.0),
                square: kind == "chiller_onoff",
                phase: g.uniform(),
            },
            "hvac" => TruthEffect::HvacCycle {
                period_s: (u(g, 1800f64.ln(), 7200f64.ln())).exp(),
                amp_c: u(g, 0.5, 1.5),
                phase: g.uniform(),
            },
            _ => TruthEffect::AmbientDrift {
                rate_c_per_h: sign * u(g, 0.15, 0.5),
            },
        }
    }
}

/// Effect kinds the truth model can switch on.
pub const TRUTH_EFFECTS: [&str; 5] = [
    "sensor_offset",
    "sensor_lag",
    "coolant",
    "bearing_nonlinear",
    "ambient_drift",
];

/// A piecewise-constant duty: (start s, rpm, feed), running speeds drawn
/// from `lo..hi` of the maximum.
pub fn random_duty(g: &mut Rng, hours: f64, lo: f64, hi: f64) -> Vec<(f64, f64, f64)> {
    let mut v = vec![(0.0, 0.0, 0.0)];
    let mut t = 600.0 + 600.0 * g.uniform();
    while t < hours * 3600.0 {
        let running = g.uniform() > 0.2;
        let rpm = if running {
            (N_MAX * (lo + (hi - lo) * g.uniform()) / 500.0).round() * 500.0
        } else {
            0.0
        };
        let feed = if running {
            (g.uniform() * 10.0).round() / 10.0
        } else {
            0.0
        };
        v.push((t, rpm, feed));
        t += 600.0 * (1.0 + (g.uniform() * 5.0).floor());
    }
    v
}

/// Conductance matrix and capacities of the machine.
struct Net {
    c: Vec<f64>,
    /// (i, j, G)
    links: Vec<(usize, usize, f64)>,
    /// convection to air per node [W/K]
    g_air: Vec<f64>,
    /// coolant jacket conductance per node while coolant flows [W/K]
    g_cool: Vec<f64>,
}

fn net() -> Net {
    let mut c = vec![0.0; NODES];
    let mut g_air = vec![0.0; NODES];
    let mut g_cool = vec![0.0; NODES];
    let mut links = Vec::new();
    // housing: steel bar, 10 segments of 60 mm, Ø 180 mm shell
    for i in 0..HOUSING {
        c[i] = 3200.0;
        g_air[i] = 1.6;
        if i + 1 < HOUSING {
            links.push((i, i + 1, 9.0));
        }
    }
    // column: cast iron, 8 segments
    for i in HOUSING..BED {
        c[i] = 26000.0;
        g_air[i] = 4.5;
        if i + 1 < BED {
            links.push((i, i + 1, 14.0));
        }
    }
    // housing mounted on the column top through a joint
    links.push((HOUSING / 2, BED - 1, 3.5));
    c[BED] = 160000.0;
    g_air[BED] = 12.0;
    links.push((HOUSING, BED, 10.0));
    c[TABLE] = 30000.0;
    g_air[TABLE] = 3.0;
    links.push((TABLE, BED, 6.0));
    // coolant tank: 80 l water, loosely coupled to the bed
    c[TANK] = 330000.0;
    g_air[TANK] = 9.0;
    // coolant jacket around the spindle nose and the table while flowing
    g_cool[0] = 2.0;
    g_cool[1] = 1.5;
    g_cool[TABLE] = 2.0;
    Net {
        c,
        links,
        g_air,
        g_cool,
    }
}

/// Output of one simulated run (before the CSV).
pub struct TruthRun {
    pub run: Run,
}

/// One backward-Euler step matrix, factorised:
/// A(flow) = C/dt + L + diag(g_air) (+ diag(g_cool) to the tank's water).
fn step_matrix(
    nt: &Net,
    dt: f64,
    flow: bool,
) -> Option<nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    let mut a = DMatrix::<f64>::zeros(NODES, NODES);
    for i in 0..NODES {
        a[(i, i)] += nt.c[i] / dt + nt.g_air[i];
    }
    for &(i, j, g) in &nt.links {
        a[(i, i)] += g;
        a[(j, j)] += g;
        a[(i, j)] -= g;
        a[(j, i)] -= g;
    }
    if flow {
        for i in 0..NODES {
            let g = nt.g_cool[i];
            if g > 0.0 {
                a[(i, i)] += g;
                a[(TANK, TANK)] += g;
                a[(i, TANK)] -= g;
                a[(TANK, i)] -= g;
            }
        }
    }
    Some(a.lu())
}

/// Columns written before the sensors.
const LEAD_COLS: [&str; 3] = ["time_s", "spindle_rpm", "feed_activity"];

/// Sensor readings follow their sites (lagged ones through contact).
fn follow_sites(lagged: &mut [f64], x: &DVector<f64>, effects: &[TruthEffect], dt: f64) {
    for (i, &s) in SITES.iter().enumerate() {
        let tau = effects.iter().find_map(|e| match e {
            TruthEffect::SensorLag { sensor, tau_s } if *sensor == i => Some(*tau_s),
            _ => None,
        });
        lagged[i] = match tau {
            Some(tau) => lagged[i] + (x[s] - lagged[i]) * (1.0 - (-dt / tau).exp()),
            None => x[s],
        };
    }
}

/// The machine's state at one written instant.
struct Sample<'a> {
    t: f64,
    rpm: f64,
    feed: f64,
    measured_ambient: f64,
    lagged: &'a [f64],
    x: &'a DVector<f64>,
    x0: &'a DVector<f64>,
}

/// One written row: the duty, the sensors (steps, noise, 1/16 °C), the
/// ambient sensor and the probes.
fn record(data: &mut [Vec<Option<f64>>], g: &mut Rng, s: &Sample, effects: &[TruthEffect]) {
    let Sample {
        t,
        rpm,
        feed,
        measured_ambient,
        lagged,
        x,
        x0,
    } = *s;
    data[0].push(Some(t));
    data[1].push(Some(rpm));
    data[2].push(Some(feed));
    for (i, _) in SITES.iter().enumerate() {
        let step: f64 = effects
            .iter()
            .map(|e| match e {
                TruthEffect::SensorStep {
                    sensor,
                    step_c,
                    at_s,
                } if *sensor == i && t >= *at_s => *step_c,
                _ => 0.0,
            })
            .sum();
        let v = lagged[i] + step + 0.02 * g.normal();
        data[3 + i].push(Some((v * 16.0).round() / 16.0));
    }
    let amb = measured_ambient + 0.02 * g.normal();
    data[3 + SITES.len()].push(Some((amb * 16.0).round() / 16.0));
    // displacement: housing growth along the spindle (nose side of
    // the fixed rear bearing), column growth and column bending
    let rise = |i: usize| x[i] - x0[i];
    let alpha = 11.5e-3; // µm per mm per K
    let growth: f64 = (0..HOUSING).map(|i| 60.0 * rise(i)).sum::<f64>() * alpha * 0.6;
    let col: f64 = (HOUSING..BED).map(|i| 110.0 * rise(i)).sum::<f64>() * alpha;
    let tilt = 2.2 * (rise(BED - 1) - rise(HOUSING + 1));
    let table = 300.0 * alpha * rise(TABLE);
    let dz = -(growth + col) + table + 0.2 * g.normal();
    let dx = tilt + 0.15 * growth + 0.2 * g.normal();
    data[4 + SITES.len()].push(Some((dx * 1e4).round() / 1e4));
    data[5 + SITES.len()].push(Some((dz * 1e4).round() / 1e4));
}

/// Heat: motor (∝ n) in the housing's middle, bearings (∝ n^1.5) at the
/// nose and the rear, ballscrew nut (∝ feed) in the table.
fn machine_heat(rpm: f64, feed: f64, effects: &[TruthEffect]) -> DVector<f64> {
    let u = rpm / N_MAX;
    let mut q = DVector::<f64>::zeros(NODES);
    if rpm > 0.0 {
        q[HOUSING / 2] += 110.0 * u;
        q[1] += 75.0 * u.powf(1.5);
        q[HOUSING - 2] += 40.0 * u.powf(1.5);
        for e in effects {
            if let TruthEffect::BearingNonlinear { k_w, p } = e {
                q[1] += k_w * u.powf(*p);
            }
        }
    }
    q[TABLE] += 35.0 * feed;
    q
}

/// The run as written: metadata and the columns in order.
fn into_run(data: Vec<Vec<Option<f64>>>, period_s: f64) -> Run {
    let mut run = Run::default();
    run.set_meta("source", "simulated (diagnose open-world truth model)");
    run.set_meta("machine", "vertical-mc-truth");
    run.set_meta("sample_period_s", &format!("{period_s}"));
    let mut names: Vec<String> = LEAD_COLS.iter().map(|s| s.to_string()).collect();
    names.extend((0..SITES.len()).map(|i| format!("T_T{i}")));
    names.extend(["T_ambient".to_string(), "dx_um".into(), "dz_um".into()]);
    for (n, d) in names.iter().zip(data) {
        // names are unique by construction
        let _ = run.push_column(n, d);
    }
    run
}

/// Simulate `hours` of the duty with the effects, 1 s backward Euler,
/// written every `period_s`.
pub fn simulate(
    duty: &[(f64, f64, f64)],
    effects: &[TruthEffect],
    hours: f64,
    period_s: f64,
    seed: u64,
) -> TruthRun {
    let nt = net();
    let dt = 1.0;
    let steps = (hours * 3600.0 / dt) as usize;
    let stride = (period_s / dt).round().max(1.0) as usize;
    let (Some(lu_off), Some(lu_on)) = (step_matrix(&nt, dt, false), step_matrix(&nt, dt, true))
    else {
        return TruthRun {
            run: Run::default(),
        };
    };
    let mut g = Rng::paired(seed);
    // measured ambient: 20 °C, a slow swing and the DS18B20's own noise
    let amb_phase = g.uniform() * std::f64::consts::TAU;
    let amb_meas = |t: f64| 20.0 + 0.4 * ((t / 86400.0) * std::f64::consts::TAU + amb_phase).sin();
    let drift: f64 = effects
        .iter()
        .map(|e| match e {
            TruthEffect::AmbientDrift { rate_c_per_h } => *rate_c_per_h,
            _ => 0.0,
        })
        .sum();
    let chiller = effects.iter().find_map(|e| match e {
        TruthEffect::ChillerCycling { band_c, power_w } => Some((*band_c, *power_w)),
        _ => None,
    });
    let chiller_wave = effects.iter().find_map(|e| match e {
        TruthEffect::ChillerWave {
            period_s,
            amp_c,
            square,
            phase,
        } => Some((
            *period_s,
            *amp_c,
            if *square { "square" } else { "sawtooth" },
            *phase,
        )),
        _ => None,
    });
    let hvac = |t: f64| -> f64 {
        effects
            .iter()
            .map(|e| match e {
                TruthEffect::HvacCycle {
                    period_s,
                    amp_c,
                    phase,
                } => amp_c * wave(t / period_s + phase, "triangle"),
                _ => 0.0,
            })
            .sum()
    };
    let t_set = 19.0;
    let mut x = DVector::from_element(NODES, amb_meas(0.0));
    x[TANK] = t_set;
    let mut chiller_on = false;
    let mut seg = 0;
    let mut lagged: Vec<f64> = SITES.iter().map(|&s| x[s]).collect();
    let mut data: Vec<Vec<Option<f64>>> = vec![Vec::new(); LEAD_COLS.len() + SITES.len() + 3];
    let x0 = x.clone();
    for k in 0..steps {
        let t = k as f64 * dt;
        while seg + 1 < duty.len() && duty[seg + 1].0 <= t {
            seg += 1;
        }
        let (_, rpm, feed) = duty[seg];
        let air = amb_meas(t) + drift * t / 3600.0 + hvac(t);
        follow_sites(&mut lagged, &x, effects, dt);
        if k % stride == 0 {
            let sample = Sample {
                t,
                rpm,
                feed,
                measured_ambient: amb_meas(t),
                lagged: &lagged,
                x: &x,
                x0: &x0,
            };
            record(&mut data, &mut g, &sample, effects);
        }
        let mut q = machine_heat(rpm, feed, effects);
        // coolant flows while the spindle runs; the tank is held at t_set by
        // an ideal chiller, or cycles bang-bang with the effect
        let flow = rpm > 0.0;
        match chiller {
            None => q[TANK] += 0.0,
            Some((band, power)) => {
                if x[TANK] > t_set + band / 2.0 {
                    chiller_on = true;
                } else if x[TANK] < t_set - band / 2.0 {
                    chiller_on = false;
                }
                // the chiller fights a constant load (pump, tank heater)
                q[TANK] += 0.45 * power - if chiller_on { power } else { 0.0 };
            }
        }
        let mut rhs = DVector::<f64>::zeros(NODES);
        for i in 0..NODES {
            rhs[i] = nt.c[i] / dt * x[i] + q[i] + nt.g_air[i] * air;
        }
        let next = if flow {
            lu_on.solve(&rhs)
        } else {
            lu_off.solve(&rhs)
        };
        if let Some(n) = next {
            x = n;
        }
        if chiller.is_none() {
            x[TANK] = t_set;
        }
        if let Some((per, amp, shape, ph)) = chiller_wave {
            x[TANK] = t_set + amp * wave((t + dt) / per + ph, shape);
        }
    }
    TruthRun {
        run: into_run(data, period_s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_truth_model_heats_up_and_its_effects_show() {
        let duty = vec![
            (0.0, 0.0, 0.0),
            (1800.0, 9000.0, 0.5),
            (3.0 * 3600.0, 0.0, 0.0),
        ];
        let clean = simulate(&duty, &[], 4.0, 30.0, 1).run;
        assert_eq!(clean.rows(), 480);
        let nose = clean.col("T_T0").unwrap();
        let start = nose[0].unwrap();
        let hot = nose[360].unwrap();
        assert!(hot - start > 3.0, "nose rose {} °C", hot - start);
        // quantised to 1/16 °C
        assert!(nose
            .iter()
            .flatten()
            .all(|v| (v * 16.0 - (v * 16.0).round()).abs() < 1e-9));
        let dz = clean.col("dz_um").unwrap();
        assert!(dz[360].unwrap() < -5.0, "dz {}", dz[360].unwrap());
        let step = simulate(
            &duty,
            &[TruthEffect::SensorStep {
                sensor: 7,
                step_c: 1.0,
                at_s: 7200.0,
            }],
            4.0,
            30.0,
            1,
        )
        .run;
        let a = step.col("T_T7").unwrap();
        let b = clean.col("T_T7").unwrap();
        assert!((a[300].unwrap() - b[300].unwrap() - 1.0).abs() < 0.1);
        assert!((a[100].unwrap() - b[100].unwrap()).abs() < 0.1);
        let cyc = simulate(
            &duty,
            &[TruthEffect::ChillerCycling {
                band_c: 1.5,
                power_w: 700.0,
            }],
            4.0,
            30.0,
            1,
        )
        .run;
        let tank = cyc.col("T_T9").unwrap();
        let (lo, hi) = tank
            .iter()
            .flatten()
            .fold((f64::MAX, f64::MIN), |a, v| (a.0.min(*v), a.1.max(*v)));
        assert!(hi - lo > 1.0, "tank swing {}", hi - lo);
    }
}

//! Drawing the closed-world cases: random duties and effects of the first
//! simulator, and the benchmark's configuration.

use tcomp_numerics::rng::Rng;
use tcomp_thermal::sim::{Duty, Effect, Machine};

/// A random 8 h (or `hours`) duty: segments of 10–60 min.
pub fn random_duty(g: &mut Rng, n_max: f64, hours: f64) -> Duty {
    let mut d = Duty {
        name: "random".into(),
        ..Default::default()
    };
    let mut t = 0.0;
    // start at rest for 10–30 min
    let rest = 600.0 + 300.0 * (g.uniform() * 4.0).floor();
    let push = |d: &mut Duty, t: f64, rpm: f64, feed: f64, cool: f64| {
        d.t.push(t);
        d.rpm.push(rpm);
        d.feed.push(feed);
        d.coolant.push(cool);
        d.ambient.push(None);
    };
    push(&mut d, t, 0.0, 0.0, 0.0);
    t += rest;
    while t < hours * 3600.0 {
        let dur = 600.0 * (1.0 + (g.uniform() * 6.0).floor());
        let running = g.uniform() > 0.25;
        let rpm = if running {
            (n_max * (0.15 + 0.85 * g.uniform()) / 500.0).round() * 500.0
        } else {
            0.0
        };
        let feed = if running {
            (g.uniform() * 100.0).round() / 100.0
        } else {
            0.0
        };
        let cool = if running && g.uniform() < 0.6 {
            1.0
        } else {
            0.0
        };
        push(&mut d, t, rpm, feed, cool);
        t += dur;
    }
    d.end_s = hours * 3600.0;
    d
}

pub(super) fn lu(g: &mut Rng, a: f64, b: f64) -> f64 {
    a + (b - a) * g.uniform()
}

/// An effect of `kind` at a random strength visible above sensor noise.
pub fn random_effect(g: &mut Rng, m: &Machine, kind: &str) -> Effect {
    let sign = if g.uniform() < 0.5 { -1.0 } else { 1.0 };
    match kind {
        "convection" => Effect::Convection {
            h_w_per_m2k: lu(g, 4.0, 20.0),
        },
        "ambient_drift" => Effect::AmbientDrift {
            amp_c: lu(g, 0.8, 3.0),
            phase_h: lu(g, 0.0, 24.0),
            rate_c_per_h: lu(g, -0.3, 0.3),
            period_h: 24.0,
        },
        "sensor_lag" => Effect::SensorLag {
            tau_s: (lu(g, 60f64.ln(), 400f64.ln())).exp(),
            sensor: None,
        },
        "bearing_nonlinear" => Effect::BearingNonlinear {
            k_w: lu(g, 20.0, 80.0),
            p: lu(g, 1.5, 2.0),
            node: None,
        },
        "coolant" => Effect::Coolant {
            g_w_per_k: (lu(g, 5f64.ln(), 40f64.ln())).exp(),
            offset_c: lu(g, -4.0, -1.0),
            amp_c: lu(g, 0.2, 1.0),
            period_s: lu(g, 600.0, 1800.0),
        },
        "ballscrew" => Effect::Ballscrew {
            k_w: lu(g, 30.0, 150.0),
        },
        "bending" => Effect::Bending {
            k_um_per_k: sign * lu(g, 0.5, 3.0),
        },
        _ => {
            let i =
                ((g.uniform() * m.sensor_cols.len() as f64) as usize).min(m.sensor_cols.len() - 1);
            Effect::SensorOffset {
                sensor: m.sensor_cols[i].clone(),
                offset_c: sign * lu(g, 0.3, 1.5),
                at_s: 0.0,
                run: None,
            }
        }
    }
}

pub struct BenchConfig {
    pub cases: usize,
    pub seed: u64,
    pub hours: f64,
    pub sample_period_s: f64,
    pub threads: usize,
    pub verbose: bool,
    /// Machine-file column: calibrate the file's design values first.
    pub calibrate: bool,
}

//! Simulated displacement-line measurements: a machine with random smooth
//! errors, measured along the plan's lines by an interferometer with noise
//! and setup errors.
//!
//! This path is deliberately not the identifier's: readings come from the
//! exact homogeneous-transform kinematics (`tool_tip_error_exact`) of the
//! reflector's true position, projected on the true (misaligned) beam, while
//! the identifier uses the first-order sensitivities of the nominal setup.

use super::errors::{GeometricErrors, Poly, Squareness, Term};
use super::identify::{Degrees, LineKind};
use super::kinematics::{tool_tip_error_exact, Structure};
use super::lines::{LineFile, LineSpec, Run};
use tcomp_numerics::rng::Rng;

/// Sizes of the random machine's errors (peak over the stroke).
#[derive(Clone, Copy, Debug)]
pub struct ErrorSizes {
    pub positioning_um: f64,
    pub straightness_um: f64,
    pub angular_urad: f64,
    pub squareness_urad: f64,
    /// Degrees of the random polynomials per term group.
    pub degrees: Degrees,
}

impl Default for ErrorSizes {
    fn default() -> Self {
        ErrorSizes {
            positioning_um: 10.0,
            straightness_um: 6.0,
            angular_urad: 20.0,
            squareness_urad: 20.0,
            degrees: Degrees::default(),
        }
    }
}

/// A random smooth machine: per term a polynomial with decaying random
/// coefficients, scaled to a random peak between half and all of the size.
pub fn random_errors(stroke_mm: [f64; 3], sizes: &ErrorSizes, rng: &mut Rng) -> GeometricErrors {
    let mut e = GeometricErrors::zero();
    for t in Term::all() {
        let l = stroke_mm[t.axis.index()];
        let degree = sizes.degrees.of(t).max(1);
        let mut coeffs: Vec<f64> = (1..=degree).map(|j| rng.normal() / j as f64).collect();
        if t.is_straightness() {
            // The bow about the end-point line: Σ c_j (u^j − u), j ≥ 2.
            coeffs[0] = -coeffs[1..].iter().sum::<f64>();
        }
        let p = Poly::new(l, coeffs);
        let peak = (0..=50)
            .map(|i| p.eval(l * i as f64 / 50.0).abs())
            .fold(0.0, f64::max)
            .max(1e-12);
        let size = if t.component.is_angular() {
            sizes.angular_urad
        } else if t.is_straightness() {
            sizes.straightness_um
        } else {
            sizes.positioning_um
        };
        let mut p = p.scaled(size * rng.range(0.5, 1.0) / peak);
        if t.is_straightness() && !p.coeffs.is_empty() {
            // Plus an end-point slope of up to ± size over the stroke.
            p.coeffs[0] += size * rng.range(-1.0, 1.0);
        }
        e.set(t, p);
    }
    let s = sizes.squareness_urad;
    e.squareness = Squareness {
        c0y: rng.range(-s, s),
        b0z: rng.range(-s, s),
        a0z: rng.range(-s, s),
    };
    e
}

/// How the simulated measurement deviates from the ideal one.
#[derive(Clone, Copy, Debug)]
pub struct MeasurementSetup {
    /// Reading noise, standard deviation [µm].
    pub noise_um: f64,
    /// Beam misalignment, standard deviation of each tilt angle [µrad].
    pub beam_misalignment_urad: f64,
    /// Reflector position error per coordinate, standard deviation [mm].
    pub reflector_offset_mm: f64,
    /// Lost motion per axis [µm]: the backward run reads this much less
    /// (projected on the beam) than the forward run.
    pub reversal_um: [f64; 3],
    /// Targets per line, ends included.
    pub targets: usize,
}

impl Default for MeasurementSetup {
    fn default() -> Self {
        MeasurementSetup {
            noise_um: 0.5,
            beam_misalignment_urad: 200.0,
            reflector_offset_mm: 1.0,
            reversal_um: [3.0, 2.0, 4.0],
            targets: 21,
        }
    }
}

/// Forward and backward run of one line on the machine `truth`.
/// The backward run keeps the forward run's zero (one bidirectional
/// measurement), so forward − backward is the lost motion along the beam.
/// A straightness line (`spec.kind`) reads the tool point's motion along
/// its sense, the optic tilted towards the travel by the beam misalignment
/// (a slope) and set at an arbitrary offset; no laser scale.
pub fn measure_line(
    st: &Structure,
    truth: &GeometricErrors,
    spec: &LineSpec,
    setup: &MeasurementSetup,
    temperature_state: Option<&str>,
    rng: &mut Rng,
) -> [LineFile; 2] {
    // Setup errors, fixed for the line: the reflector is not quite where the
    // plan says and the beam is not quite along the line.
    let reflector =
        [0, 1, 2].map(|k| spec.tool_offset_mm[k] + setup.reflector_offset_mm * rng.normal());
    let straight = spec.kind == LineKind::Straightness;
    let beam = if straight {
        // The optic's reference turned about the normal of (travel, sense).
        let a = setup.beam_misalignment_urad * 1e-6 * rng.normal();
        let v = [0, 1, 2].map(|k| spec.sense[k] + a * spec.direction[k]);
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / n)
    } else {
        tilt(
            spec.direction,
            setup.beam_misalignment_urad * 1e-6 * rng.normal(),
            setup.beam_misalignment_urad * 1e-6 * rng.normal(),
        )
    };
    let offset_um = if straight { 5.0 * rng.normal() } else { 0.0 };
    let targets = spec.targets(setup.targets);
    let point = |pos: [f64; 3]| -> [f64; 3] {
        let e = tool_tip_error_exact(st, truth, pos, reflector);
        [0, 1, 2].map(|k| pos[k] + reflector[k] + e[k] * 1e-3)
    };
    let p0 = point(targets[0].1);
    let lost: f64 = (0..3)
        .filter(|k| spec.direction[*k].abs() > 1e-9)
        .map(|k| setup.reversal_um[k] * spec.direction[k].signum() * beam[k])
        .sum();
    let mut run_file = |run: Run| {
        let disp = targets
            .iter()
            .map(|(s, pos)| {
                let p = point(*pos);
                let along: f64 = (0..3).map(|k| beam[k] * (p[k] - p0[k])).sum();
                let nominal = if straight { 0.0 } else { *s };
                let d = (along - nominal) * 1e3 + offset_um + setup.noise_um * rng.normal();
                if run == Run::Backward {
                    d - lost
                } else {
                    d
                }
            })
            .collect();
        LineFile {
            spec: spec.clone(),
            structure: st.clone(),
            run,
            temperature_state: temperature_state.map(str::to_string),
            source: "simulated".into(),
            s_mm: targets.iter().map(|t| t.0).collect(),
            pos_mm: targets.iter().map(|t| t.1).collect(),
            disp_um: disp,
            temps: Vec::new(),
        }
    };
    let forward = run_file(Run::Forward);
    let backward = run_file(Run::Backward);
    [forward, backward]
}

/// Turn a unit vector by two small angles about two axes perpendicular to it.
fn tilt(d: [f64; 3], a: f64, b: f64) -> [f64; 3] {
    let dv = nalgebra::Vector3::from(d);
    let helper = if d[0].abs() < 0.9 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let p1 = dv.cross(&helper).normalize();
    let p2 = dv.cross(&p1);
    let v = (dv + p1 * a + p2 * b).normalize();
    [v[0], v[1], v[2]]
}

/// `a + f·b`, term by term (polynomials of the same scale).
pub fn add_scaled(a: &GeometricErrors, b: &GeometricErrors, f: f64) -> GeometricErrors {
    let mut out = a.clone();
    for t in Term::all() {
        let (pa, pb) = (a.get(t), b.get(t));
        let scale = if pa.coeffs.is_empty() {
            pb.scale_mm
        } else {
            pa.scale_mm
        };
        let k = pb.scale_mm / scale; // u_b = u_a · scale / scale_b
        let n = pa.coeffs.len().max(pb.coeffs.len());
        let coeffs = (0..n)
            .map(|j| {
                let ca = pa.coeffs.get(j).copied().unwrap_or(0.0);
                let cb = pb.coeffs.get(j).copied().unwrap_or(0.0);
                ca + f * cb / k.powi(j as i32 + 1)
            })
            .collect();
        out.set(t, Poly::new(scale, coeffs));
    }
    for i in 0..3 {
        out.squareness
            .set(i, a.squareness.get(i) + f * b.squareness.get(i));
    }
    out
}

/// A machine whose errors change linearly with a few sensor temperatures.
#[derive(Clone, Debug)]
pub struct ThermalMachine {
    pub base: GeometricErrors,
    pub sensors: Vec<String>,
    /// Per sensor: the errors added per kelvin above `t_ref_c`.
    pub per_kelvin: Vec<GeometricErrors>,
    pub t_ref_c: f64,
}

impl ThermalMachine {
    pub fn random(stroke_mm: [f64; 3], sensors: &[&str], rng: &mut Rng) -> ThermalMachine {
        let sizes = ErrorSizes::default();
        let base = random_errors(stroke_mm, &sizes, rng);
        // Per kelvin: about a tenth of the cold errors (µm/K, µrad/K).
        let k = ErrorSizes {
            positioning_um: 1.5,
            straightness_um: 0.5,
            angular_urad: 1.5,
            squareness_urad: 1.5,
            degrees: sizes.degrees,
        };
        let per_kelvin = sensors
            .iter()
            .map(|_| random_errors(stroke_mm, &k, rng))
            .collect();
        ThermalMachine {
            base,
            sensors: sensors.iter().map(|s| s.to_string()).collect(),
            per_kelvin,
            t_ref_c: 20.0,
        }
    }

    pub fn at(&self, temps: &[f64]) -> GeometricErrors {
        self.per_kelvin
            .iter()
            .zip(temps)
            .fold(self.base.clone(), |e, (d, t)| {
                add_scaled(&e, d, t - self.t_ref_c)
            })
    }
}

/// The lines of one temperature state, with the sensors' readings (state
/// temperature + N(0, 0.05 K)) as `T_` columns.
pub fn measure_state(
    st: &Structure,
    machine: &ThermalMachine,
    temps: &[f64],
    state: &str,
    plan: &[LineSpec],
    setup: &MeasurementSetup,
    rng: &mut Rng,
) -> Vec<LineFile> {
    let truth = machine.at(temps);
    let mut out = Vec::new();
    for spec in plan {
        for mut f in measure_line(st, &truth, spec, setup, Some(state), rng) {
            f.temps = machine
                .sensors
                .iter()
                .zip(temps)
                .map(|(n, t)| {
                    let v = (0..f.s_mm.len()).map(|_| t + 0.05 * rng.normal()).collect();
                    (n.clone(), v)
                })
                .collect();
            out.push(f);
        }
    }
    out
}

//! Issue 49 item 3: the rotary joint fit with the generic linear model. A
//! machine whose pitch, yaw and roll carry waves (1–1.5 per stroke, 4–6
//! µrad) beside the default random polynomials, measured with the rich
//! 28-line plan, and a spindle tilted relative to the lines' frame seen
//! with two tool lengths: the polynomial linear model cannot carry the
//! waves, and through the tool length its misfit aliases into the spindle
//! direction and the location errors; the generic model carries them.

use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::errors::{GeometricErrors, Poly, Term};
use tcomp_geometry::generic::{identify_generic, null_combinations, MIN_LINES};
use tcomp_geometry::identify::{identify, to_reference_convention, Degrees, LineObs};
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::average_runs;
use tcomp_geometry::plan::{plan14_grid, rich_additions};
use tcomp_geometry::rotary::identify::{RotaryIdentification, RotaryOptions};
use tcomp_geometry::rotary::joint::{identify_rotary_joint, LinearPrior};
use tcomp_geometry::rotary::joint_generic::{identify_rotary_joint_generic, GenericPrior};
use tcomp_geometry::rotary::sim::{random_rotary, simulate, CycleSetup, RPlan, RotarySizes};
use tcomp_geometry::rotary::{Linear, RotaryModel, Spindle};
use tcomp_geometry::sim::{measure_line, random_errors, ErrorSizes, MeasurementSetup};
use tcomp_numerics::rng::Rng;

const STROKE: [f64; 3] = [800.0, 700.0, 600.0];
const TILT: [f64; 2] = [18.0, -23.0];

/// a·(sin(ωu + φ) − sin φ) as a `Poly` in u = q / stroke (its Taylor series
/// to degree 45, exact to 1e-12 for ω ≤ 3π).
fn wave(stroke: f64, a: f64, omega: f64, phi: f64) -> Poly {
    let mut c = vec![0.0; 45];
    let mut term = 1.0;
    for n in 1..=45 {
        term *= omega / n as f64;
        // d^n/du^n sin(ωu + φ) at 0 = ω^n sin(φ + nπ/2)
        let s = (phi + n as f64 * std::f64::consts::FRAC_PI_2).sin();
        c[n - 1] = a * term * s;
    }
    Poly::new(stroke, c)
}

/// Default random errors plus a wave on every angular error.
fn wavy_machine(rng: &mut Rng) -> GeometricErrors {
    let mut e = random_errors(STROKE, &ErrorSizes::default(), rng);
    for t in Term::all().filter(|t| t.component.is_angular()) {
        let l = STROKE[t.axis.index()];
        let w = wave(
            l,
            rng.range(4.0, 6.0),
            2.0 * std::f64::consts::PI * rng.range(1.0, 1.5),
            rng.range(0.0, std::f64::consts::TAU),
        );
        let mut p = e.get(t).clone();
        p.coeffs.resize(w.coeffs.len().max(p.coeffs.len()), 0.0);
        for (k, c) in w.coeffs.iter().enumerate() {
            p.coeffs[k] += c;
        }
        e.set(t, p);
    }
    to_reference_convention(&e, STROKE)
}

struct Case {
    st: Structure,
    lines: Vec<LineObs>,
    files: Vec<tcomp_geometry::rtest::RTestFile>,
    truth: RotaryModel,
}

fn case(seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    let st = Structure::parse("/XYZ").unwrap();
    let truth_lin = wavy_machine(&mut rng);
    let setup = MeasurementSetup::default();
    let mut lf = Vec::new();
    for (i, g) in plan14_grid().iter().chain(&rich_additions()).enumerate() {
        let spec = g.spec(&format!("L{:02}", i + 1), STROKE, 100.0, 100.0);
        lf.extend(measure_line(&st, &truth_lin, &spec, &setup, None, &mut rng));
    }
    let lines: Vec<LineObs> = average_runs(&lf)
        .unwrap()
        .into_iter()
        .map(|a| a.obs)
        .collect();
    // the default plan's three nests, each with tools 100 and 200 mm
    let mut plan = RPlan::default_plan();
    let nests: Vec<[f64; 3]> = plan.nests.iter().map(|(n, _)| *n).collect();
    plan.nests = (nests.iter())
        .flat_map(|n| [100.0, 200.0].map(move |l| (*n, [0.0, 0.0, l])))
        .collect();
    let mut truth = random_rotary(&plan, &RotarySizes::default(), false, &mut rng);
    truth.spindle = Some(Spindle {
        about_x_urad: TILT[0],
        about_y_urad: TILT[1],
        reference_tool_mm: [0.0; 3],
    });
    let lt = Linear {
        structure: &st,
        errors: &truth_lin,
    };
    let files = simulate(&truth, Some(lt), &plan, &CycleSetup::default(), &mut rng).unwrap();
    Case {
        st,
        lines,
        files,
        truth,
    }
}

/// Worst |error| of the spindle angles [µrad], and of the location errors
/// in units of their printed σ.
fn misses(id: &RotaryIdentification, truth: &RotaryModel) -> (f64, f64) {
    let spindle = (id.spindle.angles.iter().enumerate())
        .map(|(k, t)| (t.value.unwrap() - TILT[k]).abs())
        .fold(0.0, f64::max);
    let tl = truth.location.to_array();
    let loc = (id.location.iter().enumerate())
        .map(|(k, t)| (t.value.unwrap() - tl[k]).abs() / t.sigma.unwrap())
        .fold(0.0, f64::max);
    (spindle, loc)
}

#[test]
fn the_generic_linear_model_keeps_waves_out_of_the_spindle_and_the_location_errors() {
    let noise = StatedNoise::new(Some(0.5)).unwrap();
    let ro = RotaryOptions::default();
    for seed in [3, 4] {
        let c = case(seed);
        assert!(c.lines.len() >= MIN_LINES);
        assert!(null_combinations(&c.st, &c.lines, STROKE).is_empty());
        let g = identify_generic(&c.st, &c.lines, STROKE).unwrap();
        let p = GenericPrior {
            structure: &c.st,
            generic: &g,
            lines: &c.lines,
        };
        let (mut id, _) = identify_rotary_joint_generic(&c.files, &p, &ro).unwrap();
        id.assess(noise).unwrap();
        assert_eq!(id.linear.as_ref().unwrap().linear_model, "generic");
        assert_eq!(id.spindle.status, "identified", "{}", id.spindle.why);
        let (sp, loc) = misses(&id, &c.truth);

        let poly = identify(&c.st, &c.lines, Degrees::default(), STROKE).unwrap();
        let pp = LinearPrior {
            structure: &c.st,
            identification: &poly,
            lines: &c.lines,
        };
        let (mut idp, _) = identify_rotary_joint(&c.files, &pp, &ro).unwrap();
        idp.assess(noise).unwrap();
        let (sp_p, loc_p) = misses(&idp, &c.truth);
        println!(
            "seed {seed}: spindle worst |err| generic {sp:.2} µrad, poly {sp_p:.2}; location worst |err|/σ generic {loc:.2}, poly {loc_p:.2}; adequate generic {:?}, poly {:?}",
            id.adequate, idp.adequate
        );
        // the goal of issue 49 item 3: spindle within 3 µrad, every
        // location error within its 3σ, the model adequate
        assert!(sp <= 3.0, "seed {seed}: spindle off by {sp} µrad");
        assert!(loc <= 3.0, "seed {seed}: a location error {loc} σ off");
        assert!(id.adequate.unwrap(), "{}", id.adequacy.unwrap().failure);
        // the case discriminates: the polynomial route misses it
        assert!(
            sp_p > 3.0 || loc_p > 3.0 || !idp.adequate.unwrap(),
            "seed {seed}: the polynomial route meets the bounds too"
        );
    }
}

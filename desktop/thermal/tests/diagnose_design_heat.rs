//! Issue 27 (pair27): a heat effect inside the design's own heat tolerance
//! is not claimed. The calibration keeps the design's split of the heat
//! budget between sources, so a bearing whose friction the drawing puts
//! 15 % low used to come back as a small `bearing_nonlinear` (alone on a
//! clean machine, or as the partner of the right effect). Such a heat is
//! now barred (listed untestable with the reason), while a real extra
//! bearing heat of the size the benches draw is still named.
use std::path::PathBuf;

use tcomp_thermal::diagnose::design_heat::within_tolerance;
use tcomp_thermal::diagnose::{diagnose, prepare_all, Diagnosis, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Two 4 h runs (mixed duty) of `m` with `effects`, sampled at 10 s.
fn runs(m: &Machine, effects: &[Effect], seed: u64) -> Vec<(String, tcomp_data::runcsv::Run)> {
    let duty = Duty::load(&examples().join("duty/production-mixed.toml")).unwrap();
    (0..2)
        .map(|i| {
            let r = sim_run(
                m,
                &duty,
                &SimOptions {
                    effects: effects.to_vec(),
                    seed: seed + i,
                    hours: Some(4.0),
                    sample_period_s: Some(10.0),
                    noise: true,
                },
            )
            .unwrap();
            (format!("run{i}"), r)
        })
        .collect()
}

/// The design file: the truth with the rear bearing's friction (both
/// Palmgren terms) drawn 18 % low and the front one 8 % high — inside
/// the ±25 % heat tolerance, and a split the calibration (one heat gain
/// per driver) cannot undo.
fn design_of(truth: &Machine) -> Machine {
    let mut spec = truth.spec.clone();
    for (b, f) in spec.bearings.iter_mut().zip([1.08, 0.82]) {
        b.f0 *= f;
        b.f1 *= f;
    }
    Machine::compile(spec).unwrap()
}

fn claimed(d: &Diagnosis) -> Vec<String> {
    d.findings
        .iter()
        .filter(|f| !f.effects.is_empty())
        .map(|f| f.name.clone())
        .collect()
}

#[test]
fn bearing_heat_inside_the_design_tolerance_is_untestable_not_claimed() {
    let truth = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let design = design_of(&truth);
    let ps = prepare_all(&design, &runs(&truth, &[], 57), &Options::default()).unwrap();
    let bnl = |k_w: f64, p: f64, node: Option<&str>| Effect::BearingNonlinear {
        k_w,
        p,
        node: node.map(String::from),
    };
    // the partner the design column used to name beside the right effect
    // (bench-diagnose cross model, seed 11, case 4: 25 W, p 1.1 on both
    // bearings; 20 W here): ≤ 25 % of either bearing's design heat at the
    // top speed
    let why = within_tolerance(&design, &ps, &bnl(20.0, 1.1, None)).unwrap_or_default();
    assert!(why.contains("heat tolerance"), "20 W not barred: {why:?}");
    assert!(why.contains("rear_bearing"), "{why}");
    // the bench's real effects (54–118 W on both bearings) stay testable:
    // above a quarter of the rear bearing's heat
    assert_eq!(within_tolerance(&design, &ps, &bnl(90.0, 2.8, None)), None);
    // one bearing node only: its own design heat is the measure
    assert!(within_tolerance(&design, &ps, &bnl(30.0, 2.0, Some("front_bearing"))).is_some());
    assert_eq!(
        within_tolerance(&design, &ps, &bnl(90.0, 2.0, Some("front_bearing"))),
        None
    );
    // where the design puts no heat, any extra heat is testable
    assert_eq!(
        within_tolerance(&design, &ps, &bnl(5.0, 2.0, Some("bed"))),
        None
    );
    // not a heat effect: never barred by this rule
    let off = Effect::SensorOffset {
        sensor: "T01".into(),
        offset_c: 0.3,
        at_s: 0.0,
        run: None,
    };
    assert_eq!(within_tolerance(&design, &ps, &off), None);
}

#[test]
fn real_extra_bearing_heat_is_still_named_against_that_design() {
    let truth = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let design = design_of(&truth);
    let extra = Effect::BearingNonlinear {
        k_w: 90.0,
        p: 2.8,
        node: None,
    };
    let rs = runs(&truth, &[extra], 61);
    let d = diagnose(&design, &rs, &Options::default()).unwrap();
    let top = d
        .findings
        .first()
        .map(|f| f.name.clone())
        .unwrap_or_default();
    assert!(
        top.split('+').next() == Some("bearing_nonlinear"),
        "90 W of extra bearing heat: top {top:?}, all {:?}",
        claimed(&d)
    );
}

#[test]
fn the_calibration_moves_each_bearing_s_heat_on_its_own() {
    // the drawn split (front ×1.08, rear ×0.82) is a design error per
    // source; one heat gain per driver could not undo it, one per heated
    // node (inside the ±25 % tolerance) can: the calibrated rear/front
    // friction ratio must come part of the way back to the truth's (with
    // one gain per driver it stays the design's exactly; the rest is shared
    // with the links and films near the bearings, under the prior)
    let truth = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let design = design_of(&truth);
    let ps = prepare_all(&design, &runs(&truth, &[], 71), &Options::default()).unwrap();
    let cal = tcomp_thermal::diagnose::calibrate::calibrate(&design, &ps, 1).unwrap();
    let ratio = |m: &Machine| m.spec.bearings[1].f0 / m.spec.bearings[0].f0;
    let off_design = (ratio(&design) / ratio(&truth)).ln().abs();
    let off_cal = (ratio(&cal.machine) / ratio(&truth)).ln().abs();
    assert!(
        off_cal < 0.85 * off_design,
        "rear/front friction: truth {:.3}, design {:.3}, calibrated {:.3}",
        ratio(&truth),
        ratio(&design),
        ratio(&cal.machine)
    );
}

/// Issue 52: a bearing heat is judged by the design heat errors within
/// tolerance that best reproduce it over the speeds the runs reach — the
/// viscous term (f0, ∝ n^(5/3), its own calibration knob on the five-axis
/// head's rear bearing) and the rest of that node's heat (load term ∝ n,
/// motor), each inside its own tolerance — and barred only when they leave
/// no more of it than that tolerance. A steep heat (∝ n^1.7) of 70 % of
/// the viscous term at the top speed is a candidate: f0 ×1.25 and the
/// rest's n-law cannot follow it. The same law at 15 % of the viscous
/// term, and a shallow heat (∝ n^1.1) of 35 % of it that the load term
/// takes, are design errors the null may have: barred.
#[test]
fn a_steep_heat_is_measured_against_the_viscous_term_it_mimics() {
    let m = Machine::load(&examples().join("machines/five-axis-20.toml")).unwrap();
    let ps = prepare_all(&m, &runs(&m, &[], 71), &Options::default()).unwrap();
    let top = ps
        .iter()
        .flat_map(|p| p.inputs.rpm.iter().copied())
        .fold(0.0f64, f64::max);
    let (mut q, n_max) = (vec![0.0; m.n], m.spec.n_max_rpm);
    m.heat_nominal(top, &mut q);
    let rear = m.names.iter().position(|n| n == "rear_bearing").unwrap();
    // the design's viscous heat of the rear bearing at that speed
    let mut viscous = m.spec.clone();
    for b in viscous.bearings.iter_mut() {
        b.f1 = 0.0;
    }
    for s in viscous.sources.iter_mut() {
        s.w_at_nmax = 0.0;
    }
    viscous.motor_loss_frac = 0.0;
    let mv = Machine::compile(viscous).unwrap();
    let mut qv = vec![0.0; m.n];
    mv.heat_nominal(top, &mut qv);
    let at = |share: f64, p: f64| Effect::BearingNonlinear {
        k_w: share * qv[rear] / (top / n_max).powf(p),
        p,
        node: Some("rear_bearing".into()),
    };
    // the viscous term is part of the node's heat only (load term, motor)
    assert!(qv[rear] < 0.8 * q[rear], "{} of {}", qv[rear], q[rear]);
    // steep, 70 % of the viscous term: f0 ×1.25 and the rest's n-law
    // within its tolerance leave too much of it
    assert_eq!(within_tolerance(&m, &ps, &at(0.7, 1.7)), None);
    // steep but small: f0 within its tolerance reproduces it
    let why = within_tolerance(&m, &ps, &at(0.15, 1.7)).unwrap_or_default();
    assert!(why.contains("heat tolerance"), "15 % not barred: {why:?}");
    assert!(why.contains("rear_bearing viscous term (f0)"), "{why}");
    // shallow, 35 % of the viscous term: the load term takes it
    let why = within_tolerance(&m, &ps, &at(0.35, 1.1)).unwrap_or_default();
    assert!(
        why.contains("heat tolerance"),
        "shallow not barred: {why:?}"
    );
    // a heat no design law follows (∝ n^4), as large at the top speed as
    // the barred shallow one: it leaves too much, a candidate
    assert_eq!(within_tolerance(&m, &ps, &at(0.35, 4.0)), None);
}

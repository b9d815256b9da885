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

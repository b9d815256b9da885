//! Issue 27: a convection or bending effect that only changes design
//! values within their tolerance (the loss to air, the levers) cannot be
//! told from a design error of those values and is not claimed.
use std::path::PathBuf;

use tcomp_thermal::diagnose::design_mimic::within_tolerance;
use tcomp_thermal::sim::machine::spec::TermSpec;
use tcomp_thermal::sim::{Effect, Machine};

fn turning_center() -> Machine {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/machines/turning-center-16.toml");
    Machine::load(&p).unwrap()
}

/// The smallest film coefficient (loss to air over area) of the design
/// over the nodes with an area: convection adds h × area at each of them,
/// so this node decides whether it stays within the film tolerance.
fn smallest_film(m: &Machine) -> f64 {
    let films: Vec<f64> = (0..m.n)
        .filter(|&i| m.area[i] > 0.0)
        .map(|i| m.g_amb[i] / m.area[i])
        .collect();
    assert!(films.len() > 2, "the turning centre's nodes have areas");
    films.into_iter().fold(f64::INFINITY, f64::min)
}

#[test]
fn convection_within_the_film_tolerance_is_barred_and_beyond_it_is_not() {
    let m = turning_center();
    let h_design = smallest_film(&m);
    let conv = |h: f64| Effect::Convection { h_w_per_m2k: h };
    // the default ±25 % film tolerance: 20 % of the design film is inside
    let why = within_tolerance(&m, &conv(0.2 * h_design)).unwrap_or_default();
    assert!(why.contains("film tolerance"), "{why:?}");
    // 40 % is a convection the design cannot have
    assert_eq!(within_tolerance(&m, &conv(0.4 * h_design)), None);
    // a tighter tolerance in the file bars less
    let mut spec = m.spec.clone();
    spec.tolerance.insert("film".into(), 0.1);
    let tight = Machine::compile(spec).unwrap();
    assert_eq!(within_tolerance(&tight, &conv(0.2 * h_design)), None);
}

#[test]
fn bending_is_barred_only_when_both_levers_cover_it() {
    let m = turning_center();
    let bend = |k: f64| Effect::Bending { k_um_per_k: k };
    // headstock − bed in x: the bed has no lever in x, so no length error
    // of the design reproduces the bending, however small
    assert_eq!(within_tolerance(&m, &bend(0.01)), None);
    // give the bed a lever of 200 mm: α·200 mm ≈ 2.3 µm/K, headstock's
    // 250 mm ≈ 2.9 µm/K; a quarter of the smaller is ≈ 0.57 µm/K
    let mut spec = m.spec.clone();
    spec.directions[0].terms.push(TermSpec {
        node: "bed".into(),
        length_mm: 200.0,
    });
    let m2 = Machine::compile(spec).unwrap();
    let lever_bed = m2.spec.alpha_per_k * 1e3 * 200.0;
    let why = within_tolerance(&m2, &bend(0.2 * lever_bed)).unwrap_or_default();
    assert!(why.contains("length tolerance"), "{why:?}");
    assert_eq!(within_tolerance(&m2, &bend(-0.3 * lever_bed)), None);
}

#[test]
fn other_effects_are_never_barred_by_this_rule() {
    let m = turning_center();
    let lag = Effect::SensorLag {
        sensor: Some("T01".into()),
        tau_s: 30.0,
    };
    assert_eq!(within_tolerance(&m, &lag), None);
}

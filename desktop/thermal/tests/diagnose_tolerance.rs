//! Issue 27: tolerances in the machine file, the calibrated null by
//! default (a design 15 % off names nothing on clean runs) and a design
//! value that must leave its tolerance named as a finding.
use std::path::PathBuf;

use tcomp_thermal::diagnose::{diagnose, Options};
use tcomp_thermal::sim::{sim_run, Duty, Machine, SimOptions};

const SMALL: &str = r#"
name = "small"
ambient_c = 20.0
n_max_rpm = 10000.0
[[node]]
name = "head"
c_j_per_k = 20000.0
g_amb_w_per_k = 2.0
area_m2 = 0.5
[[node]]
name = "bed"
c_j_per_k = 90000.0
g_amb_w_per_k = 6.0
area_m2 = 2.0
[[link]]
a = "head"
b = "bed"
g_w_per_k = 5.0
[[source]]
node = "head"
w_at_nmax = 100.0
[[sensor]]
name = "T01"
node = "head"
[[direction]]
name = "z"
terms = [ { node = "head", length_mm = 300.0 } ]
"#;

fn with_tolerance(t: &str) -> anyhow::Result<Machine> {
    Machine::from_toml(&format!("{SMALL}\n[tolerance]\n{t}\n"))
}

fn one_line_error(t: &str, needle: &str) {
    let Err(e) = with_tolerance(t) else {
        panic!("`{t}` must be refused");
    };
    let msg = format!("{e:#}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    assert!(msg.contains(needle), "`{needle}` in: {msg}");
}

#[test]
fn tolerance_table_parses() {
    let m = with_tolerance(
        "default = 0.1\nfilm = 0.3\n\"link:bed-head\" = 0.05\n\"length:z:head\" = 0.0",
    )
    .unwrap();
    let tol = &m.spec.tolerance;
    use tcomp_thermal::sim::machine::tolerance::of;
    assert_eq!(of(tol, "film", Some("head")), 0.3);
    assert_eq!(of(tol, "capacity", Some("head")), 0.1);
    // a link named either way round
    assert_eq!(of(tol, "link", Some("head-bed")), 0.05);
    assert_eq!(of(tol, "length", Some("z:head")), 0.0);
    let none = Machine::from_toml(SMALL).unwrap();
    assert_eq!(of(&none.spec.tolerance, "film", Some("head")), 0.25);
}

#[test]
fn negative_tolerance_is_refused() {
    one_line_error("film = -0.1", "film = -0.1");
}

#[test]
fn nan_tolerance_is_refused() {
    one_line_error("default = nan", "default = NaN");
}

#[test]
fn tolerance_of_100_percent_is_refused() {
    one_line_error("link = 1.0", "allowed 0 ≤ tolerance < 1");
}

#[test]
fn unknown_tolerance_key_is_refused() {
    one_line_error(
        "\"film:spindle\" = 0.2",
        "`film:spindle`: unknown parameter",
    );
    one_line_error("conductance = 0.2", "`conductance`: unknown parameter");
}

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Two 4 h runs (light and full duty) of a machine, sampled at 10 s.
fn runs(m: &Machine, seed: u64) -> Vec<(String, tcomp_data::runcsv::Run)> {
    let duty = Duty::load(&examples().join("duty/production-mixed.toml")).unwrap();
    (0..2)
        .map(|i| {
            let r = sim_run(
                m,
                &duty,
                &SimOptions {
                    effects: vec![],
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

/// The design file: every capacity, loss and link of the truth off by a
/// deterministic ±10–15 %.
fn design_off(truth: &Machine) -> Machine {
    let f = |k: usize| if k.is_multiple_of(2) { 1.15 } else { 0.88 };
    let mut m = truth.clone();
    for (k, c) in m.c.iter_mut().enumerate() {
        *c *= f(k);
    }
    for (k, g) in m.g_amb.iter_mut().enumerate() {
        *g *= f(k + 1);
    }
    for (k, l) in m.links.iter_mut().enumerate() {
        l.2 *= f(k + 3);
    }
    m
}

#[test]
fn clean_runs_with_a_design_15_percent_off_name_nothing() {
    let truth = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let rs = runs(&truth, 31);
    let d = diagnose(&design_off(&truth), &rs, &Options::default()).unwrap();
    let named: Vec<&str> = d.findings.iter().map(|f| f.name.as_str()).collect();
    assert!(named.is_empty(), "clean runs, named {named:?}");
}

#[test]
fn film_coefficients_far_off_are_a_convection_finding() {
    let design = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let mut truth = design.clone();
    truth.g_amb.iter_mut().for_each(|g| *g *= 1.9);
    let rs = runs(&truth, 41);
    let d = diagnose(&design, &rs, &Options::default()).unwrap();
    let top = d.findings.first().expect("a finding");
    // convection named: the film group released, or the convection effect
    // (alone or as the base of the selected pair)
    assert!(
        top.name.split('+').any(|n| n == "convection"),
        "{} {:?}",
        top.name,
        top.params_json()
    );
    let p = top.params_json();
    if let Some(f) = p.get("factor").and_then(|f| f.as_f64()) {
        assert_eq!(p["parameter"], "film");
        assert!(f > 1.4 && f < 2.6, "film factor {f}");
    }
}

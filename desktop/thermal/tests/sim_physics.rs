//! Simulator physics: analytic steady state, energy balance, Palmgren heat,
//! determinism, DS18B20 quantisation, and the documented direction of every effect.
use tcomp_thermal::sim::machine::BearingSpec;
use tcomp_thermal::sim::{
    sim_run, simulate, steady_state, Duty, Effect, Inputs, Machine, SimOptions,
};

const TWO_NODE: &str = r#"
name = "two-node"
ambient_c = 20.0
n_max_rpm = 10000.0
[[node]]
name = "a"
c_j_per_k = 1000.0
g_amb_w_per_k = 2.0
area_m2 = 0.5
[[node]]
name = "b"
c_j_per_k = 3000.0
g_amb_w_per_k = 3.0
area_m2 = 0.5
[[link]]
a = "a"
b = "b"
g_w_per_k = 5.0
[[source]]
node = "a"
w_at_nmax = 100.0
[[sensor]]
name = "T01"
node = "a"
[[sensor]]
name = "T02"
node = "b"
[[sensor]]
name = "T03"
node = "ambient"
[[direction]]
name = "x"
terms = [ { node = "a", length_mm = 100.0 }, { node = "b", length_mm = -50.0 } ]
[effects]
coolant_nodes = ["a"]
ballscrew_nodes = ["b"]
bending = { a = "a", b = "b", direction = "x" }
"#;

/// `desktop/`, where the machine and duty files are.
fn examples() -> std::path::PathBuf {
    std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"))
}

fn constant(rpm: f64, dt: f64, n: usize, ambient: f64) -> Inputs {
    Inputs {
        t0: 0.0,
        dt,
        rpm: vec![rpm; n],
        feed: vec![0.5; n],
        coolant: vec![1.0; n],
        ambient: vec![ambient; n],
    }
}

#[test]
fn steady_state_matches_hand_solution_of_the_g_network() {
    let m = Machine::from_toml(TWO_NODE).unwrap();
    // Q = 100 W into a at n_max. Hand solution (ΔT above ambient):
    // (2+5)·a − 5·b = 100 ; −5·a + (3+5)·b = 0  →  a = 800/31, b = 500/31
    let (ea, eb) = (800.0 / 31.0, 500.0 / 31.0);
    let inp = constant(10000.0, 60.0, 24 * 60 * 2, 20.0); // 48 h at 60 s steps
    let out = simulate(&m, &inp, &[], 1).unwrap();
    let ta = *out.temps[0].last().unwrap();
    let tb = *out.temps[1].last().unwrap();
    assert!((ta - 20.0 - ea).abs() < 1e-6, "a: {ta}");
    assert!((tb - 20.0 - eb).abs() < 1e-6, "b: {tb}");
    let mut q = vec![0.0; m.n];
    m.heat_nominal(10000.0, &mut q);
    let ss = steady_state(&m, &q, 20.0, &[]).unwrap();
    assert!((ss[0] - 20.0 - ea).abs() < 1e-9 && (ss[1] - 20.0 - eb).abs() < 1e-9);
    // displacement = α·(100·ΔTa − 50·ΔTb) in µm
    let d = *out.disp[0].last().unwrap();
    let expect = 11.5e-6 * 1e3 * (100.0 * ea - 50.0 * eb);
    assert!((d - expect).abs() < 1e-6, "{d} vs {expect}");
}

#[test]
fn energy_balance_during_warm_up() {
    // stored heat = heat in − heat lost to ambient (trapezoid at a fine step)
    let m = Machine::from_toml(TWO_NODE).unwrap();
    let dt = 1.0;
    let inp = constant(7000.0, dt, 3 * 3600, 20.0);
    let out = simulate(&m, &inp, &[], 1).unwrap();
    let q_in = 100.0 * 0.7 * (inp.len() - 1) as f64 * dt;
    let mut lost = 0.0;
    let n = out.t.len();
    for k in 0..n - 1 {
        let l0 = 2.0 * (out.temps[0][k] - 20.0) + 3.0 * (out.temps[1][k] - 20.0);
        let l1 = 2.0 * (out.temps[0][k + 1] - 20.0) + 3.0 * (out.temps[1][k + 1] - 20.0);
        lost += 0.5 * (l0 + l1) * dt;
    }
    let stored = 1000.0 * (out.temps[0][n - 1] - 20.0) + 3000.0 * (out.temps[1][n - 1] - 20.0);
    let err = (q_in - lost - stored).abs() / q_in;
    assert!(err < 1e-4, "energy balance off by {:.2e} of the input", err);
}

#[test]
fn palmgren_bearing_heat() {
    let b = BearingSpec {
        node: "x".into(),
        dm_mm: 70.0,
        f0: 1.0,
        f1: 0.0005,
        load_n: 1500.0,
        nu_cst: 10.0,
    };
    let n: f64 = 9000.0;
    let m = 0.0005 * 1500.0 * 70.0 + 1e-7 * (10.0 * n).powf(2.0 / 3.0) * 70f64.powi(3);
    assert!((b.torque_nmm(n) - m).abs() < 1e-9);
    assert!((b.heat_w(n) - 1.047e-4 * n * m).abs() < 1e-9);
    assert_eq!(b.heat_w(0.0), 0.0);
    // low ν·n regime: M0 = 160e-7·f0·dm³
    let low = b.torque_nmm(100.0);
    assert!((low - (0.0005 * 1500.0 * 70.0 + 160e-7 * 70f64.powi(3))).abs() < 1e-9);
}

#[test]
fn seeded_runs_are_deterministic_and_quantised() {
    let m = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let duty = Duty::load(&examples().join("duty/warmup-steps.toml")).unwrap();
    let opt = |seed| SimOptions {
        effects: vec![],
        seed,
        hours: Some(2.0),
        sample_period_s: Some(10.0),
        noise: true,
    };
    let mut a = Vec::new();
    let mut b = Vec::new();
    let mut c = Vec::new();
    sim_run(&m, &duty, &opt(7))
        .unwrap()
        .write_to(&mut a)
        .unwrap();
    sim_run(&m, &duty, &opt(7))
        .unwrap()
        .write_to(&mut b)
        .unwrap();
    sim_run(&m, &duty, &opt(8))
        .unwrap()
        .write_to(&mut c)
        .unwrap();
    assert_eq!(a, b, "same seed, same bytes");
    assert_ne!(a, c, "another seed, other noise");
    let run = sim_run(&m, &duty, &opt(7)).unwrap();
    assert_eq!(run.rows(), 720);
    for col in run.temperature_columns() {
        for v in run.col(col).unwrap().iter().flatten() {
            let q = v * 16.0;
            assert!(
                (q - q.round()).abs() < 1e-9,
                "{col} = {v} is not a multiple of 1/16 °C"
            );
        }
    }
}

fn sim_with(effects: &[Effect]) -> tcomp_thermal::sim::SimOut {
    let m = Machine::from_toml(TWO_NODE).unwrap();
    let mut inp = constant(8000.0, 10.0, 6 * 360, 20.0);
    for k in 0..360 {
        inp.rpm[k] = 0.0; // first hour at rest
    }
    simulate(&m, &inp, effects, 1).unwrap()
}

#[test]
fn each_effect_changes_the_output_in_its_documented_direction() {
    let base = sim_with(&[]);
    let last = base.t.len() - 1;
    let mid = 360 + 6; // 1 min after the spindle starts: node a rising fast
                       // convection: more heat loss → cooler
    let e = sim_with(&[Effect::Convection { h_w_per_m2k: 10.0 }]);
    assert!(e.temps[0][last] < base.temps[0][last] - 1.0);
    // ambient drift with positive rate: ambient sensor and nodes warmer
    let e = sim_with(&[Effect::AmbientDrift {
        amp_c: 0.0,
        phase_h: 0.0,
        rate_c_per_h: 0.5,
        period_h: 24.0,
    }]);
    assert!((e.temps[2][last] - base.temps[2][last] - 0.5 * base.t[last] / 3600.0).abs() < 1e-9);
    assert!(e.temps[1][last] > base.temps[1][last] + 0.5);
    // sensor lag: reading behind a rising temperature, same at rest
    let e = sim_with(&[Effect::SensorLag {
        tau_s: 300.0,
        sensor: None,
    }]);
    assert!(e.temps[0][mid] < base.temps[0][mid] - 0.1);
    assert!((e.temps[0][100] - base.temps[0][100]).abs() < 1e-9);
    // extra bearing heat: no bearing in the two-node machine → use the turning center below
    // coolant at ambient − 3 °C on node a: cooler
    let e = sim_with(&[Effect::Coolant {
        g_w_per_k: 10.0,
        offset_c: -3.0,
        amp_c: 0.0,
        period_s: 900.0,
    }]);
    assert!(e.temps[0][last] < base.temps[0][last] - 1.0);
    // ball screw heat on b (feed 0.5): warmer b
    let e = sim_with(&[Effect::Ballscrew { k_w: 40.0 }]);
    assert!(e.temps[1][last] > base.temps[1][last] + 1.0);
    // bending: a hotter than b, k > 0 → larger dx by k·(ΔTa − ΔTb), temperatures unchanged
    let e = sim_with(&[Effect::Bending { k_um_per_k: 2.0 }]);
    let grad = (base.temps[0][last] - 20.0) - (base.temps[1][last] - 20.0);
    assert!(grad > 1.0);
    assert!((e.disp[0][last] - base.disp[0][last] - 2.0 * grad).abs() < 1e-6);
    assert_eq!(e.temps, base.temps);
    // sensor offset: exactly that sensor shifted
    let e = sim_with(&[Effect::SensorOffset {
        sensor: "T02".into(),
        offset_c: 0.75,
        at_s: 0.0,
        run: None,
    }]);
    assert!(e.temps[1]
        .iter()
        .zip(&base.temps[1])
        .all(|(a, b)| (a - b - 0.75).abs() < 1e-12));
    assert_eq!(e.temps[0], base.temps[0]);
}

#[test]
fn bearing_nonlinear_heats_the_bearings() {
    let m = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let inp = constant(9000.0, 10.0, 360 * 3, 20.0);
    let a = simulate(&m, &inp, &[], 1).unwrap();
    let b = simulate(
        &m,
        &inp,
        &[Effect::BearingNonlinear {
            k_w: 40.0,
            p: 2.0,
            node: None,
        }],
        1,
    )
    .unwrap();
    let last = a.t.len() - 1;
    assert!(
        b.temps[0][last] > a.temps[0][last] + 1.0,
        "front bearing T01"
    );
    assert!(
        b.temps[1][last] > a.temps[1][last] + 1.0,
        "rear bearing T02"
    );
}

#[test]
fn rod_conducts_from_the_hot_bearing() {
    // spindle nose (rod:0, T12) heats before the rod's middle (rod:5, T13) in the turning center
    let m = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let inp = constant(6000.0, 10.0, 360, 20.0);
    let a = simulate(&m, &inp, &[], 1).unwrap();
    let k = 60; // 10 min
    assert!(
        a.temps[11][k] > a.temps[12][k],
        "T12 {} vs T13 {}",
        a.temps[11][k],
        a.temps[12][k]
    );
}

#[test]
fn step_size_does_not_change_the_answer() {
    // exact ZOH discretisation: 1 s and 30 s steps agree at common times
    let m = Machine::load(&examples().join("machines/five-axis-20.toml")).unwrap();
    let duty = Duty::load(&examples().join("duty/warmup-steps.toml")).unwrap();
    let i1 = duty.inputs(1.0, Some(4.0 * 3600.0), 20.0);
    let i30 = duty.inputs(30.0, Some(4.0 * 3600.0), 20.0);
    let a = simulate(&m, &i1, &[], 30).unwrap();
    let b = simulate(&m, &i30, &[], 1).unwrap();
    assert_eq!(a.t.len(), b.t.len());
    for (sa, sb) in a.temps.iter().zip(&b.temps) {
        for (x, y) in sa.iter().zip(sb) {
            assert!((x - y).abs() < 1e-8);
        }
    }
}

#[test]
fn bad_inputs_give_clear_errors() {
    assert!(Effect::parse("nonsense=a:1")
        .unwrap_err()
        .to_string()
        .contains("unknown effect"));
    assert!(Effect::parse("convection=h:abc")
        .unwrap_err()
        .to_string()
        .contains("must be a number"));
    assert!(Effect::parse("convection=q:1")
        .unwrap_err()
        .to_string()
        .contains("unknown parameter"));
    let e = Effect::parse("sensor_offset=sensor:T05,offset_c:0.8").unwrap();
    assert_eq!(Effect::parse(&e.to_spec()).unwrap(), e);
    let err =
        Machine::from_toml("name = \"x\"\nambient_c = 20\n[[node]]\nname = \"a\"\n").unwrap_err();
    assert!(format!("{err:#}").contains("c_j_per_k"), "{err:#}");
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    std::fs::write(&p, "name = 3").unwrap();
    let err = Machine::load(&p).unwrap_err();
    assert!(format!("{err:#}").contains("bad.toml"), "{err:#}");
}

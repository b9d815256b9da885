use super::*;
use crate::five_axis::{
    tool_tip_error_exact5, tool_tip_error_linear5, RotaryErrors, RotaryPos, Turntable,
};
use crate::kinematics::Structure;
use crate::rotary::{tool_tip_error, Drift, Pose, COMPONENT_NAMES};
use crate::GeometricErrors;
use tcomp_numerics::rng::Rng;

fn eval(t: &Trig, deg: f64) -> f64 {
    let x = deg.to_radians();
    let mut v = t.c0;
    for h in 1..=t.order() {
        let hx = h as f64 * x;
        v += Trig::coef(&t.cos, h) * hx.cos() + Trig::coef(&t.sin, h) * hx.sin();
    }
    v
}

fn random_trig(rng: &mut Rng, order: usize) -> Trig {
    Trig {
        c0: rng.range(-3.0, 3.0),
        cos: (0..order).map(|_| rng.range(-3.0, 3.0)).collect(),
        sin: (0..order).map(|_| rng.range(-3.0, 3.0)).collect(),
    }
}

/// A model in the R-test convention with every location and component
/// error random (component order `order` on both axes).
fn random_fixed(rng: &mut Rng, order: usize) -> RotaryModel {
    let mut m = RotaryModel {
        pivot_a_mm: [400.0, 350.0, 400.0],
        offset_c_mm: [10.0, -20.0, 120.0],
        location: Location::from_array(std::array::from_fn(|k| {
            let s = if [2, 3, 6, 7].contains(&k) {
                30.0
            } else {
                20.0
            };
            rng.range(-s, s)
        })),
        ..Default::default()
    };
    for (k, name) in COMPONENT_NAMES.iter().enumerate() {
        let s = if k % 6 < 3 { 3.0 } else { 10.0 };
        let f = Fourier {
            cos: (0..order).map(|_| rng.range(-s, s)).collect(),
            sin: (0..order).map(|_| rng.range(-s, s)).collect(),
        };
        m.components.insert(name.to_string(), f);
    }
    m
}

/// The board-convention model as the simulator's rotating-frame turntable.
fn turntable(b: &board5::RotaryModel) -> Turntable {
    let mut t = Turntable {
        pivot_a_mm: b.pivot_a_mm,
        offset_c_mm: b.offset_c_mm,
        ..Default::default()
    };
    assert!(
        b.location.is_empty(),
        "static conversion: no location terms"
    );
    for (name, f) in &b.motion {
        let e: &mut RotaryErrors = if name.ends_with('A') {
            &mut t.a
        } else {
            &mut t.c
        };
        e.motion.insert(name.clone(), f.clone());
    }
    t
}

fn random_pose(rng: &mut Rng) -> (f64, f64, [f64; 3], [f64; 3]) {
    let a = rng.range(-120.0, 120.0);
    let c = rng.range(-360.0, 360.0);
    let pos = [
        rng.range(0.0, 800.0),
        rng.range(0.0, 700.0),
        rng.range(0.0, 600.0),
    ];
    let tool = [
        rng.range(-40.0, 40.0),
        rng.range(-40.0, 40.0),
        rng.range(50.0, 250.0),
    ];
    (a, c, pos, tool)
}

#[test]
fn multiplying_by_cos_and_sin_is_exact() {
    let mut rng = Rng::new(7);
    let t = random_trig(&mut rng, 4);
    for deg in [-170.0, -33.3, 0.0, 12.5, 91.0, 250.0] {
        let x = f64::to_radians(deg);
        assert!((eval(&t.times_cos(), deg) - x.cos() * eval(&t, deg)).abs() < 1e-12);
        assert!((eval(&t.times_sin(), deg) - x.sin() * eval(&t, deg)).abs() < 1e-12);
    }
    assert_eq!(t.times_cos().order(), 5);
}

#[test]
fn truncated_rms_is_the_rms_of_what_is_dropped() {
    let mut rng = Rng::new(8);
    let mut t = random_trig(&mut rng, 6);
    t.c0 = -t.cos.iter().sum::<f64>(); // zero at 0, as every converted term
    let (f, dropped) = t.to_fourier(4);
    assert_eq!(f.cos.len(), 4);
    let n = 3600;
    let ms: f64 = (0..n)
        .map(|k| {
            let deg = 360.0 * k as f64 / n as f64;
            (eval(&t, deg) - f.eval(deg)).powi(2)
        })
        .sum::<f64>()
        / n as f64;
    assert!(dropped > 0.5, "harmonics 5 and 6 are not small: {dropped}");
    assert!(
        (ms.sqrt() - dropped).abs() < 1e-9,
        "{} vs {dropped}",
        ms.sqrt()
    );
    assert_eq!(t.to_fourier(6).1, 0.0);
}

/// The conversion's claim: at random poses, the converted model gives the
/// tool-tip error of the fixed-frame model, to first order, through two
/// independent implementations (the R-test sensitivities of `model` for
/// the fixed frame, the rotating-frame chain of `five_axis` for the board's).
#[test]
fn converted_model_gives_the_same_tool_tip_error_at_random_poses() {
    let mut rng = Rng::new(31);
    let st = Structure::parse("/XYZ").unwrap();
    let zero = GeometricErrors::zero();
    let mut worst = 0.0f64;
    let mut seen = 0.0f64;
    for _ in 0..5 {
        let m = random_fixed(&mut rng, 3);
        let conv = to_board(&m, MAX_FOURIER_ORDER).unwrap();
        assert_eq!(conv.order_needed, 4);
        assert!(conv.truncated_rms.values().all(|v| *v == 0.0));
        let t = turntable(&conv.model);
        for _ in 0..40 {
            let (a, c, pos, tool) = random_pose(&mut rng);
            let p = [pos[0] + tool[0], pos[1] + tool[1], pos[2] + tool[2]];
            let fixed = rotary_error_machine(&m, &m.location, p, a, c);
            let r = RotaryPos { a_deg: a, c_deg: c };
            let w = tool_tip_error_linear5(&st, &zero, &t, pos, r, tool);
            let board = nominal_chain(m.pivot_a_mm, m.offset_c_mm, a, c).rotation * w;
            worst = worst.max((fixed - board).norm());
            seen = seen.max(fixed.norm());
        }
    }
    println!("worst |fixed − converted| {worst:.2e} µm, errors up to {seen:.1} µm");
    assert!(seen > 20.0, "errors large enough to test: {seen}");
    assert!(worst <= 1e-9, "{worst} µm");
}

/// The same in the exact rigid-body chains of both conventions: equal up
/// to second-order terms (they quarter when the errors halve).
#[test]
fn exact_chains_of_both_conventions_differ_by_second_order_terms_only() {
    let mut rng = Rng::new(5);
    let st = Structure::parse("/XYZ").unwrap();
    let zero = GeometricErrors::zero();
    let m = random_fixed(&mut rng, 2);
    let poses: Vec<_> = (0..30).map(|_| random_pose(&mut rng)).collect();
    let gap = |f: f64| {
        let mut s = m.clone();
        s.location = Location::from_array(m.location.to_array().map(|v| v * f));
        for fr in s.components.values_mut() {
            fr.cos
                .iter_mut()
                .chain(fr.sin.iter_mut())
                .for_each(|v| *v *= f);
        }
        let t = turntable(&to_board(&s, 4).unwrap().model);
        let mut g = 0.0f64;
        for (a, c, pos, tool) in &poses {
            let pose = Pose {
                pos_mm: *pos,
                a_deg: *a,
                c_deg: *c,
                tool_mm: *tool,
            };
            let fixed = tool_tip_error(&s, &s.location, None, &pose);
            let r = RotaryPos {
                a_deg: *a,
                c_deg: *c,
            };
            let rot = tool_tip_error_exact5(&st, &zero, &t, *pos, r, *tool);
            g = g.max((fixed - rot).norm());
        }
        g
    };
    let (g1, g2) = (gap(1.0), gap(0.5));
    println!("exact chains: gap {g1:.2e} µm, at half the errors {g2:.2e} µm");
    assert!(g1 < 0.05, "{g1}");
    assert!((3.0..5.0).contains(&(g1 / g2)), "second order: {}", g1 / g2);
}

#[test]
fn an_order_beyond_the_board_is_truncated_and_reported() {
    let mut rng = Rng::new(9);
    let m = random_fixed(&mut rng, 4);
    let conv = to_board(&m, 4).unwrap();
    assert_eq!(conv.order_needed, 5);
    assert!(conv.model.motion.values().all(|f| f.cos.len() <= 4));
    let (um, urad) = conv.worst_truncation();
    println!("order 4 → needs 5: dropped RMS up to {um:.3} µm, {urad:.3} µrad");
    assert!(um > 0.1 && urad > 0.1, "{um} {urad}");
    // ECC about C's own axis does not mix: its fifth harmonic is zero
    assert_eq!(conv.truncated_rms["ECC"], 0.0);
    assert_eq!(conv.truncated_rms["EAA"], 0.0);
}

#[test]
fn bad_orders_and_a_sensor_twice_are_refused_in_one_line() {
    let mut m = random_fixed(&mut Rng::new(2), 2);
    let e = to_board(&m, 5).unwrap_err().to_string();
    assert!(e.contains("up to 4") && !e.contains('\n'), "{e}");
    assert!(!to_board(&m, 4).unwrap().model.rtest_location);
    for _ in 0..2 {
        m.drift.push(Drift {
            sensor: "ctable".into(),
            reference_c: 20.0,
            per_kelvin: Location::default(),
        });
    }
    let e = to_board(&m, 4).unwrap_err().to_string();
    assert!(e.contains("ctable twice") && !e.contains('\n'), "{e}");
}

/// A model whose location errors drift (identify-rotary --drift) goes to
/// the section's R-test location mode: the served rotary part (integers,
/// `five_axis::evaluate`) against the model's f64 first-order prediction
/// at its location errors of that temperature state, at random poses ×
/// random temperature states, within the stated bound; and the drift is
/// really served (the same poses at another state move by microns).
#[test]
fn a_drifting_model_is_served_at_random_poses_and_temperature_states() {
    use crate::board::{quantize, BoardOptions};
    use crate::board5::FiveAxisOptions;
    use crate::rotary::board::{add_drift_sensors, rotary_section, stated_bound};
    use crate::sim::{random_errors, ErrorSizes};
    use crate::volumetric::build;
    use thermocomp_core::five_axis::{self, fstatus};
    let mut rng = Rng::new(131);
    let stroke = [800.0, 500.0, 400.0];
    let st = Structure::parse("/XYZ").unwrap();
    let lin = random_errors(stroke, &ErrorSizes::default(), &mut rng);
    let mut poly = build(&st, stroke, &lin, None).unwrap();
    let (mut worst, mut moved, mut n) = (0.0f64, 0.0f64, 0);
    for case in 0..4 {
        let mut m = random_fixed(&mut rng, 3);
        let names = ["ctable", "trunnion", "bed"];
        m.drift = (names.iter().zip([20.0, 21.3, 19.7]))
            .map(|(s, r)| Drift {
                sensor: s.to_string(),
                reference_c: r,
                per_kelvin: Location::from_array(std::array::from_fn(|k| {
                    let s = if [2, 3, 6, 7].contains(&k) { 2.0 } else { 1.0 };
                    rng.range(-s, s)
                })),
            })
            .collect();
        let mut p = poly.clone();
        if case == 0 {
            // one of them already read by the polynomial (as its run column)
            p.sensors = vec!["T_bed".into()];
            p.t_ref_c = vec![20.0];
        }
        add_drift_sensors(&mut p, &m).unwrap();
        assert_eq!(p.sensors.len(), 3);
        let opts = BoardOptions {
            channels: vec![0, 1, 2],
            slots: [0, 1, 2],
            origin_mm: [0.0; 3],
            tool_max_mm: 500.0,
            max_correction_um: 1000.0,
        };
        let vol = quantize(&p, &opts).unwrap();
        let o = FiveAxisOptions {
            max_correction_um: 1000.0,
            ..Default::default()
        };
        let (f, report) = rotary_section(&m, &vol, &p.sensors, &o, false).unwrap();
        assert!(report.rtest_location && f.n_sensors == 3, "{report:?}");
        assert!(report.max_error_um <= report.bound_um, "{report:?}");
        for _ in 0..50 {
            let (a, c) = (rng.range(-120.0, 120.0), rng.range(-360.0, 360.0));
            let pos_um = stroke.map(|s| (rng.range(0.0, s) * 1e3).round() as i32);
            let tool_um = (rng.range(50.0, 250.0) * 1e3).round() as i32;
            let (am, cm) = ((a * 1e3).round() as i32, (c * 1e3).round() as i32);
            let (ad, cd) = (f64::from(am) / 1e3, f64::from(cm) / 1e3);
            let p_mm = [0, 1, 2].map(|k| f64::from(pos_um[k]) / 1e3);
            let p_mm = [p_mm[0], p_mm[1], p_mm[2] + f64::from(tool_um) / 1e3];
            let mut served_at = Vec::new();
            for _ in 0..4 {
                let t16: Vec<i32> = (vol.sensors.iter())
                    .map(|s| s.sensor.ref_temp + (rng.range(-5.0, 8.0) * 16.0).round() as i32)
                    .collect();
                let temps: Vec<Option<i32>> = t16.iter().map(|t| Some(*t)).collect();
                let out = five_axis::evaluate(&vol, &f, &pos_um, tool_um, [am, cm], &temps);
                assert_eq!(out.five_status & fstatus::INCLUDED, fstatus::INCLUDED);
                let by_name = (p.sensors.iter().zip(&t16))
                    .map(|(n, t)| (n.trim_start_matches("T_").to_string(), f64::from(*t) / 16.0))
                    .collect();
                let loc = m.location_at(&by_name).unwrap();
                let want = rotary_error_machine(&m, &loc, p_mm, ad, cd);
                let arm = (Vector3::from(p_mm) / 1e3 - Vector3::from(m.pivot_a_mm) / 1e3).norm()
                    + m.offset_c_mm.iter().map(|v| v.abs()).sum::<f64>() / 1e3;
                let dt = (m.drift.iter())
                    .map(|d| (by_name[&d.sensor] - d.reference_c).abs())
                    .fold(0.0, f64::max);
                let bound = stated_bound(&f, arm, dt);
                for d in 0..3 {
                    let e = (f64::from(out.rotary[d]) / 10.0 - want[d]).abs();
                    assert!(e <= bound, "{e} > {bound} at A {ad} C {cd}");
                    worst = worst.max(e);
                }
                served_at.push(out.rotary);
                n += 1;
            }
            let spread = (0..3)
                .map(|d| {
                    let v: Vec<i32> = served_at.iter().map(|r| r[d]).collect();
                    f64::from(v.iter().max().unwrap() - v.iter().min().unwrap()) / 10.0
                })
                .fold(0.0, f64::max);
            moved = moved.max(spread);
        }
        poly = p.clone();
        poly.sensors.clear();
        poly.t_ref_c.clear();
    }
    println!(
        "drift served: {n} poses × states, worst |served − model f64| {worst:.4} µm; the drift moves the served part by up to {moved:.1} µm between states"
    );
    assert_eq!(n, 800);
    assert!(moved > 5.0, "the drift is served: {moved}");
}

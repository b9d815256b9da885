//! Kinematics of the 21 geometric errors: exact vs small-angle form, pure
//! positioning, Abbe terms, structure parsing.
use tcomp_geometry::*;

fn st(s: &str) -> Structure {
    Structure::parse(s).unwrap()
}

/// A machine with every error non-zero, sized like a real one (tens of µm,
/// tens of µrad over an 800 mm stroke).
fn busy_errors() -> GeometricErrors {
    let mut e = GeometricErrors::zero();
    for (i, t) in Term::all().enumerate() {
        let k = i as f64;
        let amp = if t.component.is_angular() { 30.0 } else { 12.0 };
        e.set(
            t,
            Poly::new(
                800.0,
                vec![
                    amp * (0.3 + 0.05 * k),
                    -amp * 0.4 * (k % 3.0 - 1.0),
                    amp * 0.2,
                ],
            ),
        );
    }
    e.squareness = Squareness {
        c0y: 25.0,
        b0z: -18.0,
        a0z: 9.0,
    };
    e
}

#[test]
fn structure_parses_and_orders_the_chain() {
    assert_eq!(st("XY/Z").chain(), [Axis::X, Axis::Y, Axis::Z]);
    assert_eq!(st("Y/XZ").chain(), [Axis::Y, Axis::X, Axis::Z]);
    assert_eq!(st("/ZYX").chain(), [Axis::Z, Axis::Y, Axis::X]);
    assert_eq!(st("XY/Z").to_string(), "XY/Z");
    for bad in ["XYZ", "XX/Z", "XY/", "XY/W", "XY/Z/"] {
        let err = Structure::parse(bad).unwrap_err().to_string();
        assert!(err.contains("structure"), "{bad}: {err}");
    }
}

#[test]
fn term_names_round_trip() {
    let names: Vec<String> = Term::all().map(|t| t.name()).collect();
    assert_eq!(names.len(), 18);
    assert_eq!(&names[..6], ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"]);
    for t in Term::all() {
        assert_eq!(Term::parse(&t.name()), Some(t));
    }
    assert!(Term::parse("EQX").is_none());
    assert!(Term::parse("EXX").unwrap().component == Component::Ex);
    assert!(Term::parse("EYX").unwrap().is_straightness());
    assert!(!Term::parse("EXX").unwrap().is_straightness());
}

#[test]
fn polynomials_are_zero_at_the_axis_zero() {
    let p = Poly::new(500.0, vec![3.0, -2.0, 1.0]);
    assert_eq!(p.eval(0.0), 0.0);
    let u = 250.0 / 500.0;
    assert!((p.eval(250.0) - (3.0 * u - 2.0 * u * u + u * u * u)).abs() < 1e-12);
}

#[test]
fn zero_errors_give_zero_error_everywhere() {
    let e = GeometricErrors::zero();
    let d = tool_tip_error_exact(&st("XY/Z"), &e, [300.0, 200.0, 100.0], [10.0, 20.0, 150.0]);
    assert!(d.norm() < 1e-9, "{d}");
}

#[test]
fn small_angle_and_exact_forms_agree_to_second_order() {
    let e = busy_errors();
    for s in ["XY/Z", "Y/XZ", "/XYZ"] {
        let s = st(s);
        let mut worst_ratio: f64 = 0.0;
        for (pos, tool) in [
            ([800.0, 500.0, 400.0], [50.0, -30.0, 150.0]),
            ([100.0, 450.0, 20.0], [0.0, 0.0, 100.0]),
            ([640.0, 30.0, 380.0], [-80.0, 60.0, 200.0]),
        ] {
            // Scale every error by λ: the first-order part scales by λ and
            // the difference exact − linear by λ², so halving λ quarters it.
            let diff = |lambda: f64| {
                let el = e.scaled(lambda);
                (tool_tip_error_exact(&s, &el, pos, tool)
                    - tool_tip_error_linear(&s, &el, pos, tool))
                .norm()
            };
            let (d1, d2) = (diff(1.0), diff(0.5));
            let full = tool_tip_error_linear(&s, &e, pos, tool).norm();
            assert!(full > 2.0, "the errors should matter: {full} µm");
            // Second order: tiny against the first-order error (< 0.1 %).
            assert!(
                d1 < 1e-3 * full,
                "{s} {pos:?}: exact-linear {d1} µm of {full}"
            );
            assert!(d1 > 1e-9, "{s}: the two forms are not the same formula");
            worst_ratio = worst_ratio.max((d1 / d2 - 4.0).abs());
        }
        assert!(worst_ratio < 0.05, "{s}: ratio off 4 by {worst_ratio}");
    }
}

#[test]
fn a_pure_positioning_error_shows_up_one_to_one() {
    let mut e = GeometricErrors::zero();
    let exx = Poly::new(800.0, vec![8.0, -3.0]);
    e.set(Term::parse("EXX").unwrap(), exx.clone());
    for s in ["XY/Z", "/XYZ", "Z/XY"] {
        for (pos, tool) in [
            ([400.0, 100.0, 50.0], [0.0, 0.0, 120.0]),
            ([800.0, 0.0, 300.0], [30.0, 40.0, 0.0]),
        ] {
            for d in [
                tool_tip_error_exact(&st(s), &e, pos, tool),
                tool_tip_error_linear(&st(s), &e, pos, tool),
            ] {
                assert!((d.x - exx.eval(pos[0])).abs() < 1e-9, "{s}: {d}");
                assert!(d.y.abs() < 1e-9 && d.z.abs() < 1e-9, "{s}: {d}");
            }
        }
    }
}

#[test]
fn an_angular_error_gives_the_abbe_term_with_the_tool_offset() {
    // Pitch of X (rotation about y): Δx = EBX · (z + tool_z), Δz = −EBX · (x arm).
    // XY/Z: the arm of X is y·ŷ + z·ẑ + tool (X sits next to the workpiece).
    let mut e = GeometricErrors::zero();
    e.set(Term::parse("EBX").unwrap(), Poly::new(800.0, vec![40.0])); // 40 µrad at x = 800
    let s = st("XY/Z");
    let (pos, tool) = ([800.0, 200.0, 300.0], [25.0, 0.0, 150.0]);
    let d = tool_tip_error_exact(&s, &e, pos, tool);
    let eps = 40.0e-6;
    // µrad × mm: 40e-6 × 450 mm = 0.018 mm = 18 µm.
    assert!((d.x - eps * (300.0 + 150.0) * 1e3).abs() < 1e-3, "{d}");
    assert!((d.z + eps * 25.0 * 1e3).abs() < 1e-3, "{d}");
    assert!(d.y.abs() < 1e-6, "{d}");
    // Yaw of Z (last in the chain): only the tool offset is an arm.
    let mut e = GeometricErrors::zero();
    e.set(Term::parse("ECZ").unwrap(), Poly::new(400.0, vec![50.0]));
    let d = tool_tip_error_linear(&s, &e, [0.0, 0.0, 400.0], [100.0, 0.0, 150.0]);
    assert!(
        (d.y - 50e-6 * 100.0 * 1e3).abs() < 1e-9 && d.x.abs() < 1e-9,
        "{d}"
    );
    let d = tool_tip_error_linear(&s, &e, [700.0, 400.0, 400.0], [0.0, 0.0, 150.0]);
    assert!(
        d.norm() < 1e-12,
        "ECZ has no arm without a lateral tool offset: {d}"
    );
}

#[test]
fn squareness_tilts_the_later_axis() {
    let mut e = GeometricErrors::zero();
    e.squareness.c0y = 20.0; // Y turned about +z: moving +Y also moves −X.
    let d = tool_tip_error_exact(&st("XY/Z"), &e, [0.0, 500.0, 0.0], [0.0, 0.0, 0.0]);
    assert!((d.x + 20e-6 * 500.0 * 1e3).abs() < 1e-6, "{d}");
    let mut e = GeometricErrors::zero();
    e.squareness.b0z = 10.0;
    e.squareness.a0z = -10.0;
    let d = tool_tip_error_linear(&st("XY/Z"), &e, [0.0, 0.0, 400.0], [0.0, 0.0, 0.0]);
    assert!((d.x - 4.0).abs() < 1e-9 && (d.y - 4.0).abs() < 1e-9, "{d}");
}

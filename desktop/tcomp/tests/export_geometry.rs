//! `tcomp export --geometry` (issue 14 item 4): the volumetric polynomial of
//! `tcomp geometry table --json` goes into the image (section kind 3), the
//! served value stays within the reported quantisation bound of the f64
//! polynomial, and what the board cannot hold is refused with one line.
mod common;
use common::{ok, refused};
use std::path::Path;
use tcomp_geometry::volumetric::VolumetricPoly;

fn table(dir: &Path) -> VolumetricPoly {
    ok(
        dir,
        &["geometry", "simulate", "--out", "lines", "--seed", "3"],
    );
    let json = ok(
        dir,
        &[
            "geometry",
            "table",
            "--model",
            "lines/errors.json",
            "--json",
        ],
    );
    std::fs::write(dir.join("vol.json"), &json).unwrap();
    serde_json::from_str(&json).unwrap()
}

#[test]
fn the_section_lands_in_the_image_within_the_reported_bound() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let poly = table(d);
    let out = ok(
        d,
        &[
            "export",
            "--demo",
            "--geometry",
            "vol.json",
            "-o",
            "m.img",
            "--json",
        ],
    );
    let s: serde_json::Value = serde_json::from_str(&out).unwrap();
    let v = &s["volumetric"];
    assert_eq!(v["terms"].as_u64().unwrap() as usize, poly.terms.len());
    let (worst, bound) = (
        v["max_error_um"].as_f64().unwrap(),
        v["bound_um"].as_f64().unwrap(),
    );
    assert!(worst <= bound && bound < 0.06, "{v}");
    assert!(worst > 0.0, "the 0.1 µm registers cannot be exact: {v}");
    assert!(
        v["max_error_before_rounding_um"].as_f64().unwrap() < 1e-3,
        "{v}"
    );
    // The image carries it, and the board's evaluation follows the polynomial.
    let model = thermocomp_core::Model::parse(&std::fs::read(d.join("m.img")).unwrap()).unwrap();
    let sec = model.volumetric.as_ref().expect("section kind 3");
    let mut pos = [0i32; 6];
    let at_mm = [611.0, 77.0, 250.0];
    for k in 0..3 {
        pos[usize::from(sec.slots[k])] = (at_mm[k] * 1e3) as i32;
    }
    let served = tcomp_geometry::board::predict(&model, &pos, 150_000, &[]).unwrap();
    let want = poly.eval(at_mm, 150.0, &[]);
    for k in 0..3 {
        assert!(
            (f64::from(served.corrections[k]) / 10.0 - want[k]).abs() <= bound,
            "{k}: {served:?} vs {want:?}"
        );
    }
    assert!(want.iter().any(|w| w.abs() > 1.0), "a real error: {want:?}");
    // The same export without --geometry has no section.
    ok(d, &["export", "--demo", "-o", "plain.img"]);
    let plain =
        thermocomp_core::Model::parse(&std::fs::read(d.join("plain.img")).unwrap()).unwrap();
    assert!(plain.volumetric.is_none());
}

#[test]
fn what_the_board_cannot_hold_is_refused_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let poly = table(d);
    let write = |name: &str, p: &VolumetricPoly| {
        std::fs::write(d.join(name), serde_json::to_string(p).unwrap()).unwrap();
    };
    // Sensors need the run's channel order.
    let mut thermal = poly.clone();
    thermal.sensors = vec!["t4".into()];
    thermal.t_ref_c = vec![20.0];
    write("thermal.json", &thermal);
    refused(
        d,
        &[
            "export",
            "--demo",
            "--geometry",
            "thermal.json",
            "-o",
            "x.img",
        ],
        "--run",
    );
    // More terms than the section holds.
    let mut many = poly.clone();
    while many.terms.len() <= 256 {
        many.terms.extend(poly.terms.iter().cloned());
    }
    write("many.json", &many);
    refused(
        d,
        &["export", "--demo", "--geometry", "many.json", "-o", "x.img"],
        "MAX_VOL_TERMS",
    );
    // A coefficient beyond ±2147 µm at full scale.
    let mut big = poly.clone();
    big.terms[0].coef_um[1] = 3000.0;
    write("big.json", &big);
    refused(
        d,
        &["export", "--demo", "--geometry", "big.json", "-o", "x.img"],
        "2147",
    );
    // Not a table at all.
    std::fs::write(d.join("junk.json"), "{}").unwrap();
    refused(
        d,
        &["export", "--demo", "--geometry", "junk.json", "-o", "x.img"],
        "geometry table",
    );
    assert!(!d.join("x.img").exists(), "nothing written on a refusal");
}

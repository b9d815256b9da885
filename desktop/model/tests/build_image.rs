//! `tcomp_model::export::build_image`, the one place a float model and its
//! sections become the board's image (export writes it, the extrapolation
//! bench replays it): fallbacks left out from the last until the image
//! fits, an image still over MAX_IMAGE_BYTES refused, and `extrapolate`
//! judged on the fallbacks the image keeps.

use tcomp_model::export::{build_image, Sections};
use thermocomp_core::float::{
    demo_model, FloatFallback, FloatModel, FloatNet, FloatTable, FloatTerm,
};
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy, NONE};
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::volumetric::{VolTerm, Volumetric, VolumetricSpec};

fn term(coef_um: f64, input: Option<u8>, input_power: u8) -> FloatTerm {
    FloatTerm {
        coef_um,
        input,
        input_power,
        position_power: 0,
    }
}

/// The demo model with Y (direction 2) made linear (its square term a
/// plain one), `extra` more 5-16-1 networks on Z and `tables` more linear
/// tables of 32 terms on Y.
fn base(extra: usize, tables: usize) -> FloatModel {
    let mut m = demo_model(1);
    m.tables[1].terms[1].input_power = 1;
    for k in 0..tables {
        m.tables.push(FloatTable {
            direction: 2,
            axis: None,
            terms: (0..32)
                .map(|i| term(0.01 * (i + k) as f64, Some((i % 3) as u8), 1))
                .collect(),
        });
    }
    for k in 0..extra {
        let w = |i: usize, j: usize| ((i * 7 + j * 3 + k) % 11) as f64 / 10.0 - 0.5;
        m.nets.push(FloatNet {
            direction: 0,
            inputs: vec![0, 1, 2, 3, 4],
            w1: (0..16).map(|i| (0..5).map(|j| w(i, j)).collect()).collect(),
            b1: (0..16).map(|i| w(i, 9) / 2.0).collect(),
            w2: (0..16).map(|i| w(i, 5)).collect(),
            b2: 0.1,
        });
    }
    m
}

/// `n` fallbacks for Y without sensor 0, linear (reading inputs 2 and 3),
/// each of `terms` terms; the last one with a square term when `square_last`.
fn fallbacks(n: usize, terms: usize, square_last: bool) -> Vec<FloatFallback> {
    (0..n)
        .map(|i| FloatFallback {
            direction: 2,
            excluded: vec![0],
            terms: (0..terms)
                .map(|k| {
                    let power = if square_last && i + 1 == n && k == 0 {
                        2
                    } else {
                        1
                    };
                    term(
                        0.5 + 0.01 * (i * terms + k) as f64,
                        Some(2 + (k % 2) as u8),
                        power,
                    )
                })
                .collect(),
        })
        .collect()
}

/// A volumetric section's report (its figures are not used here).
fn report(terms: usize) -> tcomp_geometry::board::QuantisationReport {
    tcomp_geometry::board::QuantisationReport {
        terms,
        sensors: 0,
        section_bytes: 0,
        grid_points: 0,
        max_error_um: 0.0,
        max_error_before_rounding_um: 0.0,
        bound_um: 0.0,
    }
}

/// Extrapolate on Y, and a volumetric section of `vol_terms` terms when
/// not 0.
fn extrapolate_y(vol_terms: usize) -> Sections {
    let mut envelope = [EnvelopePolicy::default(); 6];
    envelope[2] = EnvelopePolicy {
        mode: EnvelopeMode::Extrapolate,
        margin: 8,
    };
    Sections {
        geometry: (vol_terms > 0).then(|| (volumetric(vol_terms), report(vol_terms))),
        envelope: Some(envelope),
        ..Default::default()
    }
}

fn len(m: &FloatModel, s: &Sections) -> usize {
    let (mut fixed, _) = m.quantize().unwrap();
    fixed.envelope = s.envelope;
    fixed.volumetric = s.geometry.as_ref().map(|(v, _)| v.clone());
    fixed.encoded_len()
}

/// Networks, a volumetric section and fallbacks that make an image too
/// large with every fallback but small enough without them.
fn crowded(square_last: bool) -> (FloatModel, Sections) {
    let mut m = base(6, 0);
    m.fallbacks = fallbacks(30, 8, square_last);
    (m, extrapolate_y(200))
}

#[test]
fn fallbacks_are_left_out_from_the_last_until_the_image_fits() {
    let (m, s) = crowded(false);
    let mut without = m.clone();
    without.fallbacks.clear();
    assert!(len(&m, &s) > MAX_IMAGE_BYTES, "{}", len(&m, &s));
    assert!(len(&without, &s) <= MAX_IMAGE_BYTES);
    let built = build_image(&m, &s).unwrap();
    let n = built.fallbacks_left_out;
    assert!(n > 0 && n < m.fallbacks.len(), "{n}");
    assert!(built.bytes.len() <= MAX_IMAGE_BYTES);
    assert_eq!(built.bytes.len(), built.model.encoded_len());
    // The fewest: with one of them back, the image would not fit.
    let mut one_more = m.clone();
    one_more.fallbacks.truncate(m.fallbacks.len() - n + 1);
    assert!(len(&one_more, &s) > MAX_IMAGE_BYTES);
    // The first ones (highest priority) are the ones kept.
    let mut kept = m.clone();
    kept.fallbacks.truncate(m.fallbacks.len() - n);
    let (mut expect, _) = kept.quantize().unwrap();
    expect.envelope = s.envelope;
    expect.volumetric = s.geometry.as_ref().map(|(v, _)| v.clone());
    assert_eq!(
        built.bytes,
        tcomp_model::export::encode(&mut expect).unwrap()
    );
    assert_eq!(built.notes.len(), 1);
    assert!(
        built.notes[0].starts_with(&format!("note: {n} fallback model(s) left out")),
        "{:?}",
        built.notes
    );
    // What export writes is this image, byte for byte.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.img");
    let (envelope, output) = (s.envelope, s.output);
    tcomp_model::export::export_sections(&m, (s.geometry, None), (envelope, output), &path, None)
        .unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), built.bytes);
}

#[test]
fn extrapolate_is_judged_on_the_fallbacks_the_image_keeps() {
    // The square fallback is the last: left out, Y stays extrapolate.
    let (m, s) = crowded(true);
    let built = build_image(&m, &s).unwrap();
    assert!(built.fallbacks_left_out > 0);
    assert_eq!(
        built.model.envelope.unwrap()[2].mode,
        EnvelopeMode::Extrapolate
    );
    let parsed = thermocomp_core::Model::parse(&built.bytes).unwrap();
    assert_eq!(parsed.envelope.unwrap()[2].mode, EnvelopeMode::Extrapolate);
    assert!(built.notes.iter().all(|n| !n.contains("envelope")));
    // Kept (room for every fallback), it makes Y hold, with a note.
    let s = extrapolate_y(0);
    let mut roomy = base(0, 0);
    roomy.fallbacks = fallbacks(4, 3, true);
    let built = build_image(&roomy, &s).unwrap();
    assert_eq!(built.fallbacks_left_out, 0);
    assert_eq!(built.model.fallbacks.len(), 4);
    assert_eq!(built.model.envelope.unwrap()[2].mode, EnvelopeMode::Hold);
    assert_eq!(built.model.envelope.unwrap()[2].margin, 8);
    assert_eq!(built.notes.len(), 1);
    assert!(
        built.notes[0].starts_with("envelope dY_um: extrapolate needs a linear model"),
        "{:?}",
        built.notes
    );
    // Linear fallbacks only: extrapolate as asked, no note.
    roomy.fallbacks = fallbacks(4, 3, false);
    let built = build_image(&roomy, &s).unwrap();
    assert_eq!(
        built.model.envelope.unwrap()[2].mode,
        EnvelopeMode::Extrapolate
    );
    assert!(built.notes.is_empty());
}

/// A volumetric section of `n` terms (at most 256, every one the format holds).
fn volumetric(n: usize) -> Volumetric {
    let terms: Vec<VolTerm> = (0..n as u32)
        .map(|i| VolTerm {
            exps: [0, 1, 2, 3].map(|k| ((i >> (2 * k)) & 3) as u8),
            sensor: NONE,
            coef: [1000, -1000, 500],
        })
        .collect();
    Volumetric::new(&VolumetricSpec {
        slots: [0, 1, 2],
        origin_um: [0, 0, 0],
        stroke_um: [800_000, 500_000, 400_000],
        tool_max_um: 500_000,
        max_correction: [100_000; 3],
        sensors: &[],
        terms: &terms,
    })
    .unwrap()
}

#[test]
fn an_image_still_over_the_limit_is_refused() {
    let mut m = base(6, 2);
    m.fallbacks = fallbacks(2, 3, false);
    let s = Sections {
        geometry: Some((volumetric(256), report(256))),
        ..Default::default()
    };
    let err = build_image(&m, &s).unwrap_err().to_string();
    assert!(
        err.starts_with("the image with the volumetric section (4148 bytes, 256 terms) would be ")
            && err.ends_with("bytes; the board's upload staging area holds 8192 (MAX_IMAGE_BYTES)"),
        "{err}"
    );
    // Without the section the same model fits, fallbacks and all.
    let built = build_image(&m, &Sections::default()).unwrap();
    assert_eq!(built.fallbacks_left_out, 0);
    // export refuses it with the same line and writes nothing.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.img");
    let e = tcomp_model::export::export_with(&m, s.geometry.clone(), &path)
        .unwrap_err()
        .to_string();
    assert_eq!(e, err);
    assert!(!path.exists());
}

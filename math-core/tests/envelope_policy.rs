//! The envelope policy (issue 50 item 3, image section kind 5, format v3):
//! per direction a margin and `hold` or `fallback`; the step count; old
//! images read as `hold`, margin 0; a v3 image refused by the previous
//! format's version check.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::compensator::status::*;
use thermocomp_core::float::*;
use thermocomp_core::image::*;
use thermocomp_core::{Compensator, StepInput, StepOutput};

/// Two sensors by channel, their rises over 0 … 160 (10 °C); direction Z
/// = 10 µm·x0 + 5 µm·x1 (x normalised to [−1, 1]); one fallback without
/// sensor 0: 20 µm·x1 + 3 µm.
fn float_model() -> FloatModel {
    let sensor = |channel| SensorRef {
        rom: [0; 8],
        channel,
        ref_temp: 320,
    };
    let term = |coef_um, input: Option<u8>| FloatTerm {
        coef_um,
        input,
        input_power: u8::from(input.is_some()),
        position_power: 0,
    };
    let rise = |a| FloatInput {
        kind: InputKind::SensorRise { a },
        tau_s: None,
        min: 0.0,
        max: 160.0,
    };
    FloatModel {
        model_version: 7,
        step_ms: 1000,
        warmup_s: 0,
        fixed_reference: true,
        sensors: vec![sensor(0), sensor(1)],
        directions: vec![FloatDirection {
            name: "Z".into(),
            max_correction_um: 200.0,
            max_rate_um_per_s: 1000.0,
        }],
        axes: vec![],
        inputs: vec![rise(0), rise(1)],
        nets: vec![],
        tables: vec![FloatTable {
            direction: 0,
            axis: None,
            terms: vec![term(10.0, Some(0)), term(5.0, Some(1))],
        }],
        fallbacks: vec![FloatFallback {
            direction: 0,
            excluded: vec![0],
            terms: vec![term(20.0, Some(1)), term(3.0, None)],
        }],
    }
}

fn model(policy: Option<EnvelopePolicy>) -> Model {
    let (mut m, _) = float_model().quantize().unwrap();
    // One direction: the parser reads one entry, the rest stay default.
    m.envelope = policy.map(|p| {
        let mut all = [EnvelopePolicy::default(); 6];
        all[0] = p;
        all
    });
    m
}

fn encode(m: &mut Model) -> Vec<u8> {
    let mut b = vec![0u8; m.encoded_len()];
    assert_eq!(m.encode(&mut b).unwrap(), b.len());
    b
}

fn reseal(mut b: Vec<u8>) -> Vec<u8> {
    let n = b.len();
    let crc = crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

/// One step at `s` seconds with sensor rises `r0`, `r1` (1/16 °C over the
/// stored reference 320).
fn step(c: &mut Compensator, s: u64, r0: i32, r1: i32) -> StepOutput {
    c.step(&StepInput {
        now_ms: s * 1000,
        temps: &[Some(320 + r0), Some(320 + r1)],
        spindle_rpm: 0,
        positions: &[],
        stale: false,
    })
}

const FALLBACK: EnvelopePolicy = EnvelopePolicy {
    mode: EnvelopeMode::Fallback,
    margin: 16,
};

#[test]
fn beyond_the_margin_the_fallback_serves_within_it_the_edge_holds() {
    let mut c = Compensator::new(Some(model(Some(FALLBACK))));
    // Inside: the main model, 10·0 + 5·0 = 0 at mid-range (80, 80).
    let o = step(&mut c, 0, 80, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 0, 0));
    assert_eq!(o.status & OUT_OF_ENVELOPE, 0);
    // Sensor 0 at 160 + 16 = 176: beyond the range, within the margin:
    // held at the edge by the main model (10 + 0 = 10 µm = 100), not counted.
    let o = step(&mut c, 1, 176, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 0, 100));
    assert_ne!(
        o.status & OUT_OF_ENVELOPE,
        0,
        "held at the edge is still flagged"
    );
    assert_eq!(c.envelope_steps()[0], 0);
    // 177: beyond the margin → the fallback without sensor 0 (20·0 + 3 = 30).
    let o = step(&mut c, 2, 177, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (1, 1, 30));
    assert_ne!(o.status & DEGRADED, 0);
    assert_ne!(o.status & OUT_OF_ENVELOPE, 0);
    assert_eq!(c.envelope_steps()[0], 1);
    // Below the range too, sensor 1 held at its edge within its margin.
    let o = step(&mut c, 3, -17, 170);
    assert_eq!((o.active[0], o.predicted[0]), (1, 230));
    assert_eq!(c.envelope_steps()[0], 2);
    // Both beyond: the fallback reads sensor 1 too, so the main model
    // holds both at their edges (−10 + 5 µm).
    let o = step(&mut c, 4, -17, 200);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 1, -50));
    assert_eq!(c.envelope_steps()[0], 3);
    // Back inside: the main model again; the count stays.
    let o = step(&mut c, 5, 80, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 0, 0));
    assert_eq!(c.envelope_steps()[0], 3);
    // Sensor 1 beyond: the only fallback reads it, so the main model holds.
    let o = step(&mut c, 6, 80, 400);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 1, 50));
    assert_eq!(c.envelope_steps()[0], 4);
    // A new model restarts the count.
    c.load(Some(model(Some(FALLBACK))));
    assert_eq!(c.envelope_steps()[0], 0);
}

#[test]
fn hold_counts_the_same_steps_and_keeps_the_main_model() {
    let hold = EnvelopePolicy {
        mode: EnvelopeMode::Hold,
        margin: 16,
    };
    let mut c = Compensator::new(Some(model(Some(hold))));
    let o = step(&mut c, 0, 177, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 1, 100));
    assert_eq!(o.status & DEGRADED, 0);
    assert_eq!(c.envelope_steps()[0], 1);
    // Without the section: hold, margin 0, so 161 already counts.
    let mut c = Compensator::new(Some(model(None)));
    let o = step(&mut c, 0, 161, 80);
    assert_eq!((o.active[0], o.envelope, o.predicted[0]), (0, 1, 100));
    let o = step(&mut c, 1, 160, 80);
    assert_eq!(o.envelope, 0);
    assert_eq!(c.envelope_steps()[0], 1);
}

#[test]
fn the_section_round_trips_as_format_3_and_old_images_read_as_hold() {
    let mut m = model(Some(FALLBACK));
    let b = encode(&mut m);
    assert_eq!(u16::from_le_bytes([b[4], b[5]]), 3);
    let back = Model::parse(&b).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.envelope.unwrap()[0], FALLBACK);
    // Without the policy: version 2 (sections) as before, policy absent.
    let mut old = model(None);
    let b2 = encode(&mut old);
    assert_eq!(u16::from_le_bytes([b2[4], b2[5]]), SECTIONS_VERSION);
    // Section header 4 B, count 4 B, 4 B per direction.
    assert_eq!(b.len(), b2.len() + 4 + 4 + 4);
    assert_eq!(Model::parse(&b2).unwrap().envelope, None);
    // A stored v1 image (before sections) still reads, with no policy.
    let v1 = include_bytes!("../../fuzz/seeds/model_image/fl-thermal.img");
    assert_eq!(Model::parse(v1).unwrap().envelope, None);
}

/// The version check of format 2's parser (math-core/src/image/parse.rs
/// before format 3, commit e59a5fc), verbatim: what a board running that
/// firmware does first with a staged image.
fn previous_version_check(bytes: &[u8]) -> Result<(), ImageError> {
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != 1 && version != 2 {
        return Err(ImageError::UnsupportedVersion(version));
    }
    Ok(())
}

#[test]
fn a_format_3_image_is_refused_cleanly_by_the_previous_format() {
    let b = encode(&mut model(Some(FALLBACK)));
    let e = previous_version_check(&b).unwrap_err();
    assert_eq!(e, ImageError::UnsupportedVersion(3));
    let text = e.to_string();
    assert!(text.contains("version 3") && !text.contains('\n'), "{text}");
    // Relabelled as version 2, section kind 5 is unknown there, as it is
    // to the previous format's section list (kinds 1, 3, 4).
    let mut v2 = b.clone();
    v2[4..6].copy_from_slice(&2u16.to_le_bytes());
    assert_eq!(
        Model::parse(&reseal(v2)),
        Err(ImageError::UnknownSection {
            kind: SECTION_ENVELOPE
        })
    );
    // A later format is refused by this build's check the same way.
    let later = FORMAT_VERSION + 1;
    let mut next = b;
    next[4..6].copy_from_slice(&later.to_le_bytes());
    assert_eq!(
        Model::parse(&reseal(next)),
        Err(ImageError::UnsupportedVersion(later))
    );
}

#[test]
fn bad_envelope_sections_are_refused() {
    let good = encode(&mut model(Some(FALLBACK)));
    // The section is last: kind, 0, len u16, count, 3 × 0, one entry.
    let at = good.len() - 4 - 12;
    assert_eq!(good[at], SECTION_ENVELOPE);
    let bad = |offset: usize, value: u8| {
        let mut b = good.clone();
        b[at + offset] = value;
        Model::parse(&reseal(b))
    };
    assert!(
        matches!(bad(4, 2), Err(ImageError::BadValue { .. })),
        "count"
    );
    assert!(matches!(bad(5, 1), Err(ImageError::BadValue { .. })), "pad");
    assert!(
        matches!(bad(8, 2), Err(ImageError::BadValue { .. })),
        "policy"
    );
    assert!(matches!(bad(9, 1), Err(ImageError::BadValue { .. })), "pad");
    assert_eq!(
        bad(8, ENVELOPE_HOLD).unwrap().envelope.unwrap()[0].mode,
        EnvelopeMode::Hold
    );
}

//! The output low-pass per direction (issue 51 item 1, section kind 6,
//! format v5): a direction with a decay serves its prediction through a
//! causal first-order lag advanced in whole model steps (exact over gaps),
//! started at the prediction; a direction without one is served bit for bit
//! as before; written as format v5 only with the section, refused in an
//! older image and by a v4 build.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::float::*;
use thermocomp_core::image::*;
use thermocomp_core::{Compensator, StepInput, StepOutput};

/// τ of the filtered direction (s) and the model step (ms).
const TAU_S: f64 = 600.0;
const STEP_MS: u32 = 1000;

/// One sensor by channel, its rise over 0 … 160 (10 °C); direction Z =
/// 100 µm·x0 and X = −40 µm·x0 + 7 µm (x0 normalised to [−1, 1]).
fn float_model() -> FloatModel {
    let dir = |name: &str| FloatDirection {
        name: name.into(),
        max_correction_um: 500.0,
        max_rate_um_per_s: 1000.0,
    };
    let term = |coef_um, input| FloatTerm {
        coef_um,
        input,
        input_power: u8::from(input.is_some()),
        position_power: 0,
    };
    FloatModel {
        model_version: 3,
        step_ms: STEP_MS,
        warmup_s: 0,
        fixed_reference: true,
        sensors: vec![SensorRef {
            rom: [0; 8],
            channel: 0,
            ref_temp: 320,
        }],
        directions: vec![dir("Z"), dir("X")],
        axes: vec![],
        inputs: vec![FloatInput {
            kind: InputKind::SensorRise { a: 0 },
            tau_s: None,
            min: 0.0,
            max: 160.0,
        }],
        nets: vec![],
        tables: vec![
            FloatTable {
                direction: 0,
                axis: None,
                terms: vec![term(100.0, Some(0))],
            },
            FloatTable {
                direction: 1,
                axis: None,
                terms: vec![term(-40.0, Some(0)), term(7.0, None)],
            },
        ],
        fallbacks: vec![],
    }
}

/// exp(−step/τ) in Q30, as the export computes it.
fn decay_q30(tau_s: f64) -> u32 {
    ((-f64::from(STEP_MS) / 1000.0 / tau_s).exp() * f64::from(1u32 << 30)).round() as u32
}

/// The model with `decays` (per direction, Q30) or without the section.
fn model(decays: Option<[u32; 2]>) -> Model {
    let (mut m, _) = float_model().quantize().unwrap();
    m.output_decay_q30 = decays.map(|d| {
        let mut all = [0u32; 6];
        all[..2].copy_from_slice(&d);
        all
    });
    m
}

fn filtered() -> Model {
    model(Some([decay_q30(TAU_S), 0]))
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

fn version(b: &[u8]) -> u16 {
    u16::from_le_bytes([b[4], b[5]])
}

/// One step at `ms` with the sensor's rise `rise` (1/16 °C over the
/// stored reference; `None`: the sensor is invalid).
fn step(c: &mut Compensator, ms: u64, rise: Option<i32>) -> StepOutput {
    c.step(&StepInput {
        now_ms: ms,
        temps: &[rise.map(|r| 320 + r)],
        spindle_rpm: 0,
        positions: &[],
        stale: false,
    })
}

/// The unfiltered predictions at rise 0 and 160 (0.1 µm): the step's ends.
fn ends() -> (i32, i32) {
    let mut c = Compensator::new(Some(model(None)));
    let u0 = step(&mut c, 0, Some(0)).predicted[0];
    let u1 = step(&mut c, 1000, Some(160)).predicted[0];
    (u0, u1)
}

#[test]
fn a_step_rises_as_one_minus_exp_within_one_lsb() {
    let (u0, u1) = ends();
    assert_eq!((u0, u1), (-1000, 1000));
    let mut c = Compensator::new(Some(filtered()));
    // The first served step starts at the prediction, no ramp from 0.
    let o = step(&mut c, 0, Some(0));
    assert_eq!(o.predicted[0], u0);
    for s in 1..=3000u64 {
        let o = step(&mut c, s * 1000, Some(160));
        let want = f64::from(u1) + f64::from(u0 - u1) * (-(s as f64) / TAU_S).exp();
        assert!(
            (f64::from(o.predicted[0]) - want).abs() <= 1.0,
            "{s} s: {} vs {want:.2}",
            o.predicted[0]
        );
        // Served = the filtered value (the limits are far away here).
        assert_eq!(o.corrections[0], o.predicted[0], "{s} s");
    }
    // At t = τ the value is 1 − 1/e of the way: −1000 + 2000·0.632 = 264.
    let mut c = Compensator::new(Some(filtered()));
    step(&mut c, 0, Some(0));
    let mut at_tau = 0;
    for s in 1..=600u64 {
        at_tau = step(&mut c, s * 1000, Some(160)).predicted[0];
    }
    assert!((263..=265).contains(&at_tau), "{at_tau}");
}

#[test]
fn a_direction_without_a_decay_is_served_bit_for_bit_as_before() {
    let rises = |s: u64| Some(((s * 37) % 211) as i32 - 20);
    let mut plain = Compensator::new(Some(model(None)));
    let mut zero = Compensator::new(Some(model(Some([0, 0]))));
    let mut one = Compensator::new(Some(filtered()));
    let mut differs = false;
    for s in 0..500u64 {
        let ms = s * 1300 + s % 7;
        let r = if s % 50 == 49 { None } else { rises(s) };
        let (a, b, c) = (
            step(&mut plain, ms, r),
            step(&mut zero, ms, r),
            step(&mut one, ms, r),
        );
        assert_eq!(a, b, "{s}: decay 0 everywhere");
        // X (no decay) unchanged beside a filtered Z.
        assert_eq!(a.corrections[1], c.corrections[1], "{s}");
        assert_eq!(a.predicted[1], c.predicted[1], "{s}");
        assert_eq!(a.status, c.status, "{s}");
        differs |= a.predicted[0] != c.predicted[0];
    }
    assert!(differs, "the filtered direction must differ");
}

#[test]
fn a_gap_of_many_steps_is_exact() {
    let (u0, u1) = ends();
    let d = f64::from(decay_q30(TAU_S)) / f64::from(1u32 << 30);
    // Stepped every second …
    let mut stepped = Compensator::new(Some(filtered()));
    step(&mut stepped, 0, Some(0));
    let mut last = 0;
    for s in 1..=1000u64 {
        last = step(&mut stepped, s * 1000, Some(160)).predicted[0];
    }
    // … against one step over the whole gap, off the step grid (1000.7 s
    // is 1000 whole steps) …
    let mut jumped = Compensator::new(Some(filtered()));
    step(&mut jumped, 0, Some(0));
    let j = step(&mut jumped, 1_000_700, Some(160)).predicted[0];
    let want = f64::from(u1) + f64::from(u0 - u1) * d.powi(1000);
    assert!((f64::from(j) - want).abs() <= 0.5, "{j} vs {want:.3}");
    assert!((last - j).abs() <= 1, "{last} vs {j}");
    // … and against a sensor fault over the gap (the direction is not
    // served, its filter does not advance, then advances over the gap
    // with the first new prediction): the same bits as the jump.
    let mut faulted = Compensator::new(Some(filtered()));
    step(&mut faulted, 0, Some(0));
    for s in 1..1000u64 {
        let o = step(&mut faulted, s * 1000, None);
        assert_eq!(o.predicted[0], u0, "held while not served");
    }
    assert_eq!(step(&mut faulted, 1_000_700, Some(160)).predicted[0], j);
    // The clock stays on the step grid: 0.3 s later one more whole step.
    let next = step(&mut jumped, 1_001_000, Some(160)).predicted[0];
    let want = f64::from(u1) + f64::from(u0 - u1) * d.powi(1001);
    assert!((f64::from(next) - want).abs() <= 0.5, "{next} vs {want:.3}");
}

#[test]
fn a_new_reference_or_load_starts_the_filter_at_the_prediction() {
    let (u0, u1) = ends();
    let mut c = Compensator::new(Some(filtered()));
    step(&mut c, 0, Some(0));
    let o = step(&mut c, 1000, Some(160));
    assert!(o.predicted[0] < 0, "still near u0: {}", o.predicted[0]);
    c.rereference();
    // The stored reference is kept (FLAG_FIXED_REFERENCE): the rise is the same.
    assert_eq!(step(&mut c, 2000, Some(160)).predicted[0], u1);
    c.load(Some(filtered()));
    assert_eq!(step(&mut c, 3000, Some(0)).predicted[0], u0);
    c.preset_reference(&[Some(320)]);
    assert_eq!(step(&mut c, 4000, Some(160)).predicted[0], u1);
}

#[test]
fn version_5_only_with_the_section_and_the_round_trip() {
    let mut m = filtered();
    let b = encode(&mut m);
    assert_eq!(version(&b), 5);
    assert_eq!(version(&b), FORMAT_VERSION);
    assert_eq!(OUTPUT_FILTER_VERSION, 5);
    let back = Model::parse(&b).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.output_decay_q30.unwrap()[..2], [decay_q30(TAU_S), 0]);
    // Without the section: format 1 (no sections), 16 B shorter.
    let plain = encode(&mut model(None));
    assert_eq!(version(&plain), 1);
    assert_eq!(b.len(), plain.len() + 4 + 4 + 4 + 4 * 2);
    assert_eq!(Model::parse(&plain).unwrap().output_decay_q30, None);
    // With the envelope section too: still one section each, v5.
    let mut both = filtered();
    both.envelope = Some([EnvelopePolicy::default(); 6]);
    let bb = encode(&mut both);
    assert_eq!(version(&bb), 5);
    assert_eq!(Model::parse(&bb).unwrap(), both);
}

/// The version check of format 4's parser (math-core/src/image/parse.rs at
/// f4c8cd8, FORMAT_VERSION 4): what a board running that firmware does
/// first with a staged image.
fn v4_build_version_check(bytes: &[u8]) -> Result<(), ImageError> {
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version == 0 || version > 4 {
        return Err(ImageError::UnsupportedVersion(version));
    }
    Ok(())
}

#[test]
fn a_v4_build_refuses_it_and_an_older_image_may_not_carry_kind_6() {
    let b = encode(&mut filtered());
    assert_eq!(
        v4_build_version_check(&b),
        Err(ImageError::UnsupportedVersion(5))
    );
    for older in 2..=4u16 {
        let mut v = b.clone();
        v[4..6].copy_from_slice(&older.to_le_bytes());
        assert_eq!(
            Model::parse(&reseal(v)),
            Err(ImageError::UnknownSection {
                kind: SECTION_OUTPUT_FILTER
            }),
            "v{older}"
        );
    }
}

#[test]
fn bad_output_filter_sections_are_refused_in_one_line() {
    let good = encode(&mut filtered());
    // The section is last: kind, 0, len u16, count, 3 × 0, two decays.
    let at = good.len() - 4 - 16;
    assert_eq!(good[at], SECTION_OUTPUT_FILTER);
    let bad = |offset: usize, value: &[u8]| {
        let mut b = good.clone();
        b[at + offset..at + offset + value.len()].copy_from_slice(value);
        Model::parse(&reseal(b))
    };
    for (what, offset, value) in [
        ("count", 4, &[1u8][..]),
        ("padding", 5, &[1][..]),
        ("decay 2^30", 12, &(1u32 << 30).to_le_bytes()[..]),
        ("decay max", 8, &u32::MAX.to_le_bytes()[..]),
    ] {
        let e = bad(offset, value).unwrap_err();
        assert!(matches!(e, ImageError::BadValue { .. }), "{what}: {e:?}");
        let text = e.to_string();
        assert!(
            text.contains("output filter") && !text.contains('\n'),
            "{what}: {text}"
        );
    }
    // The largest decay below 2^30 is accepted (τ of ~10^9 steps).
    assert!(bad(8, &((1u32 << 30) - 1).to_le_bytes()).is_ok());
    // And the encoder refuses nothing itself: the parser is the check.
    let mut m = filtered();
    m.output_decay_q30.as_mut().unwrap()[1] = 1 << 30;
    let e = Model::parse(&encode(&mut m)).unwrap_err();
    assert!(e.to_string().contains("below 2^30"), "{e}");
}

#[test]
fn the_fuzz_seed_is_this_model() {
    let seed = include_bytes!("../../fuzz/seeds/model_image/output-filter.img");
    assert_eq!(&seed[..], &encode(&mut filtered())[..]);
    assert_eq!(
        Model::parse(seed).unwrap().output_decay_q30.unwrap()[0],
        decay_q30(TAU_S)
    );
}

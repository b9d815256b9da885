//! The envelope policy `extrapolate` (issue 50 item 3, section kind 5 code
//! 2, format v4): a linear direction continues up to two training widths
//! beyond each edge of its inputs' ranges and is held at that outer edge;
//! counted and flagged as under hold; only linear directions; written as
//! format v4 only with it, refused in a v3 image and by a v3 build.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::compensator::status::*;
use thermocomp_core::float::*;
use thermocomp_core::image::*;
use thermocomp_core::limits::EXTRAPOLATE_WIDTHS;
use thermocomp_core::{Compensator, StepInput, StepOutput};

/// Training range of both rises, raw units (1/16 °C): 0 … 160.
const WIDTH: i32 = 160;

/// Two sensors by channel, their rises over 0 … 160 (10 °C); direction Z
/// = 10 µm·x0 + 5 µm·x1 (x normalised to [−1, 1] over the range); one
/// fallback without sensor 0: 20 µm·x1 + 3 µm. Every model is linear.
fn float_model() -> FloatModel {
    let sensor = |channel| SensorRef {
        rom: [0; 8],
        channel,
        ref_temp: 320,
    };
    let rise = |a| FloatInput {
        kind: InputKind::SensorRise { a },
        tau_s: None,
        min: 0.0,
        max: f64::from(WIDTH),
    };
    FloatModel {
        model_version: 9,
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
            terms: vec![term(10.0, Some(0), 1), term(5.0, Some(1), 1)],
        }],
        fallbacks: vec![FloatFallback {
            direction: 0,
            excluded: vec![0],
            terms: vec![term(20.0, Some(1), 1), term(3.0, None, 0)],
        }],
    }
}

fn term(coef_um: f64, input: Option<u8>, input_power: u8) -> FloatTerm {
    FloatTerm {
        coef_um,
        input,
        input_power,
        position_power: 0,
    }
}

fn policy(mode: EnvelopeMode) -> EnvelopePolicy {
    EnvelopePolicy { mode, margin: 16 }
}

/// `fm` quantized with `p` on its one direction (`None`: no section; the
/// parser reads one entry per direction, the rest stay default).
fn model_of(fm: &FloatModel, p: Option<EnvelopePolicy>) -> Model {
    let (mut m, _) = fm.quantize().unwrap();
    m.envelope = p.map(|p| {
        let mut all = [EnvelopePolicy::default(); 6];
        all[0] = p;
        all
    });
    m
}

fn model(mode: EnvelopeMode) -> Model {
    model_of(&float_model(), Some(policy(mode)))
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

/// One step at `s` seconds with sensor rises `r0`, `r1` (1/16 °C over the
/// stored reference 320; `None`: that sensor invalid).
fn step(c: &mut Compensator, s: u64, r0: Option<i32>, r1: i32) -> StepOutput {
    c.step(&StepInput {
        now_ms: s * 1000,
        temps: &[r0.map(|r| 320 + r), Some(320 + r1)],
        spindle_rpm: 0,
        positions: &[],
        stale: false,
    })
}

/// Z's linear continuation (0.1 µm) at rises `r0`, `r1`: x = 2r/160 − 1
/// continued without any clamp.
fn linear(r0: i32, r1: i32) -> f64 {
    let x = |r: i32| 2.0 * f64::from(r) / f64::from(WIDTH) - 1.0;
    100.0 * x(r0) + 50.0 * x(r1)
}

#[test]
fn inside_the_range_extrapolate_serves_what_hold_serves_bit_for_bit() {
    let mut hold = Compensator::new(Some(model(EnvelopeMode::Hold)));
    let mut ext = Compensator::new(Some(model(EnvelopeMode::Extrapolate)));
    let mut s = 0;
    for r0 in (0..=WIDTH).step_by(7) {
        for r1 in [0, 1, 33, 80, 159, WIDTH] {
            let (a, b) = (
                step(&mut hold, s, Some(r0), r1),
                step(&mut ext, s, Some(r0), r1),
            );
            assert_eq!(a, b, "rises {r0}, {r1}");
            assert_eq!(b.status & OUT_OF_ENVELOPE, 0);
            s += 1;
        }
    }
    assert_eq!(ext.envelope_steps()[0], 0);
}

#[test]
fn half_a_width_below_the_line_continues_and_differs_from_hold() {
    let mut hold = Compensator::new(Some(model(EnvelopeMode::Hold)));
    let mut ext = Compensator::new(Some(model(EnvelopeMode::Extrapolate)));
    let (r0, r1) = (-WIDTH / 2, 80);
    let h = step(&mut hold, 1, Some(r0), r1);
    let e = step(&mut ext, 1, Some(r0), r1);
    // Linear: 10·(−2) + 5·0 = −20 µm; hold: 10·(−1) = −10 µm.
    assert!(
        (f64::from(e.predicted[0]) - linear(r0, r1)).abs() <= 1.0,
        "{e:?}"
    );
    assert_eq!(e.predicted[0], -200);
    assert_eq!(h.predicted[0], -100);
    // The served value reaches it in one second (rate 1000 µm/s, max 200 µm).
    assert_eq!(e.corrections[0], -200);
    // Above the range too, on both inputs at once.
    let e = step(&mut ext, 2, Some(WIDTH + 40), WIDTH + 120);
    assert!((f64::from(e.predicted[0]) - linear(WIDTH + 40, WIDTH + 120)).abs() <= 1.0);
    assert_eq!(e.predicted[0], 275);
}

#[test]
fn beyond_two_widths_it_is_held_at_the_outer_edge_and_counted() {
    let mut ext = Compensator::new(Some(model(EnvelopeMode::Extrapolate)));
    let edge = -EXTRAPOLATE_WIDTHS * WIDTH; // x0 = −5
    let at_edge = step(&mut ext, 0, Some(edge), 80);
    assert_eq!(at_edge.predicted[0], -500);
    assert!((f64::from(at_edge.predicted[0]) - linear(edge, 80)).abs() <= 1.0);
    for (s, r0) in [(1, edge - 1), (2, edge - WIDTH / 2), (3, -100_000)] {
        let o = step(&mut ext, s, Some(r0), 80);
        assert_eq!(o.predicted[0], -500, "rise {r0}");
    }
    // Above: x1 held at +5 (5·5 = 25 µm), x0 at 0.
    let o = step(&mut ext, 4, Some(80), WIDTH + 3 * WIDTH);
    assert_eq!(o.predicted[0], 250);
    // Every one of these steps beyond the margin is counted and flagged,
    // as under hold.
    assert_eq!(ext.envelope_steps()[0], 5);
    assert_ne!(o.status & OUT_OF_ENVELOPE, 0);
    assert_eq!(o.envelope, 1);
    assert_eq!(o.active[0], 0, "no switch to a fallback");
}

#[test]
fn within_the_margin_the_line_continues_flagged_but_not_counted() {
    let mut ext = Compensator::new(Some(model(EnvelopeMode::Extrapolate)));
    // 16 below: x0 = −1.2 → −12 µm; beyond the range, within the margin.
    let o = step(&mut ext, 0, Some(-16), 80);
    assert_eq!(o.predicted[0], -120);
    assert_ne!(o.status & OUT_OF_ENVELOPE, 0);
    assert_eq!(o.envelope, 0);
    assert_eq!(ext.envelope_steps()[0], 0);
    let o = step(&mut ext, 1, Some(-17), 80);
    assert_eq!((o.envelope, ext.envelope_steps()[0]), (1, 1));
    assert!((f64::from(o.predicted[0]) - linear(-17, 80)).abs() <= 1.0);
}

#[test]
fn the_fallback_in_force_extrapolates_too() {
    let mut ext = Compensator::new(Some(model(EnvelopeMode::Extrapolate)));
    let mut hold = Compensator::new(Some(model(EnvelopeMode::Hold)));
    // Sensor 0 invalid: the fallback 20·x1 + 3 serves; x1 = 2 at 240.
    let e = step(&mut ext, 0, None, WIDTH + WIDTH / 2);
    let h = step(&mut hold, 0, None, WIDTH + WIDTH / 2);
    assert_eq!((e.active[0], h.active[0]), (1, 1));
    assert_ne!(e.status & DEGRADED, 0);
    assert_eq!(e.predicted[0], 430);
    assert_eq!(h.predicted[0], 230);
    assert_eq!(ext.envelope_steps()[0], 1);
    // Inside, the fallback serves the same under both policies.
    let e = step(&mut ext, 1, None, 40);
    let h = step(&mut hold, 1, None, 40);
    assert_eq!(e.predicted, h.predicted);
}

#[test]
fn fixed_and_float_agree_beyond_the_envelope() {
    let fm = float_model();
    let m = model(EnvelopeMode::Extrapolate);
    let policies = m.envelope.unwrap();
    let mut c = Compensator::new(Some(m));
    let mut s = 0;
    for r0 in (-3 * WIDTH..=4 * WIDTH).step_by(13) {
        for r1 in [-500, -WIDTH, -3, 80, WIDTH + 1, 2 * WIDTH + 17, 900] {
            let o = step(&mut c, s, Some(r0), r1);
            let f =
                fm.evaluate_um_with_policy(&[f64::from(r0), f64::from(r1)], &[], Some(&policies));
            let fixed = f64::from(o.predicted[0]) / 10.0;
            assert!(
                (fixed - f[0]).abs() <= 0.1,
                "{r0}, {r1}: {fixed} vs {}",
                f[0]
            );
            s += 1;
        }
    }
    // Under hold the float mirror is evaluate_um, unchanged.
    let hold = [policy(EnvelopeMode::Hold); 6];
    assert_eq!(
        fm.evaluate_um_with_policy(&[-400.0, 900.0], &[], Some(&hold)),
        fm.evaluate_um(&[-400.0, 900.0], &[])
    );
}

#[test]
fn version_4_only_with_extrapolate_and_the_round_trip() {
    let mut m = model(EnvelopeMode::Extrapolate);
    let b = encode(&mut m);
    assert_eq!(version(&b), 4);
    assert_eq!(version(&b), EXTRAPOLATE_VERSION);
    let back = Model::parse(&b).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.envelope.unwrap()[0], policy(EnvelopeMode::Extrapolate));
    assert_eq!(back.extrapolate_mask(), 1);
    // Hold and fallback stay format 3, no section format 2, and the images
    // differ only in the version, the code and the CRC.
    let h = encode(&mut model(EnvelopeMode::Hold));
    let f = encode(&mut model(EnvelopeMode::Fallback));
    let none = encode(&mut model_of(&float_model(), None));
    assert_eq!((version(&h), version(&f), version(&none)), (3, 3, 2));
    let n = b.len();
    let differ: Vec<usize> = (0..n - 4).filter(|&i| b[i] != h[i]).collect();
    assert_eq!(differ, vec![4, n - 4 - 4]);
    assert_eq!(b[n - 8], ENVELOPE_EXTRAPOLATE);
}

/// The version check of format 3's parser (math-core/src/image/parse.rs
/// at 74a5143, FORMAT_VERSION 3): what a board running that firmware does
/// first with a staged image.
fn v3_build_version_check(bytes: &[u8]) -> Result<(), ImageError> {
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version == 0 || version > 3 {
        return Err(ImageError::UnsupportedVersion(version));
    }
    Ok(())
}

#[test]
fn a_v3_build_refuses_it_and_a_v3_image_may_not_carry_code_2() {
    let b = encode(&mut model(EnvelopeMode::Extrapolate));
    assert_eq!(
        v3_build_version_check(&b),
        Err(ImageError::UnsupportedVersion(4))
    );
    assert!(v3_build_version_check(&encode(&mut model(EnvelopeMode::Fallback))).is_ok());
    // Relabelled as version 3: code 2 is refused there, in one line.
    let mut v3 = b.clone();
    v3[4..6].copy_from_slice(&3u16.to_le_bytes());
    let e = Model::parse(&reseal(v3)).unwrap_err();
    assert!(matches!(e, ImageError::BadValue { .. }), "{e:?}");
    let text = e.to_string();
    assert!(
        text.contains("extrapolate") && !text.contains('\n'),
        "{text}"
    );
    // An unknown code is refused in a v4 image as before.
    let mut bad = b;
    let at = bad.len() - 8;
    bad[at] = 3;
    assert!(matches!(
        Model::parse(&reseal(bad)),
        Err(ImageError::BadValue {
            what: "envelope policy"
        })
    ));
}

/// `m` with `mode` on direction `d` only, encoded and parsed back.
fn parse_with(mut m: Model, d: usize, mode: EnvelopeMode) -> Result<Model, ImageError> {
    let mut all = [policy(EnvelopeMode::Hold); 6];
    all[d] = policy(mode);
    m.envelope = Some(all);
    Model::parse(&encode(&mut m))
}

#[test]
fn only_a_linear_direction_may_extrapolate() {
    // The demo model: Z (0) a network, X (1) a network and an axis table,
    // Y (2) a static table with x3² — none of them linear.
    let demo = demo_model(1).quantize().unwrap().0;
    for d in 0..3 {
        let e = parse_with(demo.clone(), d, EnvelopeMode::Extrapolate).unwrap_err();
        assert!(matches!(e, ImageError::BadValue { .. }), "{d}: {e:?}");
        let text = e.to_string();
        assert!(
            text.contains("not linear") && !text.contains('\n'),
            "{text}"
        );
        // The same direction may hold or fall back.
        assert!(parse_with(demo.clone(), d, EnvelopeMode::Fallback).is_ok());
    }
    // Y without its square term is linear and may extrapolate.
    let mut fm = demo_model(1);
    fm.tables[1].terms.retain(|t| t.input_power <= 1);
    let linear_y = fm.quantize().unwrap().0;
    assert!(parse_with(linear_y.clone(), 2, EnvelopeMode::Extrapolate).is_ok());
    // … unless one of its fallbacks is not.
    fm.fallbacks = vec![FloatFallback {
        direction: 2,
        excluded: vec![2],
        terms: vec![term(-3.0, Some(3), 2)],
    }];
    let bad_fallback = fm.quantize().unwrap().0;
    assert!(parse_with(bad_fallback.clone(), 2, EnvelopeMode::Hold).is_ok());
    assert!(matches!(
        parse_with(bad_fallback, 2, EnvelopeMode::Extrapolate),
        Err(ImageError::BadValue { .. })
    ));
}

#[test]
fn the_prediction_bound_counts_the_extended_span() {
    // 3 mm per unit of x0: within the ±10 mm bound over [−1, 1], but 15 mm
    // at x0 = ±5.
    let mut fm = float_model();
    fm.directions[0].max_correction_um = 10_000.0;
    fm.tables[0].terms = vec![term(3000.0, Some(0), 1)];
    fm.fallbacks.clear();
    let m = fm.quantize().unwrap().0;
    assert!(parse_with(m.clone(), 0, EnvelopeMode::Hold).is_ok());
    assert_eq!(
        parse_with(m, 0, EnvelopeMode::Extrapolate),
        Err(ImageError::PredictionBound { direction: 0 })
    );
    // 1.9 mm: 9.5 mm at the outer edge, accepted; served there.
    fm.tables[0].terms = vec![term(1900.0, Some(0), 1)];
    let m = parse_with(fm.quantize().unwrap().0, 0, EnvelopeMode::Extrapolate).unwrap();
    let mut c = Compensator::new(Some(m));
    let o = step(&mut c, 0, Some(-10 * WIDTH), 80);
    assert_eq!(o.predicted[0], -95_000);
}

#[test]
fn the_fuzz_seed_is_this_model() {
    let seed = include_bytes!("../../fuzz/seeds/model_image/extrapolate.img");
    assert_eq!(
        &seed[..],
        &encode(&mut model(EnvelopeMode::Extrapolate))[..]
    );
    assert_eq!(Model::parse(seed).unwrap().extrapolate_mask(), 1);
}

#[test]
fn the_extended_span_is_the_same_line_and_held_at_its_outer_edge() {
    use thermocomp_core::fixed::{Span, ONE_Q24};
    for (lo, hi) in [
        (0, 160 << 8),
        (-16 << 8, 480 << 8),
        (-7, 3),
        (-(1 << 30), 1 << 30),
    ] {
        let sp = Span::new(lo, hi).unwrap();
        let w = i64::from(hi) - i64::from(lo);
        let step = (w / 97).max(1);
        let mut v = i64::from(lo);
        while v <= i64::from(hi) {
            assert_eq!(sp.normalise_extended(v as i32), sp.normalise(v as i32).0);
            v += step;
        }
        // Outside: x = 2(v − lo)/w − 1 continued, within 2 LSB of Q24 at
        // five units, held beyond two widths.
        let q24 = f64::from(ONE_Q24);
        for k in [-2.0, -1.5, -0.25, 1.01, 2.0, 3.0] {
            let v = (i64::from(lo) as f64 + k * w as f64).round();
            let v = v.clamp(f64::from(i32::MIN), f64::from(i32::MAX));
            let want = (2.0 * (v - f64::from(lo)) / w as f64 - 1.0) * q24;
            let got = f64::from(sp.normalise_extended(v as i32));
            assert!(
                (got - want).abs() <= 3.0,
                "{lo}..{hi} at {k}: {got} vs {want}"
            );
        }
        let bound = (1 + 2 * EXTRAPOLATE_WIDTHS) * ONE_Q24;
        let far = i64::from(lo) - 3 * w;
        if far >= i64::from(i32::MIN) {
            assert_eq!(sp.normalise_extended(far as i32), -bound);
        }
        let far = i64::from(hi) + 3 * w;
        if far <= i64::from(i32::MAX) {
            assert_eq!(sp.normalise_extended(far as i32), bound);
        }
        assert!(sp.normalise_extended(i32::MIN) >= -bound);
        assert!(sp.normalise_extended(i32::MAX) <= bound);
    }
}

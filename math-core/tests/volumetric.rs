//! The volumetric section (image format v2, kind 3): round trip, images
//! without it unchanged, the integer evaluation against the f64 polynomial
//! of the same coefficients within the stated bound, the overflow bound at
//! the extremes (tests run with overflow checks), every refusal typed.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
// Per-direction loops index several parallel [x, y, z] arrays.
#![allow(clippy::needless_range_loop)]
use proptest::prelude::*;
use thermocomp_core::float::demo_model;
use thermocomp_core::image::*;
use thermocomp_core::volumetric::*;
use thermocomp_core::{Compensator, StepInput};

fn sensor(channel: u8, ref_temp: i32, min: i16, max: i16) -> VolSensor {
    VolSensor {
        sensor: SensorRef {
            rom: [0; 8],
            channel,
            ref_temp,
        },
        min,
        max,
    }
}

fn spec<'a>(sensors: &'a [VolSensor], terms: &'a [VolTerm]) -> VolumetricSpec<'a> {
    VolumetricSpec {
        slots: [0, 1, 2],
        origin_um: [0, 0, -400_000],
        stroke_um: [800_000, 500_000, 400_000],
        tool_max_um: 500_000,
        max_correction: [100_000; 3],
        sensors,
        terms,
    }
}

/// A small section: constant and per-kelvin terms of two sensors.
fn small() -> Volumetric {
    let sensors = [
        sensor(0, 20 * 16, -10 * 16, 60 * 16),
        sensor(3, 22 * 16, 0, 50 * 16),
    ];
    let terms = [
        VolTerm {
            exps: [0, 0, 0, 0],
            sensor: NONE,
            coef: [1_500_000, -2_000_000, 300_000],
        },
        VolTerm {
            exps: [1, 0, 0, 0],
            sensor: NONE,
            coef: [12_345_678, 0, -7_654_321],
        },
        VolTerm {
            exps: [1, 1, 0, 1],
            sensor: NONE,
            coef: [-3_000_000, 4_000_000, 5_000_000],
        },
        VolTerm {
            exps: [2, 0, 1, 0],
            sensor: 0,
            coef: [800_000, -600_000, 100_000],
        },
        VolTerm {
            exps: [0, 3, 0, 1],
            sensor: 1,
            coef: [-250_000, 90_000, 1_000_000],
        },
    ];
    Volumetric::new(&spec(&sensors, &terms)).unwrap()
}

fn with_section(v: Option<Volumetric>) -> (Model, Vec<u8>) {
    static DEMO: std::sync::OnceLock<Model> = std::sync::OnceLock::new();
    let mut m = DEMO
        .get_or_init(|| demo_model(7).quantize().unwrap().0)
        .clone();
    m.volumetric = v;
    let mut buf = vec![0u8; m.encoded_len()];
    let n = m.encode(&mut buf).unwrap();
    assert_eq!(n, buf.len());
    (m, buf)
}

/// The polynomial of the same integer coefficients in f64, 0.1 µm, before the clamp.
fn f64_eval(v: &Volumetric, pos: &[i32], tool: i32, temps: &[i32]) -> [f64; 3] {
    let mut x = [0.0f64; 4];
    for k in 0..3 {
        let p = f64::from(pos[usize::from(v.slots[k])]);
        x[k] = ((p - f64::from(v.origin_um[k])) / f64::from(v.stroke_um[k])).clamp(0.0, 1.0);
    }
    x[3] = (f64::from(tool) / f64::from(v.tool_max_um)).clamp(0.0, 1.0);
    let mut out = [0.0; 3];
    for t in &v.terms {
        let m: f64 = (0..4).map(|k| x[k].powi(i32::from(t.exps[k]))).product();
        let s = if t.sensor == NONE {
            1.0
        } else {
            let vs = &v.sensors[usize::from(t.sensor)];
            let c = temps[usize::from(t.sensor)].clamp(i32::from(vs.min), i32::from(vs.max));
            f64::from(c - vs.sensor.ref_temp) / 16.0
        };
        for d in 0..3 {
            out[d] += f64::from(t.coef[d]) * m * s / 1e5;
        }
    }
    out
}

fn rises(v: &Volumetric, temps: &[i32]) -> Vec<i32> {
    v.sensors
        .iter()
        .zip(temps)
        .map(|(s, &t)| t.clamp(i32::from(s.min), i32::from(s.max)) - s.sensor.ref_temp)
        .collect()
}

#[test]
fn a_section_round_trips_and_the_image_says_version_2() {
    let (m, buf) = with_section(Some(small()));
    assert_eq!(u16::from_le_bytes([buf[4], buf[5]]), 2);
    let back = Model::parse(&buf).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.volumetric, Some(small()));
    // 48 B + 2 sensors + 5 terms, 16 B each, plus the section header.
    assert_eq!(small().encoded_len(), 48 + 16 * 7);
}

#[test]
fn images_without_the_section_are_unchanged_and_serve_the_same() {
    let (plain, plain_bytes) = with_section(None);
    // Without the section the encoder still writes a v1 image, byte for byte
    // what the build before this section wrote (its CRC pins it).
    assert_eq!(u16::from_le_bytes([plain_bytes[4], plain_bytes[5]]), 1);
    let back = Model::parse(&plain_bytes).unwrap();
    assert_eq!(back.volumetric, None);
    assert_eq!(back, plain);
    // With the section, the main model serves exactly the same corrections.
    let (with, _) = with_section(Some(small()));
    let mut a = Compensator::new(Some(plain));
    let mut b = Compensator::new(Some(with));
    for i in 0..200u64 {
        let temps: Vec<Option<i32>> = (0..6)
            .map(|c| Some(320 + (i as i32) * (c + 1) / 4))
            .collect();
        let input = StepInput {
            now_ms: i * 15_000,
            temps: &temps,
            spindle_rpm: if i < 50 { 0 } else { 6000 },
            positions: &[100_000, -20_000, 0, 0, 0, 0],
            stale: false,
        };
        assert_eq!(a.step(&input), b.step(&input), "step {i}");
    }
}

#[test]
fn fallbacks_and_the_section_live_side_by_side() {
    let (mut m, _) = demo_model(7).quantize().unwrap();
    m.push_fallback(
        0,
        [1, NONE],
        &[Term {
            coef: 77,
            input: NONE,
            input_power: 0,
            position_power: 0,
        }],
    )
    .unwrap();
    m.volumetric = Some(small());
    let mut buf = vec![0u8; m.encoded_len()];
    m.encode(&mut buf).unwrap();
    let back = Model::parse(&buf).unwrap();
    assert_eq!(back.fallbacks.len(), 1);
    assert_eq!(back.volumetric, Some(small()));
}

#[test]
fn the_evaluation_matches_the_f64_polynomial_within_its_bound() {
    let v = small();
    let mut worst = 0.0f64;
    for &x in &[0, 200_000, 799_999, 800_000] {
        for &y in &[0, 123_456, 500_000] {
            for &z in &[-400_000, -1, -250_000] {
                for &tool in &[0, 80_000, 500_000] {
                    for &(t0, t1) in &[(320, 352), (500, 600), (-160, 0), (960, 800)] {
                        let pos = [x, y, z, 0, 0, 0];
                        let out = v.evaluate(&pos, tool, &[Some(t0), Some(t1)]);
                        assert_eq!(out.status & vstatus::VALID, vstatus::VALID);
                        let want = f64_eval(&v, &pos, tool, &[t0, t1]);
                        let bound = v.error_bound_tenth_um(&rises(&v, &[t0, t1]));
                        assert!(bound < 0.51, "the bound is tight for this section: {bound}");
                        for d in 0..3 {
                            let err = (f64::from(out.corrections[d]) - want[d]).abs();
                            worst = worst.max(err);
                            assert!(
                                err <= bound,
                                "{pos:?} {tool} {t0},{t1} dir {d}: {err} > {bound}"
                            );
                            // Before the final rounding: within the bound's non-rounding part.
                            let pre = out.acc[d] as f64 / 1_600_000.0;
                            assert!((pre - want[d]).abs() <= bound - 0.5 + 1e-9);
                        }
                    }
                }
            }
        }
    }
    assert!(worst > 0.0 && worst <= 0.5, "{worst}");
    // And it is not trivially zero somewhere.
    let out = v.evaluate(
        &[800_000, 500_000, 0, 0, 0, 0],
        500_000,
        &[Some(960), Some(800)],
    );
    assert!(out.corrections.iter().all(|&c| c.abs() > 10), "{out:?}");
}

#[test]
fn clamps_and_faults_are_flagged_never_silent() {
    let v = small();
    // A sensor without a value: not valid, nothing computed.
    let out = v.evaluate(&[0; 6], 0, &[Some(320), None]);
    assert_eq!(out.status, vstatus::SENSOR_FAULT);
    assert_eq!(out.status & vstatus::VALID, 0);
    // Positions, tool and temperatures beyond their ranges are held at the edge.
    let edge = v.evaluate(
        &[800_000, 500_000, 0, 0, 0, 0],
        500_000,
        &[Some(960), Some(800)],
    );
    let beyond = v.evaluate(
        &[900_000, 600_000, 5, 0, 0, 0],
        700_000,
        &[Some(1200), Some(900)],
    );
    assert_eq!(edge.corrections, beyond.corrections);
    assert_eq!(edge.status, vstatus::VALID);
    assert_eq!(
        beyond.status,
        vstatus::VALID
            | vstatus::POSITION_CLAMPED
            | vstatus::TOOL_CLAMPED
            | vstatus::TEMPERATURE_CLAMPED
    );
    assert_eq!(beyond.tool_um, 500_000);
    // The max correction clamps and says so.
    let sensors = [sensor(0, 320, 0, 1000)];
    let terms = [VolTerm {
        exps: [0; 4],
        sensor: NONE,
        coef: [2_000_000_000, -2_000_000_000, 1],
    }];
    let mut s = spec(&sensors, &terms);
    s.max_correction = [100, 200, 300];
    let c = Volumetric::new(&s)
        .unwrap()
        .evaluate(&[0; 6], 0, &[Some(0)]);
    assert_eq!(c.corrections, [100, -200, 0]);
    assert_eq!(c.status, vstatus::VALID | vstatus::CLAMPED);
}

#[test]
fn the_extreme_section_cannot_overflow() {
    // 256 terms of the highest degree, every coefficient at the i32 edge,
    // every variable and temperature at its edge: with overflow checks on
    // (test profile) any overflow in the evaluation panics.
    let sensors = [
        sensor(0, TEMP_MIN_16, TEMP_MIN_16 as i16, TEMP_MAX_16 as i16),
        sensor(1, TEMP_MAX_16, TEMP_MIN_16 as i16, TEMP_MAX_16 as i16),
        sensor(2, TEMP_MIN_16, TEMP_MIN_16 as i16, TEMP_MAX_16 as i16),
        sensor(3, TEMP_MAX_16, TEMP_MIN_16 as i16, TEMP_MAX_16 as i16),
    ];
    for coef in [i32::MAX, i32::MIN] {
        for (sens, temps) in [
            (0u8, [TEMP_MAX_16, TEMP_MIN_16, TEMP_MAX_16, TEMP_MIN_16]),
            (1u8, [TEMP_MAX_16, TEMP_MIN_16, TEMP_MAX_16, TEMP_MIN_16]),
            (NONE, [0; 4]),
        ] {
            let terms: Vec<VolTerm> = (0..MAX_VOL_TERMS)
                .map(|i| VolTerm {
                    exps: if i % 2 == 0 { [3; 4] } else { [0; 4] },
                    sensor: sens,
                    coef: [coef; 3],
                })
                .collect();
            let v = Volumetric::new(&spec(&sensors, &terms)).unwrap();
            let t: Vec<Option<i32>> = temps.iter().map(|&t| Some(t)).collect();
            for pos in [[i32::MAX; 6], [i32::MIN; 6], [800_000, 500_000, 0, 0, 0, 0]] {
                for tool in [i32::MAX, i32::MIN, 500_000] {
                    let out = v.evaluate(&pos, tool, &t);
                    let want = f64_eval(&v, &pos, tool, &temps);
                    for d in 0..3 {
                        let pre = out.acc[d] as f64 / 1_600_000.0;
                        let rel = (pre - want[d]).abs() / want[d].abs().max(1.0);
                        assert!(rel < 1e-6, "{pre} vs {}", want[d]);
                        assert!(out.acc[d].unsigned_abs() < 1 << 52, "the stated bound");
                    }
                }
            }
        }
    }
}

#[test]
fn every_refusal_is_typed_and_one_line() {
    let sensors = [sensor(0, 320, 0, 1000)];
    let terms = [VolTerm {
        exps: [1, 0, 0, 0],
        sensor: 0,
        coef: [1, 2, 3],
    }];
    let ok = spec(&sensors, &terms);
    assert!(Volumetric::new(&ok).is_ok());
    let mut cases: Vec<(VolumetricSpec, ImageError)> = Vec::new();
    let mut s = ok;
    s.slots = [0, 6, 2];
    cases.push((s, ImageError::VolumetricAxisSlot { axis: 1, slot: 6 }));
    let mut s = ok;
    s.stroke_um = [800_000, 1, 400_000];
    cases.push((s, ImageError::VolumetricStroke { axis: 1, value: 1 }));
    let mut s = ok;
    s.origin_um = [i32::MAX - 10, 0, 0];
    cases.push((
        s,
        ImageError::VolumetricStroke {
            axis: 0,
            value: 800_000,
        },
    ));
    let mut s = ok;
    s.tool_max_um = 0;
    cases.push((s, ImageError::VolumetricTool { value: 0 }));
    let mut s = ok;
    s.max_correction = [1, 0, 1];
    cases.push((
        s,
        ImageError::VolumetricMaxCorrection {
            direction: 1,
            value: 0,
        },
    ));
    let hot = [sensor(0, 126 * 16, 0, 1000)];
    cases.push((
        spec(&hot, &terms),
        ImageError::VolumetricTemperature { sensor: 0 },
    ));
    let flat = [sensor(0, 320, 500, 500)];
    cases.push((
        spec(&flat, &terms),
        ImageError::VolumetricTemperature { sensor: 0 },
    ));
    let far = [sensor(20, 320, 0, 1000)];
    cases.push((
        spec(&far, &terms),
        ImageError::SensorChannelOutOfRange {
            sensor: 0,
            channel: 20,
        },
    ));
    let bad_term = [VolTerm {
        exps: [0; 4],
        sensor: 1,
        coef: [0; 3],
    }];
    cases.push((
        spec(&sensors, &bad_term),
        ImageError::BadIndex {
            what: "volumetric term sensor",
            index: 1,
        },
    ));
    cases.push((
        spec(&sensors, &[]),
        ImageError::TooMany {
            what: "volumetric terms",
            count: 0,
            max: MAX_VOL_TERMS,
        },
    ));
    for (s, want) in cases {
        let e = Volumetric::new(&s).unwrap_err();
        assert_eq!(e, want);
        let text = e.to_string();
        assert!(
            !text.is_empty() && !text.contains('\n') && !text.contains('{'),
            "{text}"
        );
    }
}

/// Byte offset of the volumetric payload in an image whose only section it is.
fn payload_at(buf: &[u8], v: &Volumetric) -> usize {
    buf.len() - 4 - v.encoded_len()
}

fn reseal(mut b: Vec<u8>) -> Vec<u8> {
    let len = b.len() as u32;
    b[8..12].copy_from_slice(&len.to_le_bytes());
    let n = b.len();
    let crc = crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn the_parser_refuses_a_bad_section_by_name() {
    let v = small();
    let (_, good) = with_section(Some(v.clone()));
    let at = payload_at(&good, &v);
    assert_eq!(good[at - 4], SECTION_VOLUMETRIC);
    let edit = |off: usize, bytes: &[u8]| {
        let mut b = good.clone();
        b[at + off..at + off + bytes.len()].copy_from_slice(bytes);
        Model::parse(&reseal(b))
    };
    // Stroke of y (offset 12 + 12 + 4) zero.
    assert_eq!(
        edit(28, &0i32.to_le_bytes()),
        Err(ImageError::VolumetricStroke { axis: 1, value: 0 })
    );
    // Slot of z beyond the PLC's axes.
    assert_eq!(
        edit(6, &[9]),
        Err(ImageError::VolumetricAxisSlot { axis: 2, slot: 9 })
    );
    // Padding must be zero.
    assert_eq!(
        edit(1, &[1]),
        Err(ImageError::BadValue {
            what: "volumetric section padding"
        })
    );
    // Too many sensors.
    assert!(matches!(
        edit(0, &[5]),
        Err(ImageError::TooMany {
            what: "volumetric sensors",
            ..
        })
    ));
    // A term's sensor beyond the section's (first term at 48 + 2·16).
    assert_eq!(
        edit(48 + 32 + 1, &[2]),
        Err(ImageError::BadIndex {
            what: "volumetric term sensor",
            index: 2
        })
    );
    // A sensor's envelope inverted (sensor 0's min at 48 + 12).
    assert_eq!(
        edit(48 + 12, &2000i16.to_le_bytes()),
        Err(ImageError::VolumetricTemperature { sensor: 0 })
    );
    // One term more than the payload holds: the section's length is wrong.
    assert_eq!(
        edit(2, &6u16.to_le_bytes()),
        Err(ImageError::SectionLength {
            kind: SECTION_VOLUMETRIC
        })
    );
    // The section twice.
    let mut twice = good[..good.len() - 4].to_vec();
    let section = good[at - 4..good.len() - 4].to_vec();
    twice.extend_from_slice(&section);
    twice.extend_from_slice(&[0; 4]);
    let n_at = at - 8; // n_sections byte before the (only) section header
    twice[n_at] = 2;
    assert_eq!(
        Model::parse(&reseal(twice)),
        Err(ImageError::DuplicateSection {
            kind: SECTION_VOLUMETRIC
        })
    );
}

fn arb_section() -> impl Strategy<Value = Volumetric> {
    let term = (
        prop::array::uniform4(0u8..=3),
        prop_oneof![Just(NONE), 0u8..2],
        prop::array::uniform3(-50_000_000i32..50_000_000),
    )
        .prop_map(|(exps, sensor, coef)| VolTerm { exps, sensor, coef });
    (
        prop::collection::vec(term, 1..60),
        prop::array::uniform3(2i32..2_000_000),
        prop::array::uniform3(-1_000_000i32..1_000_000),
        2i32..1_000_000,
        -880i32..2000,
    )
        .prop_map(|(terms, stroke_um, origin_um, tool_max_um, r)| {
            let sensors = [
                sensor(1, r, -880, 2000),
                sensor(4, 2000 - (r + 880) / 2, -800, 1900),
            ];
            Volumetric::new(&VolumetricSpec {
                slots: [2, 0, 5],
                origin_um,
                stroke_um,
                tool_max_um,
                max_correction: [100_000; 3],
                sensors: &sensors,
                terms: &terms,
            })
            .unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn random_sections_stay_within_the_bound_and_round_trip(
        v in arb_section(),
        pos in prop::array::uniform6(-3_000_000i32..3_000_000),
        tool in -100_000i32..1_200_000,
        temps in prop::array::uniform2(-1000i32..2100),
    ) {
        let out = v.evaluate(&pos, tool, &[Some(temps[0]), Some(temps[1])]);
        prop_assert!(out.status & vstatus::VALID != 0);
        let want = f64_eval(&v, &pos, tool, &temps);
        let bound = v.error_bound_tenth_um(&rises(&v, &temps));
        for d in 0..3 {
            let pre = out.acc[d] as f64 / 1_600_000.0;
            prop_assert!((pre - want[d]).abs() <= bound - 0.5 + 1e-9, "{} vs {} bound {}", pre, want[d], bound);
            if out.status & vstatus::CLAMPED == 0 {
                prop_assert!((f64::from(out.corrections[d]) - want[d]).abs() <= bound);
            }
        }
        let (m, buf) = with_section(Some(v.clone()));
        let back = Model::parse(&buf).unwrap();
        prop_assert_eq!(&back, &m);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    /// Any byte of an image with the section changed (and the image resealed,
    /// so the edit itself is what the parser sees): never a panic, and what
    /// parses evaluates at every extreme without overflow (checks on).
    #[test]
    fn mutated_sections_never_panic_and_what_parses_evaluates(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        pos in prop::array::uniform6(any::<i32>()),
        tool in any::<i32>(),
        temps in prop::array::uniform4(any::<i32>()),
    ) {
        let v = small();
        let (_, good) = with_section(Some(v.clone()));
        let at = payload_at(&good, &v);
        let mut b = good.clone();
        for (i, x) in edits {
            // Inside the section's payload (most edits) or its header.
            let k = at - 4 + i.index(good.len() - 4 - (at - 4));
            b[k] = x;
        }
        if let Ok(m) = Model::parse(&reseal(b)) {
            if let Some(s) = &m.volumetric {
                let t: Vec<Option<i32>> = temps.iter().map(|&t| Some(t)).collect();
                let out = s.evaluate(&pos, tool, &t);
                prop_assert!(out.status & vstatus::VALID != 0);
                for d in 0..3 {
                    prop_assert!(out.corrections[d].abs() <= s.max_correction[d]);
                    prop_assert!(out.acc[d].unsigned_abs() < 1 << 52);
                }
            }
        }
    }
}

//! Model image: round trip, every typed refusal, and fuzzed bytes never panic.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use proptest::prelude::*;
use thermocomp_core::float::demo_model;
use thermocomp_core::image::*;
use thermocomp_core::limits::*;

fn demo_image() -> (Model, Vec<u8>) {
    static IMAGE: std::sync::OnceLock<(Model, Vec<u8>)> = std::sync::OnceLock::new();
    IMAGE
        .get_or_init(|| {
            let (mut m, _) = demo_model(7).quantize().unwrap();
            let mut buf = vec![0u8; m.encoded_len()];
            let n = m.encode(&mut buf).unwrap();
            assert_eq!(n, buf.len());
            (m, buf)
        })
        .clone()
}

/// Re-seal an edited image: fix total_len and the CRC so the edit itself is tested.
fn reseal(mut b: Vec<u8>) -> Vec<u8> {
    let len = b.len() as u32;
    b[8..12].copy_from_slice(&len.to_le_bytes());
    let n = b.len();
    let crc = crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn encode_parse_round_trip_is_identical() {
    let (m, buf) = demo_image();
    let back = Model::parse(&buf).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.crc, crc32(&buf[..buf.len() - 4]));
}

#[test]
fn bytes_after_the_sealed_image_are_refused() {
    let (_, good) = demo_image();
    for tail in [&[0u8][..], &[0xFF; 100][..]] {
        let mut b = good.clone();
        b.extend_from_slice(tail);
        assert_eq!(
            Model::parse(&b),
            Err(ImageError::TrailingBytes {
                image_len: good.len(),
                got: good.len() + tail.len()
            })
        );
    }
}

#[test]
fn every_defect_is_a_typed_error() {
    let (_, good) = demo_image();
    assert!(matches!(
        Model::parse(&good[..10]),
        Err(ImageError::TooShort { .. })
    ));
    assert!(matches!(
        Model::parse(&good[..good.len() - 1]),
        Err(ImageError::TooShort { .. })
    ));
    let mut b = good.clone();
    b[0] = b'X';
    assert_eq!(Model::parse(&b), Err(ImageError::BadMagic));
    let mut b = good.clone();
    b[4] = 9;
    assert_eq!(Model::parse(&b), Err(ImageError::UnsupportedVersion(9)));
    let mut b = good.clone();
    b[40] ^= 1;
    assert!(matches!(Model::parse(&b), Err(ImageError::BadCrc { .. })));
    let mut b = good.clone();
    b[8..12].copy_from_slice(&100_000u32.to_le_bytes());
    assert!(matches!(Model::parse(&b), Err(ImageError::TooLong { .. })));
    // Too many sensors.
    let mut b = good.clone();
    b[24] = (MAX_SENSORS + 1) as u8;
    assert!(matches!(
        Model::parse(&reseal(b)),
        Err(ImageError::TooMany {
            what: "sensors",
            ..
        })
    ));
    // Units.
    let mut b = good.clone();
    b[30] = 2;
    assert_eq!(
        Model::parse(&reseal(b)),
        Err(ImageError::UnsupportedUnits(2))
    );
    // Trailing garbage before the CRC.
    let mut b = good.clone();
    b.insert(good.len() - 4, 0);
    assert_eq!(Model::parse(&reseal(b)), Err(ImageError::LengthMismatch));
    // Cut one section short.
    let mut b = good.clone();
    b.remove(good.len() - 5);
    assert_eq!(Model::parse(&reseal(b)), Err(ImageError::LengthMismatch));
}

#[test]
fn semantic_errors_are_refused() {
    let (m, _) = demo_image();
    let enc = |mut m: Model| {
        let mut b = vec![0u8; m.encoded_len()];
        m.encode(&mut b).unwrap();
        Model::parse(&b)
    };
    let mut bad = m.clone();
    bad.inputs[1].max = bad.inputs[1].min; // non-monotone envelope
    assert_eq!(
        enc(bad),
        Err(ImageError::NonMonotoneRange {
            what: "input",
            index: 1
        })
    );
    let mut bad = m.clone();
    bad.axes[0].pos_max = bad.axes[0].pos_min - 5;
    assert_eq!(
        enc(bad),
        Err(ImageError::NonMonotoneRange {
            what: "axis",
            index: 0
        })
    );
    let mut bad = m.clone();
    bad.nets[0].inputs[0] = 11;
    assert_eq!(
        enc(bad),
        Err(ImageError::BadIndex {
            what: "net input",
            index: 11
        })
    );
    let mut bad = m.clone();
    bad.nets[0].direction = 5;
    assert_eq!(
        enc(bad),
        Err(ImageError::BadIndex {
            what: "net direction",
            index: 5
        })
    );
    let mut bad = m.clone();
    bad.tables[0].terms[0].position_power = 4;
    assert_eq!(enc(bad), Err(ImageError::BadValue { what: "term power" }));
    let mut bad = m.clone();
    bad.step_ms = 0;
    assert_eq!(enc(bad), Err(ImageError::BadValue { what: "step_ms" }));
    let mut bad = m.clone();
    bad.directions[0].max_rate = -1;
    assert_eq!(
        enc(bad),
        Err(ImageError::MaxRateOutOfRange {
            direction: 0,
            value: -1
        })
    );
    let mut bad = m.clone();
    bad.inputs[0].kind = InputKind::SensorRise { a: 9 };
    assert_eq!(
        enc(bad),
        Err(ImageError::BadIndex {
            what: "sensor",
            index: 9
        })
    );
}

fn encoded(mut m: Model) -> Result<Model, ImageError> {
    let mut b = vec![0u8; m.encoded_len()];
    m.encode(&mut b).unwrap();
    Model::parse(&b)
}

#[test]
fn a_sensor_channel_beyond_the_board_is_refused() {
    let (m, _) = demo_image();
    for channel in [MAX_SENSORS as u8, 99, 255] {
        let mut bad = m.clone();
        bad.sensors[2].channel = channel;
        assert_eq!(
            encoded(bad),
            Err(ImageError::SensorChannelOutOfRange { sensor: 2, channel })
        );
    }
    let mut last = m.clone();
    last.sensors[2].channel = MAX_SENSORS as u8 - 1;
    assert!(encoded(last).is_ok(), "the last channel is fine");
}

/// A DS18B20 ROM code with a valid CRC-8 (family 0x28, serial `n`).
fn rom(n: u8) -> [u8; 8] {
    let mut r = [0x28, n, 0x4C, 0x1A, 0x02, 0x16, 0x03, 0];
    r[7] = thermocomp_core::image::rom_crc8(&r[..7]);
    r
}

#[test]
fn sensors_named_by_rom_code_round_trip_and_bad_or_twice_named_codes_are_refused() {
    let (m, _) = demo_image();
    // The datasheet's own example check: CRC-8/MAXIM of "123456789" is 0xA1.
    assert_eq!(thermocomp_core::image::rom_crc8(b"123456789"), 0xA1);
    let mut named = m.clone();
    for (i, s) in named.sensors.iter_mut().enumerate() {
        s.rom = rom(i as u8 + 1);
    }
    let back = encoded(named.clone()).unwrap();
    assert_eq!(back.sensors, named.sensors, "ROM codes and channels kept");
    // Some by ROM, some by channel: fine.
    let mut mixed = m.clone();
    mixed.sensors[0].rom = rom(9);
    assert!(encoded(mixed).is_ok());
    let mut bad = named.clone();
    bad.sensors[3].rom[7] ^= 1;
    assert_eq!(encoded(bad), Err(ImageError::BadSensorRom { sensor: 3 }));
    let mut twice = named.clone();
    twice.sensors[4].rom = twice.sensors[1].rom;
    assert_eq!(
        encoded(twice),
        Err(ImageError::DuplicateSensorRom {
            sensor: 4,
            first: 1
        })
    );
    assert_eq!(
        ImageError::DuplicateSensorRom {
            sensor: 4,
            first: 1
        }
        .to_string(),
        "sensor 4 has the same ROM code as sensor 1"
    );
    assert_eq!(
        ImageError::BadSensorRom { sensor: 3 }.to_string(),
        "sensor 3: ROM code fails its CRC-8 (not a 1-Wire ROM code)"
    );
}

#[test]
fn model_version_0_is_refused() {
    let (m, _) = demo_image();
    let mut bad = m.clone();
    bad.model_version = 0;
    assert_eq!(encoded(bad), Err(ImageError::ZeroModelVersion));
}

#[test]
fn direction_limits_outside_their_bounds_are_refused() {
    let (m, _) = demo_image();
    for value in [0, -1, thermocomp_core::compensator::MAX_RATE + 1] {
        let mut bad = m.clone();
        bad.directions[1].max_rate = value;
        assert_eq!(
            encoded(bad),
            Err(ImageError::MaxRateOutOfRange {
                direction: 1,
                value
            }),
            "max_rate {value}"
        );
    }
    for value in [0, -5, MAX_CORRECTION + 1, i32::MAX] {
        let mut bad = m.clone();
        bad.directions[2].max_correction = value;
        assert_eq!(
            encoded(bad),
            Err(ImageError::MaxCorrectionOutOfRange {
                direction: 2,
                value
            }),
            "max_correction {value}"
        );
    }
    let mut edge = m.clone();
    edge.directions[0].max_rate = thermocomp_core::compensator::MAX_RATE;
    edge.directions[0].max_correction = MAX_CORRECTION;
    edge.directions[1].max_rate = 1;
    edge.directions[1].max_correction = 1;
    assert!(encoded(edge).is_ok(), "the bounds themselves are accepted");
}

/// A model whose position-dependent tables on axis 0 all have `n_terms`
/// terms of coefficient `coef` at position power 3 (the largest d/dp weight).
fn heavy_tables(n_tables: usize, n_terms: usize, coef: i32) -> Model {
    let (m, _) = demo_image();
    let mut heavy = m.clone();
    heavy.tables.clear();
    for _ in 0..n_tables {
        let mut terms = heapless::Vec::new();
        for _ in 0..n_terms {
            terms
                .push(Term {
                    coef,
                    input: NONE,
                    input_power: 0,
                    position_power: 3,
                })
                .unwrap();
        }
        heavy
            .tables
            .push(Table {
                direction: 1,
                axis: 0,
                terms,
            })
            .unwrap();
    }
    heavy
}

fn evaluate_at_extremes(m: &Model) {
    for v in [i32::MIN, -1, 0, 1 << 28, i32::MAX] {
        for p in [i32::MIN, 0, i32::MAX] {
            let e = m.evaluate(&[v; MAX_INPUTS], &[p; MAX_AXES]);
            std::hint::black_box(e);
        }
    }
}

#[test]
fn tables_whose_sums_could_overflow_the_accumulator_are_refused() {
    // Eight full tables of i32::MAX coefficients: d/dp alone sums to
    // 8 * 32 * 3 * 2^31 * 2^24 > 2^63 in eval.rs's axis pair.
    let bad = heavy_tables(MAX_TABLES, MAX_TERMS, i32::MAX);
    assert_eq!(encoded(bad), Err(ImageError::TableSumTooLarge { axis: 0 }));
    assert_eq!(
        encoded(heavy_tables(MAX_TABLES, MAX_TERMS, i32::MIN)),
        Err(ImageError::TableSumTooLarge { axis: 0 })
    );
    // At the bound the sums pass (what is refused now is the prediction
    // such tables can make over the envelope, issue 30's semantic limit),
    // and the evaluation cannot overflow (this test runs with overflow
    // checks on).
    let per_term = MAX_AXIS_TABLE_WEIGHT / (3 * (MAX_TABLES * MAX_TERMS) as u64);
    let at_bound = heavy_tables(MAX_TABLES, MAX_TERMS, -(per_term as i32));
    assert!(
        matches!(
            encoded(at_bound.clone()),
            Err(ImageError::PredictionBound { .. })
        ),
        "at the sum bound only the prediction bound refuses"
    );
    evaluate_at_extremes(&at_bound);
    let over = heavy_tables(MAX_TABLES, MAX_TERMS, -(per_term as i32) - 1);
    assert_eq!(encoded(over), Err(ImageError::TableSumTooLarge { axis: 0 }));
}

#[test]
fn every_refusal_has_a_one_line_message() {
    let (_, good) = demo_image();
    let mut b = good.clone();
    b.push(0);
    let errors = [
        Model::parse(&b).unwrap_err(),
        Model::parse(&good[..10]).unwrap_err(),
        ImageError::SensorChannelOutOfRange {
            sensor: 1,
            channel: 99,
        },
        ImageError::BadCrc {
            stored: 2_777_176_152,
            computed: 1,
        },
        ImageError::TableSumTooLarge { axis: 0 },
        ImageError::ZeroModelVersion,
    ];
    for e in errors {
        let text = e.to_string();
        assert!(!text.is_empty() && !text.contains('\n'), "{text:?}");
        assert!(!text.contains('{'), "no Debug form: {text}");
    }
    assert_eq!(
        ImageError::SensorChannelOutOfRange {
            sensor: 1,
            channel: 99
        }
        .to_string(),
        "sensor 1 names bus channel 99; the board has channels 0-19"
    );
    assert_eq!(
        ImageError::BadCrc {
            stored: 0xA5A5_0000,
            computed: 0x1234_5678
        }
        .to_string(),
        "CRC-32 mismatch: stored 0xa5a50000, computed 0x12345678 (image corrupted)"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]
    #[test]
    fn random_bytes_never_panic(b in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = Model::parse(&b);
    }

    #[test]
    fn mutated_images_never_panic_and_resealed_ones_evaluate(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        seal in any::<bool>(),
    ) {
        let (_, good) = demo_image();
        let mut b = good.clone();
        for (i, v) in &edits {
            let at = i.index(b.len());
            b[at] = *v;
        }
        if seal && b.len() > 12 { b = reseal(b); }
        let parsed = Model::parse(&b);
        if !seal {
            // Without a re-seal, any change is refused (CRC-32, or the length
            // fields it covers) and an unchanged image is accepted.
            prop_assert_eq!(parsed.is_ok(), b == good, "{:?}", parsed);
        }
        if let Ok(m) = parsed {
            // Whatever parses is a model the encoder reproduces (same length,
            // same content; only padding bytes and so the CRC may differ) ...
            let mut again = m.clone();
            let mut buf = vec![0u8; again.encoded_len()];
            prop_assert_eq!(again.encode(&mut buf), Ok(b.len()));
            let mut back = Model::parse(&buf).expect("a re-encoded model parses");
            back.crc = m.crc;
            prop_assert_eq!(&back, &m);
            // ... and evaluates without overflow or panic, even at extremes.
            evaluate_at_extremes(&m);
        }
    }
}

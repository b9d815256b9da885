//! Model image: round trip, every typed refusal, and fuzzed bytes never panic.
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
    // A flash slot holds the image followed by erased bytes: still parses.
    let mut slot = buf.clone();
    slot.extend_from_slice(&[0xFF; 100]);
    assert_eq!(Model::parse(&slot).unwrap(), m);
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
        Err(ImageError::BadValue {
            what: "direction limits"
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
        if let Ok(m) = Model::parse(&b) {
            // Whatever parses evaluates without overflow or panic, even at extremes.
            for v in [i32::MIN, -1, 0, 1 << 28, i32::MAX] {
                let f = [v; MAX_INPUTS];
                let _ = m.evaluate(&f, &[i32::MIN, i32::MAX, 0, 0, 0, 0]);
            }
        } else if !seal {
            // An unsealed edit that changed anything must be refused.
            prop_assert!(b != good);
        }
    }
}

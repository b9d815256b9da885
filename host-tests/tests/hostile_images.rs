//! Well-formed but absurd images (issue 30): every one is sealed with a
//! correct CRC, so only the semantic limits (`thermocomp_core::image`'s
//! `semantic`, result codes 74–77) stand between it and the compensator.
//! Each is refused over Modbus with its own result code, the board locks,
//! and the old model keeps serving; `tcomp export` refuses the same image.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{blank_app, encode, stage_and_send};
use thermocomp::app::App;
use thermocomp_core::{ImageError, Model};
use thermocomp_protocol::holding::*;

fn demo(version: u32) -> Model {
    let mut fm = thermocomp_core::float::demo_model(u64::from(version));
    fm.model_version = version;
    fm.quantize().unwrap().0
}

/// Unlock (the board's own key), stage and commit `img`; the reply frame.
fn upload(app: &mut App<MockFlash>, img: &[u8]) -> Vec<u8> {
    stage_and_send(app, img, CMD_COMMIT_MODEL)
}

/// Each hostile change, the error the parser must name and its result code.
fn hostile() -> Vec<(&'static str, Model, u16)> {
    let mut cases = vec![];
    let mut m = demo(3);
    for n in m.nets.iter_mut() {
        n.w1.iter_mut().flatten().for_each(|w| *w = i32::MIN);
    }
    cases.push(("hidden weights at i32::MIN", m, result::COEFFICIENT_RANGE));
    let mut m = demo(3);
    for n in m.nets.iter_mut() {
        n.b1.iter_mut().for_each(|b| *b = i32::MAX);
    }
    cases.push(("hidden biases at i32::MAX", m, result::COEFFICIENT_RANGE));
    let mut m = demo(3);
    for n in m.nets.iter_mut() {
        n.w2.iter_mut().for_each(|w| *w = i32::MAX);
        n.b2 = i32::MAX;
    }
    cases.push(("output weights at i32::MAX", m, result::PREDICTION_BOUND));
    let mut m = demo(3);
    // The direction-2 table has no axis: its sum is bounded only by the
    // prediction bound (the axis tables' overflow bound does not see it).
    for t in m.tables.iter_mut().filter(|t| t.axis == 0xFF) {
        t.terms.iter_mut().for_each(|x| x.coef = i32::MIN);
    }
    cases.push(("static table at i32::MIN", m, result::PREDICTION_BOUND));
    let mut m = demo(3);
    m.warmup_s = u32::MAX;
    cases.push(("warm-up 0xFFFFFFFF", m, result::WARMUP_TOO_LONG));
    let mut m = demo(3);
    m.inputs[0].lag.as_mut().unwrap().tau_s = u32::MAX;
    cases.push(("lag 0xFFFFFFFF", m, result::LAG_TOO_LONG));
    let mut m = demo(3);
    m.inputs[1].lag.as_mut().unwrap().tau_s = 0;
    cases.push(("lag 0", m, result::LAG_TOO_LONG));
    for (name, t) in [
        ("sensor reference at i32::MAX", i32::MAX),
        ("sensor reference at i32::MIN", i32::MIN),
        ("sensor reference at +125.0625 °C", 125 * 16 + 1),
    ] {
        let mut m = demo(3);
        m.sensors[0].ref_temp = t;
        cases.push((name, m, result::BAD_VALUE));
    }
    let mut m = demo(3);
    for n in m.nets.iter_mut() {
        n.w1.iter_mut().flatten().for_each(|w| *w = i32::MAX);
        n.b1.iter_mut().for_each(|w| *w = i32::MIN);
        n.w2.iter_mut().for_each(|w| *w = i32::MIN);
        n.b2 = i32::MIN;
    }
    for t in m.tables.iter_mut() {
        t.terms.iter_mut().for_each(|x| x.coef = i32::MAX);
    }
    m.warmup_s = u32::MAX;
    // Everything at once: the first limit checked (module docs' order) speaks.
    cases.push(("everything at the extremes", m, result::WARMUP_TOO_LONG));
    cases
}

#[test]
fn hostile_images_are_refused_with_their_own_codes_and_the_old_model_kept() {
    let mut app = blank_app();
    host_tests::commission(&mut app);
    app.program(&encode(&mut demo(2))).unwrap();
    for (what, mut m, code) in hostile() {
        let img = encode(&mut m);
        let err = Model::parse(&img).unwrap_err();
        assert_eq!(result::of_image_error(&err), code, "{what}: {err}");
        let reply = upload(&mut app, &img);
        assert_eq!((reply[1], reply[2]), (0x86, 0x04), "{what}: exception 04");
        assert_eq!(app.result(), code, "{what}");
        assert!(!app.unlocked(0), "{what}: locked");
        assert_eq!(app.model_version(), 2, "{what}: old model kept");
    }
    // The untouched model of the same version commits.
    assert_eq!(upload(&mut app, &encode(&mut demo(3)))[1], 6);
    assert_eq!(app.model_version(), 3);
}

#[test]
fn the_bounds_sit_where_the_limits_say() {
    use thermocomp_core::limits::{MAX_NET_WEIGHT_Q16, MAX_PREDICTION, MAX_TAU_S, MAX_WARMUP_S};
    let mut m = demo(3);
    m.warmup_s = MAX_WARMUP_S;
    Model::parse(&encode(&mut m)).unwrap();
    m.warmup_s += 1;
    assert!(matches!(
        Model::parse(&encode(&mut m)),
        Err(ImageError::WarmupTooLong { .. })
    ));
    let mut m = demo(3);
    m.inputs[0].lag.as_mut().unwrap().tau_s = MAX_TAU_S;
    Model::parse(&encode(&mut m)).unwrap();
    m.inputs[0].lag.as_mut().unwrap().tau_s += 1;
    assert!(matches!(
        Model::parse(&encode(&mut m)),
        Err(ImageError::LagTooLong { input: 0, .. })
    ));
    let mut m = demo(3);
    m.nets[0].w1[0][0] = MAX_NET_WEIGHT_Q16 as i32;
    Model::parse(&encode(&mut m)).unwrap();
    m.nets[0].w1[0][0] = -(MAX_NET_WEIGHT_Q16 as i32) - 1;
    assert!(matches!(
        Model::parse(&encode(&mut m)),
        Err(ImageError::CoefficientRange { net: 0 })
    ));
    // One constant term worth exactly the bound on the static table's
    // direction, with its other terms gone: at the bound passes, 1 LSB more not.
    let mut m = demo(3);
    let t = m.tables.iter_mut().find(|t| t.axis == 0xFF).unwrap();
    let direction = t.direction;
    t.terms.truncate(1);
    t.terms[0].coef = MAX_PREDICTION << 8;
    Model::parse(&encode(&mut m)).unwrap();
    let t = m.tables.iter_mut().find(|t| t.axis == 0xFF).unwrap();
    t.terms[0].coef = -(MAX_PREDICTION << 8) - 1;
    assert_eq!(
        Model::parse(&encode(&mut m)).unwrap_err(),
        ImageError::PredictionBound { direction }
    );
}

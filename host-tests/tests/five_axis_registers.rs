//! The five-axis part of the volumetric correction on the register map
//! (issue 31 item 4): A and C in holding registers 36–39 (0.001°, no
//! unlock, broadcast allowed), the correction in 180–185 refreshed at once
//! after a write of positions or angles and equal to the core's
//! `five_axis::evaluate`, what it used in input registers 330–359, "not
//! available" until the PLC has written A and C, and result codes 80–86 (87, an unknown flag bit, is the core's test).
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{
    be_words, blank_app, encode, read_holding, read_inputs, s32, words, write_n, Reply,
};
use thermocomp::app::App;
use thermocomp_core::five_axis::{self, fstatus, FiveAxis, FiveAxisSpec};
use thermocomp_core::image::NONE;
use thermocomp_core::volumetric::*;
use thermocomp_core::ImageError;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;

/// FC04 of `n` input registers from `addr`.
fn read(app: &mut App<MockFlash>, addr: u16, n: u8, now: u64) -> Vec<u16> {
    read_inputs(app, addr, u16::from(n), now)
}

fn section() -> Volumetric {
    let terms: Vec<VolTerm> = [
        ([0, 0, 0, 0], [1_500_000, -2_000_000, 300_000]),
        ([1, 0, 0, 0], [12_345_678, 0, -7_654_321]),
        ([1, 1, 0, 1], [-3_000_000, 4_000_000, 5_000_000]),
    ]
    .into_iter()
    .map(|(exps, coef)| VolTerm {
        exps,
        sensor: NONE,
        coef,
    })
    .collect();
    Volumetric::new(&VolumetricSpec {
        slots: [0, 1, 2],
        origin_um: [0, 0, -400_000],
        stroke_um: [800_000, 500_000, 400_000],
        tool_max_um: 500_000,
        max_correction: [100_000; 3],
        sensors: &[],
        terms: &terms,
    })
    .unwrap()
}

fn five() -> FiveAxis {
    let mut s = FiveAxisSpec {
        pivot_a_um: [400_000, 250_000, -150_000],
        offset_c_um: [0, 0, 120_000],
        a_range_mdeg: [-110_000, 110_000],
        c_range_mdeg: [-360_000, 360_000],
        max_correction: [10_000; 3],
        n_sensors: 0,
        order: 2,
        ..FiveAxisSpec::default()
    };
    // XOC 10 µm, YOC −6 µm, AOC 20 µrad, BOC −15 µrad, YOA 4 µm, ZOA −8 µm, BOA 12 µrad, COA −9 µrad.
    let loc = [10, -6, 20, -15, 4, -8, 12, -9];
    for (row, v) in s.location.iter_mut().zip(loc) {
        row[0] = v * 1_000_000;
    }
    s.motion[1][2][0] = [2_000_000, -1_000_000]; // EZC
    s.motion[1][5][1] = [0, 5_000_000]; // ECC, second order
    s.motion[0][4][0] = [3_000_000, 4_000_000]; // EBA
    FiveAxis::new(&s).unwrap()
}

fn image(v: Option<Volumetric>, f: Option<FiveAxis>) -> Vec<u8> {
    let (mut m, _) = thermocomp_core::float::demo_model(1).quantize().unwrap();
    m.volumetric = v;
    m.five_axis = f;
    encode(&mut m)
}

fn app() -> App<MockFlash> {
    let mut app = blank_app();
    host_tests::commission(&mut app);
    app
}

#[test]
fn served_correction_is_the_cores_five_axis_evaluation_at_the_plcs_pose() {
    let mut app = app();
    let (v, f) = (section(), five());
    app.program(&image(Some(v.clone()), Some(f.clone())))
        .unwrap();
    let mut reply = Reply::new();
    // Positions and tool, but no angles yet: not available, and why.
    app.request(
        &write_n(1, HR_POSITIONS, &words(&[100_000, 200_000, -100_000])),
        0,
        &mut reply,
    );
    let w = read(&mut app, IR_VOL_CORRECTION, 20, 0);
    assert_eq!(&w[0..6], &[0x8000, 0, 0x8000, 0, 0x8000, 0], "{w:04x?}");
    assert_eq!(
        w[6] & (vstatus::VALID | vstatus::NO_POSITIONS),
        vstatus::NO_POSITIONS
    );
    let x = read(&mut app, IR_FIVE_ANGLES, 30, 0);
    assert_eq!(x[4], fstatus::NO_ANGLES);
    assert_eq!(x[5], 2, "the section's order");
    assert_eq!(s32(&x, 0), NOT_AVAILABLE_32);
    assert_eq!(s32(&x, 6), NOT_AVAILABLE_32);
    let mut last_seq = s32(&w, 14) as u32;
    let poses = [
        ([0, 0, -400_000], 0, [0, 0]),
        ([400_000, 250_000, -200_000], 120_000, [30_000, 45_000]),
        ([800_000, 500_000, 0], 500_000, [-90_000, 315_000]),
        ([123_456, 7, -399_999], 33_333, [-45_500, -120_250]),
        ([650_000, 90_000, -30_000], 250_000, [110_000, 359_999]),
        ([300_000, 300_000, -300_000], 200_000, [125_000, -400_000]), // both clamped
    ];
    let mut distinct = std::collections::BTreeSet::new();
    for (k, (pos, tool, ang)) in poses.into_iter().enumerate() {
        let now = 1000 * k as u64 + 10;
        app.request(&write_n(1, HR_POSITIONS, &words(&pos)), now, &mut reply);
        app.request(
            &write_n(1, HR_TOOL_LENGTH, &words(&[tool])),
            now,
            &mut reply,
        );
        // Angles by broadcast, as a PLC may: no reply, but taken.
        reply.clear();
        app.request(&write_n(0, HR_ROTARY, &words(&ang)), now, &mut reply);
        assert!(reply.is_empty());
        assert_eq!(
            read_holding(&mut app, HR_ROTARY + 2, 1, now),
            [words(&ang)[2]]
        );
        let w = read(&mut app, IR_VOL_CORRECTION, 20, now);
        let x = read(&mut app, IR_FIVE_ANGLES, 30, now);
        let mut full = [0i32; 6];
        full[..3].copy_from_slice(&pos);
        let want = five_axis::evaluate(&v, &f, &full, tool, ang, &[]);
        assert_eq!(
            [s32(&w, 0), s32(&w, 2), s32(&w, 4)],
            want.corrections,
            "{pos:?} {ang:?}"
        );
        assert_eq!(w[6], want.status, "{ang:?}");
        assert_eq!([s32(&x, 0), s32(&x, 2)], want.angles_mdeg);
        assert_eq!(x[4], want.five_status);
        assert_ne!(x[4] & fstatus::INCLUDED, 0);
        assert_eq!([s32(&x, 6), s32(&x, 8), s32(&x, 10)], want.rotary);
        assert_eq!(s32(&x, 12), s32(&w, 14), "the same evaluation");
        assert!(x[14..].iter().all(|&r| r == 0), "reserved");
        let seq = s32(&w, 14) as u32;
        assert!(seq > last_seq);
        last_seq = seq;
        // The rotary part is really there: not the three-axis correction.
        let lin = v.evaluate(&full, tool, &[]);
        if ang != [0, 0] {
            assert_ne!(want.corrections, lin.corrections, "{ang:?}");
        }
        distinct.insert(want.corrections);
    }
    assert_eq!(distinct.len(), poses.len());
    let clamped = read(&mut app, IR_FIVE_STATUS, 1, 10_000)[0];
    assert_eq!(
        clamped,
        fstatus::INCLUDED | fstatus::A_CLAMPED | fstatus::C_CLAMPED
    );
}

#[test]
fn a_write_of_angles_alone_refreshes_at_once() {
    let mut app = app();
    let (v, f) = (section(), five());
    app.program(&image(Some(v.clone()), Some(f.clone())))
        .unwrap();
    let mut reply = Reply::new();
    app.request(
        &write_n(1, HR_POSITIONS, &words(&[1, 2, -3])),
        0,
        &mut reply,
    );
    app.request(&write_n(1, HR_ROTARY, &words(&[0, 0])), 0, &mut reply);
    let before = read(&mut app, IR_VOL_CORRECTION, 16, 5);
    // C alone (two registers), unit-addressed: no unlock needed.
    app.request(&write_n(1, HR_ROTARY + 2, &words(&[90_000])), 6, &mut reply);
    assert_eq!(reply[1], 0x10, "accepted: {reply:02x?}");
    let after = read(&mut app, IR_VOL_CORRECTION, 16, 7);
    assert_ne!(&before[0..6], &after[0..6]);
    assert!(s32(&after, 14) > s32(&before, 14));
    let want = five_axis::evaluate(&v, &f, &[1, 2, -3], 0, [0, 90_000], &[]);
    assert_eq!(
        [s32(&after, 0), s32(&after, 2), s32(&after, 4)],
        want.corrections
    );
}

#[test]
fn without_a_five_axis_section_angles_change_nothing() {
    let mut app = app();
    let v = section();
    app.program(&image(Some(v.clone()), None)).unwrap();
    let mut reply = Reply::new();
    app.request(
        &write_n(1, HR_POSITIONS, &words(&[5, 6, -7])),
        0,
        &mut reply,
    );
    app.request(
        &write_n(1, HR_ROTARY, &words(&[45_000, 90_000])),
        0,
        &mut reply,
    );
    let w = read(&mut app, IR_VOL_CORRECTION, 20, 1);
    let want = v.evaluate(&[5, 6, -7], 0, &[]);
    assert_eq!([s32(&w, 0), s32(&w, 2), s32(&w, 4)], want.corrections);
    assert_eq!(w[6], want.status);
    let x = read(&mut app, IR_FIVE_ANGLES, 30, 1);
    assert_eq!(x[4], fstatus::NO_SECTION);
    assert_eq!(x[5], 0);
    assert_eq!(s32(&x, 0), NOT_AVAILABLE_32);
}

#[test]
fn five_axis_refusals_have_their_own_result_codes() {
    let codes = [
        (
            ImageError::FiveAxisWithoutVolumetric,
            80,
            "FIVE_AXIS_NO_VOLUMETRIC",
        ),
        (
            ImageError::FiveAxisSensors {
                count: 2,
                available: 1,
            },
            81,
            "FIVE_AXIS_SENSORS",
        ),
        (
            ImageError::FiveAxisOrder { order: 5 },
            82,
            "FIVE_AXIS_ORDER",
        ),
        (ImageError::FiveAxisGeometry, 83, "FIVE_AXIS_GEOMETRY"),
        (
            ImageError::FiveAxisAngleRange { axis: 1 },
            84,
            "FIVE_AXIS_ANGLE_RANGE",
        ),
        (
            ImageError::FiveAxisMaxCorrection {
                direction: 0,
                value: 0,
            },
            85,
            "FIVE_AXIS_MAX_CORRECTION",
        ),
        (
            ImageError::FiveAxisErrorTooLarge { error: 3 },
            86,
            "FIVE_AXIS_ERROR_TOO_LARGE",
        ),
    ];
    for (e, code, name) in codes {
        assert_eq!(result::of_image_error(&e), code, "{e}");
        assert_eq!(result::name(code), name);
    }
    // A commit of kind 4 without kind 3 is refused with 80 over the wire.
    let mut app = app();
    let img = image(None, Some(five()));
    let mut reply = Reply::new();
    app.request(
        &write_n(1, HR_UNLOCK, &[host_tests::TEST_UNLOCK_KEY]),
        0,
        &mut reply,
    );
    let regs = be_words(&img);
    for (k, chunk) in regs.chunks(100).enumerate() {
        app.request(
            &write_n(1, HR_STAGING + 100 * k as u16, chunk),
            0,
            &mut reply,
        );
        assert_eq!(reply[1], 0x10, "{reply:02x?}");
    }
    app.request(
        &write_n(1, HR_STAGED_LEN, &[img.len() as u16]),
        0,
        &mut reply,
    );
    app.request(&write_n(1, HR_COMMAND, &[CMD_COMMIT_MODEL]), 0, &mut reply);
    assert_eq!(reply[1], 0x90, "refused: {reply:02x?}");
    assert_eq!(app.result(), 80);
}

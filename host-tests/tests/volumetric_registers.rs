//! The volumetric correction on the register map (issue 14): input
//! registers 180–199, tool length in holding registers 34–35, "not
//! available" (0x8000 0000) whenever it cannot be computed, and the served
//! value equal to the math core's evaluation at the PLC's positions.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{
    blank_app, encode, frame, read_holding, read_inputs, s32, words, write_n, Reply,
};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp_core::image::{SensorRef, NONE};
use thermocomp_core::volumetric::*;
use thermocomp_core::ImageError;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;

/// FC04 of 180–199 through the server: the words as a PLC sees them.
fn read_block(app: &mut App<MockFlash>, now: u64) -> Vec<u16> {
    read_inputs(app, IR_VOL_CORRECTION, 20, now)
}

fn section(sensors: &[VolSensor]) -> Volumetric {
    let terms: Vec<VolTerm> = [
        ([0, 0, 0, 0], NONE, [1_500_000, -2_000_000, 300_000]),
        ([1, 0, 0, 0], NONE, [12_345_678, 0, -7_654_321]),
        ([1, 1, 0, 1], NONE, [-3_000_000, 4_000_000, 5_000_000]),
        ([0, 2, 1, 0], NONE, [800_000, -600_000, 100_000]),
    ]
    .into_iter()
    .chain((!sensors.is_empty()).then_some(([1, 0, 1, 0], 0, [90_000, -40_000, 250_000])))
    .map(|(exps, sensor, coef)| VolTerm { exps, sensor, coef })
    .collect();
    Volumetric::new(&VolumetricSpec {
        slots: [0, 1, 2],
        origin_um: [0, 0, -400_000],
        stroke_um: [800_000, 500_000, 400_000],
        tool_max_um: 500_000,
        max_correction: [100_000; 3],
        sensors,
        terms: &terms,
    })
    .unwrap()
}

fn image(v: Option<Volumetric>) -> Vec<u8> {
    let (mut m, _) = thermocomp_core::float::demo_model(1).quantize().unwrap();
    m.volumetric = v;
    encode(&mut m)
}

fn app() -> App<MockFlash> {
    blank_app()
}

fn not_available(w: &[u16]) {
    assert_eq!(&w[0..6], &[0x8000, 0, 0x8000, 0, 0x8000, 0], "{w:04x?}");
    assert_eq!(s32(w, 8), NOT_AVAILABLE_32);
    assert_eq!(w[6] & vstatus::VALID, 0);
}

#[test]
fn without_a_section_the_block_says_not_available() {
    let mut app = app();
    let w = read_block(&mut app, 0);
    not_available(&w);
    assert_eq!(w[6], vstatus::NO_SECTION);
    assert_eq!(w[7], 0, "no terms");
    app.program(&image(None)).unwrap();
    let mut reply = Reply::new();
    app.request(
        &write_n(1, HR_POSITIONS, &words(&[1000, 2000, -3000])),
        5,
        &mut reply,
    );
    let w = read_block(&mut app, 10);
    not_available(&w);
    assert_eq!(w[6], vstatus::NO_SECTION);
    // The map ends after the envelope block (360–371), past the
    // volumetric, identity, probe-reference and five-axis ones.
    assert_eq!(IR_LAST, 371);
    let [a, b] = (IR_LAST + 1).to_be_bytes();
    app.request(&frame(&[1, 4, a, b, 0, 1]), 10, &mut reply);
    assert_eq!(&reply[1..3], &[0x84, 2], "{reply:02x?}");
}

#[test]
fn served_correction_equals_the_core_at_the_plcs_positions() {
    let mut app = app();
    let v = section(&[]);
    app.program(&image(Some(v.clone()))).unwrap();
    // No positions from the PLC yet: not available, and says why.
    let w = read_block(&mut app, 0);
    not_available(&w);
    assert_eq!(w[6] & vstatus::NO_POSITIONS, vstatus::NO_POSITIONS);
    assert_eq!(w[7], 4, "terms in the section");
    let mut reply = Reply::new();
    let mut last_seq = s32(&w, 14) as u32;
    for (k, (pos, tool)) in [
        ([0, 0, -400_000], 0),
        ([400_000, 250_000, -200_000], 120_000),
        ([800_000, 500_000, 0], 500_000),
        ([123_456, 7, -399_999], 33_333),
        ([900_000, -5, 10], 600_000), // beyond the strokes and the tool scale
    ]
    .into_iter()
    .enumerate()
    {
        let now = 1000 * k as u64;
        // Positions by broadcast (as a PLC may), tool length to the unit.
        app.request(&write_n(0, HR_POSITIONS, &words(&pos)), now, &mut reply);
        app.request(
            &write_n(1, HR_TOOL_LENGTH, &words(&[tool])),
            now,
            &mut reply,
        );
        let w = read_block(&mut app, now);
        let mut full = [0i32; 6];
        full[..3].copy_from_slice(&pos);
        let want = v.evaluate(&full, tool, &[]);
        assert_eq!(
            [s32(&w, 0), s32(&w, 2), s32(&w, 4)],
            want.corrections,
            "{pos:?} tool {tool}"
        );
        assert_eq!(w[6], want.status, "{pos:?}");
        assert_eq!(s32(&w, 8), tool.clamp(0, 500_000));
        let seq = s32(&w, 14) as u32;
        assert!(seq > last_seq, "a new evaluation per write");
        last_seq = seq;
        assert!(want.corrections.iter().any(|&c| c != 0));
    }
    assert_eq!(
        read_holding(&mut app, HR_TOOL_LENGTH + 1, 1, 0),
        [600_000u32 as u16]
    );
    assert_eq!(
        read_holding(&mut app, HR_TOOL_LENGTH + 2, 1, 0),
        [0],
        "A (holding 36), never written"
    );
}

#[test]
fn a_section_sensor_without_a_value_makes_it_not_available() {
    let mut app = app();
    let s = VolSensor {
        sensor: SensorRef {
            rom: [0; 8],
            channel: 2,
            ref_temp: 320,
        },
        min: 0,
        max: 1000,
    };
    app.program(&image(Some(section(&[s])))).unwrap();
    let mut reply = Reply::new();
    app.request(&write_n(1, HR_POSITIONS, &words(&[1, 2, 3])), 0, &mut reply);
    // A cycle on an acquisition that has read nothing: channel 2 has no value.
    let acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    app.cycle(&acq, 1000, 1000, None);
    let w = read_block(&mut app, 1000);
    not_available(&w);
    assert_eq!(w[6] & vstatus::SENSOR_FAULT, vstatus::SENSOR_FAULT);
    assert_eq!(w[10], NOT_AVAILABLE, "no temperature to report");
}

#[test]
fn volumetric_refusals_have_their_own_result_codes() {
    let codes = [
        (
            ImageError::VolumetricAxisSlot { axis: 0, slot: 7 },
            40,
            "VOLUMETRIC_RANGE",
        ),
        (
            ImageError::VolumetricStroke { axis: 1, value: 0 },
            40,
            "VOLUMETRIC_RANGE",
        ),
        (
            ImageError::VolumetricTool { value: 0 },
            40,
            "VOLUMETRIC_RANGE",
        ),
        (
            ImageError::VolumetricTemperature { sensor: 0 },
            41,
            "VOLUMETRIC_TEMPERATURE",
        ),
        (
            ImageError::VolumetricMaxCorrection {
                direction: 2,
                value: 0,
            },
            42,
            "VOLUMETRIC_MAX_CORRECTION",
        ),
    ];
    for (e, code, name) in codes {
        assert_eq!(result::of_image_error(&e), code, "{e}");
        assert_eq!(result::name(code), name);
    }
}

#[test]
fn a_section_sensor_named_by_rom_follows_the_channel_map() {
    use thermocomp::acquisition::rom::RomCode;
    let rom = RomCode::from_serial(0x28, [1, 2, 3, 4, 5, 6]).0;
    let s = VolSensor {
        sensor: SensorRef {
            rom,
            channel: 0,
            ref_temp: 320,
        },
        min: 0,
        max: 1000,
    };
    let mut app = app();
    app.program(&image(Some(section(&[s])))).unwrap();
    assert_eq!(
        app.compensation().vol_channel_of(0),
        None,
        "not on the bus yet"
    );
    // A bus search finds it on channel 7 (the model's own sensors are by channel).
    let mut map = ChannelMap::new();
    map.set(7, Some(RomCode(rom))).unwrap();
    app.update_channel_map(map);
    assert_eq!(app.compensation().vol_channel_of(0), Some(7));
}

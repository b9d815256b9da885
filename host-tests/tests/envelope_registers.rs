//! Input registers 360–371 (map version 5, issue 50 item 3): per direction,
//! the steps served with an input beyond its training envelope by more than
//! the image's margin. The application over the emulated 1-Wire bus and its
//! Modbus codec: a sensor warmed past its range plus the margin counts in
//! exactly the directions whose model reads it, one per cycle, and not
//! while it is within the margin.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{self, encode, read_inputs, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy};
use thermocomp_protocol::registers::{IR_ENVELOPE_STEPS, IR_MAP_VERSION, MAP_VERSION};

/// Margin of the image's policy, 1/16 °C (1 °C).
const MARGIN: u16 = 16;

/// The demo model (Z: network on inputs 0–4; X: network and table on 0, 1,
/// 4; Y: table on 2, 3; input 2 = rise of sensor 2, unlagged, trained over
/// −32 … 320) with the envelope policy `hold`, margin 1 °C, on every direction.
fn image() -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(1);
    fm.model_version = 5;
    let (mut m, _) = fm.quantize().unwrap();
    assert_eq!(m.inputs[2].max, 320);
    m.envelope = Some(
        [EnvelopePolicy {
            mode: EnvelopeMode::Hold,
            margin: MARGIN,
        }; 6],
    );
    encode(&mut m)
}

fn u32s(words: &[u16]) -> Vec<u32> {
    words
        .chunks(2)
        .map(|w| u32::from(w[0]) << 16 | u32::from(w[1]))
        .collect()
}

#[test]
fn the_count_registers_count_steps_beyond_the_margin_per_direction() {
    let bus = bus_with_sensors(6, 0x2EF_0051, 20 * 16);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
    assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
    let mut app = modbus::boot(MockFlash::new(2 * SLOT as usize), *acq.map());
    app.program(&image()).unwrap();
    app.update_channel_map(*acq.map());
    app.poll_flash();
    assert_eq!(app.model_version(), 5);

    // The sensor on channel 2 (model sensor 2: the demo's sensors are by
    // channel) warms by 2 °C a cycle from the reference (the acquisition's
    // step limit); the others stay at 20 °C.
    let device = (0..6)
        .find(|&k| {
            bus.with_device(k, |d| d.rom)
                .and_then(|r| acq.map().channel_of(&r))
                == Some(2)
        })
        .unwrap();
    let mut expected = [0u32; 6];
    for cycle in 0..24i16 {
        let rise = 32 * cycle;
        bus.with_device(device, |d| d.temperature = 20 * 16 + rise);
        bus.advance_ns(1_000 * MS);
        let now = bus.now_ms();
        block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), now));
        let out = app.cycle(&acq, now, now, Some(3_000));
        assert_eq!(
            out.status & thermocomp_core::compensator::status::SENSOR_FAULT,
            0
        );
        if i32::from(rise) > 320 + i32::from(MARGIN) {
            // Z and Y read input 2; X does not.
            expected[0] += 1;
            expected[2] += 1;
        }
        let regs = read_inputs(&mut app, IR_ENVELOPE_STEPS, 12, now);
        assert_eq!(u32s(&regs), expected, "cycle {cycle}, rise {rise}");
        assert_eq!(app.compensator().envelope_steps().to_vec(), expected);
    }
    // Rises 352 … 736 were beyond 320 + 16; 320 and 336 were not.
    assert_eq!(expected[0], 13);
    assert_eq!(
        read_inputs(&mut app, IR_MAP_VERSION, 1, bus.now_ms()),
        vec![MAP_VERSION]
    );
    // A new model restarts the count (published with the next cycle).
    app.program(&modbus::demo_image(1, 6)).unwrap();
    app.poll_flash();
    assert_eq!(app.compensator().envelope_steps(), [0; 6]);
    bus.advance_ns(1_000 * MS);
    let now = bus.now_ms();
    block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), now));
    app.cycle(&acq, now, now, Some(3_000));
    let regs = read_inputs(&mut app, IR_ENVELOPE_STEPS, 12, now);
    // The new model takes its reference at this cycle: nothing beyond.
    assert_eq!(u32s(&regs), vec![0; 6]);
}

//! The commit check lends the compensator's model (issue 47: no second
//! model on the Modbus task's stack): a candidate image is parsed in the
//! compensator's own model storage and the model in force is parsed back
//! from its slot where the flash maps it. A refused commit — an image that
//! does not parse, or one that parses but is not newer — must leave the
//! running compensation exactly as it was: every later cycle serves the
//! same output, bit for bit, as a twin board that never saw the commit.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{self, demo_image, stage_and_send, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp_core::StepOutput;
use thermocomp_protocol::holding::*;

struct Rig {
    bus: Bus,
    acq: TemperatureAcquisition,
}

impl Rig {
    fn new() -> Rig {
        let bus = bus_with_sensors(6, 0x2EF_0001, 20 * 16);
        let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        Rig { bus, acq }
    }

    /// Sensor k at `base + k·step` (1/16 °C), then one acquisition cycle 1 s on.
    fn warm(&mut self, base: i16, step: i16) {
        for k in 0..6 {
            self.bus
                .with_device(k, |d| d.temperature = base + step * k as i16);
        }
        self.bus.advance_ns(1_000 * MS);
        let now = self.bus.now_ms();
        block_on(
            self.acq
                .cycle(&mut master(&self.bus), &mut self.bus.delay(), now),
        );
    }

    fn cycle(&self, app: &mut App<MockFlash>) -> StepOutput {
        let now = self.bus.now_ms();
        app.cycle(&self.acq, now, now, Some(3_000))
    }
}

fn board(rig: &Rig) -> App<MockFlash> {
    let mut app = modbus::boot(MockFlash::new(2 * SLOT as usize), *rig.acq.map());
    app.program(&demo_image(1, 5)).unwrap();
    app.update_channel_map(*rig.acq.map());
    app.poll_flash();
    app
}

#[test]
fn a_refused_commit_leaves_the_running_compensation_bit_for_bit() {
    let mut rig = Rig::new();
    let mut twin = board(&rig);
    let mut app = board(&rig);
    // A corrupt image (CRC broken) and a valid but older one (version 4).
    let mut corrupt = demo_image(2, 9);
    let last = corrupt.len() - 1;
    corrupt[last] ^= 0x5A;
    let older = demo_image(3, 4);
    let mut refused = 0;
    for t in 0..120i16 {
        rig.warm(20 * 16 + t * 3, 1 + t / 20);
        if t == 40 {
            let reply = stage_and_send(&mut app, &corrupt, CMD_COMMIT_MODEL);
            assert_eq!((reply[1], reply[2]), (0x86, 0x04), "corrupt: exception 04");
            assert_eq!(app.result(), result::BAD_CRC);
            refused += 1;
        }
        if t == 70 {
            let reply = stage_and_send(&mut app, &older, CMD_COMMIT_MODEL);
            assert_eq!((reply[1], reply[2]), (0x86, 0x04), "older: exception 04");
            assert_eq!(app.result(), result::NOT_NEWER);
            refused += 1;
        }
        let (a, b) = (rig.cycle(&mut app), rig.cycle(&mut twin));
        assert_eq!(a, b, "cycle {t}: served output differs from the twin's");
        assert_eq!(app.model_version(), 5, "cycle {t}: model in force");
        assert_eq!(
            app.compensator().reference(),
            twin.compensator().reference(),
            "cycle {t}: reference"
        );
    }
    assert_eq!(refused, 2);
    // The older image the check parsed is still staged: command 5
    // (rollback) commits it on purpose, and then it serves.
    let reply = stage_and_send(&mut app, &older, CMD_ROLLBACK_MODEL);
    assert_eq!(reply[1], 6, "rollback accepted");
    app.poll_flash();
    assert_eq!(app.model_version(), 4);
}

#[test]
fn a_board_without_a_model_stays_without_one_after_a_refused_commit() {
    let rig = Rig::new();
    let mut app = modbus::boot(MockFlash::new(2 * SLOT as usize), *rig.acq.map());
    host_tests::commission(&mut app);
    let mut corrupt = demo_image(2, 9);
    corrupt[0] ^= 0xFF;
    let reply = stage_and_send(&mut app, &corrupt, CMD_COMMIT_MODEL);
    assert_eq!((reply[1], reply[2]), (0x86, 0x04));
    assert!(app.compensator().model().is_none());
    assert_eq!(app.model_version(), 0);
}

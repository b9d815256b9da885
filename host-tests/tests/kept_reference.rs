//! The reference sample a machine with a fixed reference keeps (issue 12,
//! item 4): command 10 takes it from the pin-level emulated bus, it is
//! stored with the settings in the A/B slots and applied at boot (a warm
//! reboot does not take a new one), command 11 and command 7 drop it, and a
//! power cut at every flash operation of storing it leaves the old kept
//! reference or the new one.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{self, demo_image, read_inputs, write_unlocked, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp::settings::KeptReference;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::IR_REFERENCE_STATE;

fn command(app: &mut App<MockFlash>, cmd: u16) -> Vec<u8> {
    write_unlocked(app, HR_COMMAND, cmd)
}

fn input(app: &mut App<MockFlash>, addr: u16) -> u16 {
    read_inputs(app, addr, 1, 0)[0]
}

fn holding_result(app: &App<MockFlash>) -> u16 {
    app.result()
}

/// The demo model (six sensors by channel 0–5), version 1.
fn image() -> Vec<u8> {
    demo_image(1, 1)
}

struct Rig {
    bus: Bus,
    acq: TemperatureAcquisition,
}

impl Rig {
    /// Six DS18B20s on the emulated line, searched and configured.
    fn new() -> Rig {
        let bus = bus_with_sensors(6, 0x2EF_0001, 20 * 16);
        let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        let mut rig = Rig { bus, acq };
        rig.cycle();
        rig
    }

    /// Every sensor at `t` (1/16 °C), then one acquisition cycle 1 s on.
    fn set_all(&mut self, t: i16) {
        for k in 0..6 {
            self.bus.with_device(k, |d| d.temperature = t);
        }
        self.cycle();
    }

    fn cycle(&mut self) {
        self.bus.advance_ns(1_000 * MS);
        let now = self.bus.now_ms();
        block_on(
            self.acq
                .cycle(&mut master(&self.bus), &mut self.bus.delay(), now),
        );
    }

    fn app_cycle(&self, app: &mut App<MockFlash>) {
        let now = self.bus.now_ms();
        app.cycle(&self.acq, now, now, Some(0));
    }
}

fn boot(rig: &Rig, flash: MockFlash) -> App<MockFlash> {
    modbus::boot(flash, *rig.acq.map())
}

fn power_cycle(rig: &Rig, app: &mut App<MockFlash>) -> App<MockFlash> {
    modbus::power_cycle(app, *rig.acq.map())
}

fn reference(app: &mut App<MockFlash>) -> Vec<i32> {
    app.compensator().reference().unwrap().to_vec()
}

#[test]
fn a_kept_reference_survives_a_warm_reboot_and_commands_11_and_7_drop_it() {
    let mut rig = Rig::new();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&image()).unwrap();
    app.update_channel_map(*rig.acq.map());
    app.poll_flash();
    rig.set_all(20 * 16);
    rig.app_cycle(&mut app);
    assert_eq!(input(&mut app, IR_REFERENCE_STATE), 0);
    // Command 10: the next cycle with every model sensor fresh is kept.
    let reply = command(&mut app, CMD_KEEP_REFERENCE);
    assert_eq!(reply[1], 6, "{reply:02x?}");
    assert_eq!(holding_result(&app), result::REFERENCE_PENDING);
    assert_eq!(input(&mut app, IR_REFERENCE_STATE), 2);
    rig.set_all(21 * 16);
    rig.app_cycle(&mut app);
    assert_eq!(reference(&mut app), vec![21 * 16; 6], "used at once");
    assert_eq!(input(&mut app, IR_REFERENCE_STATE), 1);
    let kept = app.kept_reference().expect("kept");
    assert_eq!(kept.temps.iter().flatten().count(), 6);
    assert_eq!(holding_result(&app), result::COMMIT_IN_PROGRESS);
    assert!(!app.poll_flash());
    assert_eq!(holding_result(&app), result::OK);

    // The machine is warm when the board reboots: the kept reference
    // serves, not the first sample after boot.
    rig.set_all(30 * 16);
    let mut app = power_cycle(&rig, &mut app);
    assert_eq!(app.kept_reference(), Some(kept));
    assert_eq!(input(&mut app, IR_REFERENCE_STATE), 1);
    rig.app_cycle(&mut app);
    assert_eq!(reference(&mut app), vec![21 * 16; 6]);
    let warm = app.snapshot().predictions;
    assert_ne!(warm, [0; 6], "rises of 9 K against the kept reference");
    // Command 2 on a machine with a kept reference takes a new one and keeps it.
    command(&mut app, CMD_REREFERENCE);
    assert_eq!(holding_result(&app), result::REFERENCE_PENDING);
    rig.set_all(22 * 16);
    rig.app_cycle(&mut app);
    app.poll_flash();
    assert_eq!(reference(&mut app), vec![22 * 16; 6]);
    let mut app = power_cycle(&rig, &mut app);
    rig.app_cycle(&mut app);
    assert_eq!(
        reference(&mut app),
        vec![22 * 16; 6],
        "the new one was kept"
    );

    // Command 11: forgotten (stored); after the next boot the first sample is the reference.
    command(&mut app, CMD_FORGET_REFERENCE);
    app.poll_flash();
    assert_eq!(app.kept_reference(), None);
    assert_eq!(input(&mut app, IR_REFERENCE_STATE), 0);
    let mut app = power_cycle(&rig, &mut app);
    assert_eq!(app.kept_reference(), None);
    rig.app_cycle(&mut app);
    assert_eq!(reference(&mut app), vec![22 * 16; 6], "the sample at boot");
    // Without a kept reference command 2 is the plain re-reference (not kept).
    command(&mut app, CMD_REREFERENCE);
    rig.set_all(23 * 16);
    rig.app_cycle(&mut app);
    assert_eq!(reference(&mut app), vec![23 * 16; 6]);
    assert_eq!(app.kept_reference(), None);

    // Command 7 (defaults) drops a kept reference too.
    command(&mut app, CMD_KEEP_REFERENCE);
    rig.app_cycle(&mut app);
    app.poll_flash();
    assert!(app.kept_reference().is_some());
    command(&mut app, CMD_RESTORE_DEFAULTS);
    app.poll_flash();
    let app = power_cycle(&rig, &mut app);
    assert_eq!(app.kept_reference(), None);
    assert_eq!(app.model_version(), 1, "the model stays");
}

#[test]
fn a_reference_waits_for_every_model_sensor_to_read_fresh() {
    let mut rig = Rig::new();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&image()).unwrap();
    rig.set_all(20 * 16);
    rig.app_cycle(&mut app);
    command(&mut app, CMD_KEEP_REFERENCE);
    rig.bus.unplug(3);
    for _ in 0..3 {
        rig.cycle();
        rig.app_cycle(&mut app);
        assert_eq!(app.kept_reference(), None, "a model sensor is off the bus");
        assert_eq!(input(&mut app, IR_REFERENCE_STATE), 2);
    }
    rig.bus.plug(3);
    // Back on the bus: it answers a whole cycle before it counts (intermittent rule).
    for _ in 0..4 {
        rig.cycle();
        rig.app_cycle(&mut app);
    }
    let kept = app.kept_reference().expect("taken once all read fresh");
    assert_eq!(kept.temps.iter().flatten().count(), 6);
}

#[test]
fn a_power_cut_at_every_step_of_storing_the_reference_leaves_old_or_new() {
    let mut rig = Rig::new();
    // Starting point: model, settings, map and a kept reference at 20 °C.
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&image()).unwrap();
    app.update_channel_map(*rig.acq.map());
    app.poll_flash();
    rig.set_all(20 * 16);
    command(&mut app, CMD_KEEP_REFERENCE);
    rig.app_cycle(&mut app);
    app.poll_flash();
    let old = app.kept_reference().unwrap();
    let start = app.flash_mut().bytes.clone();
    // (A step the plausibility check accepts: the reading stays fresh.)
    rig.set_all(21 * 16);
    let fresh = || {
        let mut f = MockFlash::new(0);
        f.bytes = start.clone();
        boot(&rig, f)
    };
    // How many flash operations storing the new one takes.
    let mut probe = fresh();
    let before = probe.flash_mut().operations;
    command(&mut probe, CMD_KEEP_REFERENCE);
    rig.app_cycle(&mut probe);
    while probe.poll_flash() {}
    let new = probe.kept_reference().unwrap();
    assert_eq!(input(&mut probe, IR_REFERENCE_STATE), 1, "taken");
    assert_ne!(new, old);
    let per_op = probe.flash_mut().operations - before;
    assert!(per_op > 3, "{per_op}");
    let (mut n_old, mut n_new) = (0, 0);
    for cut in 0..=per_op {
        let mut app = fresh();
        app.flash_mut().budget = Some(cut);
        command(&mut app, CMD_KEEP_REFERENCE);
        rig.app_cycle(&mut app);
        while app.poll_flash() {}
        let stored_ok = holding_result(&app) == result::OK;
        assert_eq!(stored_ok, cut >= per_op, "cut at {cut}");
        let mut app = power_cycle(&rig, &mut app);
        assert_eq!(app.model_version(), 1, "cut at {cut}: the model stays");
        match app.kept_reference() {
            Some(k) if k == old => n_old += 1,
            Some(k) if k == new => n_new += 1,
            other => panic!("cut at {cut}: {other:?}"),
        }
        rig.app_cycle(&mut app);
        let expect = app.kept_reference().unwrap().temps[0].unwrap();
        assert_eq!(
            reference(&mut app)[0],
            i32::from(expect),
            "cut at {cut}: applied at boot"
        );
    }
    assert!(n_old > 0 && n_new > 0, "old {n_old} new {n_new}");
}

#[test]
fn a_stored_reference_that_does_not_check_is_no_reference() {
    let mut temps = [None; 20];
    temps[0] = Some(20 * 16);
    temps[19] = Some(-10 * 16);
    let k = KeptReference { temps };
    let good = k.encode();
    assert_eq!(KeptReference::decode(&good), Some(k));
    let mut bad = good;
    bad[1] = 2; // another version
    assert_eq!(KeptReference::decode(&bad), None);
    let mut bad = good;
    bad[6..8].copy_from_slice(&(200i16 * 16).to_le_bytes()); // 200 °C
    assert_eq!(KeptReference::decode(&bad), None);
    let mut bad = good;
    bad[5] = 0x80; // channel 31
    assert_eq!(KeptReference::decode(&bad), None);
    assert_eq!(KeptReference::decode(&good[1..]), None);
}

#[test]
fn on_an_image_with_a_fixed_reference_command_2_takes_and_keeps_a_measured_one() {
    let mut rig = Rig::new();
    let mut fm = thermocomp_core::float::demo_model(1);
    fm.fixed_reference = true; // ref_temp 20 °C per sensor
    let (mut m, _) = fm.quantize().unwrap();
    let mut img = vec![0u8; m.encoded_len()];
    m.encode(&mut img).unwrap();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&img).unwrap();
    rig.set_all(21 * 16);
    rig.app_cycle(&mut app);
    assert_eq!(
        reference(&mut app),
        vec![20 * 16; 6],
        "the image's reference"
    );
    command(&mut app, CMD_REREFERENCE);
    assert_eq!(holding_result(&app), result::REFERENCE_PENDING);
    rig.set_all(22 * 16);
    rig.app_cycle(&mut app);
    app.poll_flash();
    assert_eq!(reference(&mut app), vec![22 * 16; 6], "measured, kept");
    let mut app = power_cycle(&rig, &mut app);
    rig.app_cycle(&mut app);
    assert_eq!(
        reference(&mut app),
        vec![22 * 16; 6],
        "kept over the image's"
    );
    // Command 11: the image's own reference again from the next boot on.
    command(&mut app, CMD_FORGET_REFERENCE);
    app.poll_flash();
    let mut app = power_cycle(&rig, &mut app);
    rig.app_cycle(&mut app);
    assert_eq!(reference(&mut app), vec![20 * 16; 6]);
}

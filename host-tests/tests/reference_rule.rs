//! The probe-reference rule's parameters in holding registers 90–99 (issue
//! 51 item 5), over the application's Modbus requests on the pin-level
//! 1-Wire emulator and the mock flash: with the registers set, every
//! reference and every served correction equals `thermocomp_core::reference`
//! run here with the same parameters (bit for bit), also after a change in
//! the middle and after a power cycle (the registers are stored); a value
//! outside a register's range is refused with exception 03 and changes
//! nothing; 0xFFFF is the firmware's default; command 7 restores them all.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{
    self, demo_image, read_holding, read_inputs, write_n, write_unlocked, Reply, SLOT,
};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::ProbeReading;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp_core::reference::{ReferenceOutcome, ReferenceParams, ReferenceState};
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::IR_REF_ACCEPTED;
use thermocomp_protocol::states::ProbeState;

/// The registers this test sets, and the parameters they mean (written out
/// by hand from the units in docs/register-map.md, not through the codec).
const SET: [u16; 10] = [50, 250, 90, 150, 45, 35, 2_500, 1_500, 4_000, 1_000];
const SET_PARAMS: ReferenceParams = ReferenceParams {
    sigma_ref_nm: 500,
    sigma_bias_nm: 2_500,
    tau_bias_s: 90 * 60,
    sigma_rate_nm_h: 1_500,
    tau_rate_s: 45 * 60,
    gate_k_x10: 35,
    gate_abs_nm: 25_000,
    max_step_nm: 15_000,
    max_bias_nm: 40_000,
    max_rate_nm_h: 10_000,
};
/// The firmware's defaults as the registers read them.
const DEFAULT_REGS: [u16; 10] = [30, 300, 240, 200, 120, 40, 3_000, 2_000, 5_000, 2_000];

struct Rig {
    bus: Bus,
    acq: TemperatureAcquisition,
    n: i16,
}

impl Rig {
    fn new() -> Rig {
        let bus = bus_with_sensors(6, 0x2EF_0515, 20 * 16);
        let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        Rig { bus, acq, n: 0 }
    }

    /// 10 s on, the sensors warmed a little, one acquisition and one
    /// application cycle: the time and the compensator's own correction of
    /// direction 0 (before the reference terms).
    fn cycle(&mut self, app: &mut App<MockFlash>) -> (u64, i32) {
        self.n += 1;
        let warm = (self.n / 20).min(200);
        for k in 0..6 {
            self.bus
                .with_device(k, |d| d.temperature = 20 * 16 + warm * (k as i16 + 1));
        }
        self.bus.advance_ns(10_000 * MS);
        let now = self.bus.now_ms();
        block_on(
            self.acq
                .cycle(&mut master(&self.bus), &mut self.bus.delay(), now),
        );
        let out = app.cycle(&self.acq, now, now, Some(3000));
        app.poll_flash();
        (now, out.corrections[0])
    }
}

fn settle(app: &mut App<MockFlash>) {
    while app.poll_flash() {}
}

/// Unlock, then FC16 of `values` from `addr`; the reply.
fn write_block(app: &mut App<MockFlash>, addr: u16, values: &[u16]) -> Reply {
    write_unlocked(app, HR_UNLOCK, host_tests::keys::TEST_UNLOCK_KEY);
    let mut reply = Reply::new();
    app.request(&write_n(1, addr, values), 0, &mut reply);
    reply
}

fn rule_regs(app: &mut App<MockFlash>) -> Vec<u16> {
    read_holding(app, HR_RULE, RULE_REGS, 0)
}

fn board(rig: &Rig, flash: MockFlash) -> App<MockFlash> {
    let mut app = modbus::boot(flash, *rig.acq.map());
    if app.model().is_none() {
        app.program(&demo_image(1, 1)).unwrap();
    }
    app
}

/// The board and the host's rule, side by side: the board's state of
/// direction 0 and the host's (the same rule, run here).
struct Twin {
    host: ReferenceState,
    max: i32,
}

impl Twin {
    /// One cycle; with `offset` (0.1 µm) a probe reference that far off the
    /// model, checked against the host's outcome. Then the served
    /// correction and input registers 304–306 against the host's; the
    /// time and the compensator's correction (before the terms).
    fn step(
        &mut self,
        rig: &mut Rig,
        app: &mut App<MockFlash>,
        p: &ReferenceParams,
        offset: Option<i32>,
    ) -> (u64, i32) {
        if offset.is_some() {
            write_unlocked(app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
        }
        let (now, model) = rig.cycle(app);
        if let Some(offset) = offset {
            let reading = ProbeReading {
                state: ProbeState::Ok,
                tenth_um: Some(model + offset),
                mean_x16: 0,
                min_code: 100,
                max_code: 200,
            };
            app.set_probe(&reading, Some((&rig.acq, now)));
            settle(app);
            let expected = match self.host.reference(p, now, model, model + offset) {
                ReferenceOutcome::Accepted { .. } => result::OK,
                ReferenceOutcome::Refused { .. } => result::REFERENCE_REFUSED,
            };
            assert_eq!(app.result(), expected, "reference at {now} ms");
        }
        let served = self.host.serve(p, now, model, self.max);
        assert_eq!(app.snapshot().corrections[0], served, "served at {now} ms");
        let (b, _) = self.host.terms_at(p, now);
        let regs = read_inputs(app, IR_REF_ACCEPTED, 3, now);
        let bias = (b + if b < 0 { -50 } else { 50 }) / 100;
        assert_eq!(
            regs,
            vec![self.host.accepted, self.host.refused, bias as i16 as u16],
            "input registers 304-306 at {now} ms"
        );
        (now, model)
    }
}

/// References every 30 min, some of them far off (refused by the set gate).
fn offset_at(i: usize) -> Option<i32> {
    const OFFSETS: [i32; 6] = [40, -25, 160, 90, -60, 30];
    (i % 180 == 90).then(|| OFFSETS[(i / 180) % OFFSETS.len()])
}

#[test]
fn the_registers_set_the_rule_bit_for_bit_and_a_power_cycle_keeps_them() {
    let mut rig = Rig::new();
    let mut app = board(&rig, MockFlash::new(2 * SLOT as usize));
    let reply = write_unlocked(&mut app, HR_PROBE_DIRECTION, 0);
    assert_eq!(reply[1], 6, "{reply:02x?}");
    settle(&mut app);
    assert_eq!(rule_regs(&mut app), DEFAULT_REGS, "the defaults in force");
    let reply = write_block(&mut app, HR_RULE, &SET);
    assert_eq!(reply[1], 16, "{reply:02x?}");
    settle(&mut app);
    assert_eq!(app.result(), result::OK, "stored");
    assert_eq!(rule_regs(&mut app), SET);
    let max = app.model().unwrap().directions[0].max_correction;
    let mut twin = Twin {
        host: ReferenceState::new(&SET_PARAMS),
        max,
    };
    // The same references under the defaults: the set parameters must
    // make a difference, or this test could not fail.
    let mut under_default = ReferenceState::new(&ReferenceParams::DEFAULT);
    let mut differs = false;
    let mut p = SET_PARAMS;
    for i in 0..1_080 {
        if i == 540 {
            // τ_b to 30 min in the middle: the terms go on from what they
            // learned, with the new time constant.
            let reply = write_unlocked(&mut app, HR_RULE + 2, 30);
            assert_eq!(reply[1], 6, "{reply:02x?}");
            settle(&mut app);
            p.tau_bias_s = 30 * 60;
        }
        let offset = offset_at(i);
        let (now, model) = twin.step(&mut rig, &mut app, &p, offset);
        if let Some(o) = offset {
            let _ = under_default.reference(&ReferenceParams::DEFAULT, now, model, model + o);
        }
        differs |= under_default.bias_nm != twin.host.bias_nm;
    }
    assert!(differs, "the set parameters changed nothing");
    assert!(
        twin.host.accepted >= 3 && twin.host.refused >= 1,
        "{:?}",
        twin.host
    );

    // A power cycle: the registers come back, the terms resume (their last
    // reference taken as made at the first cycle), the rule is the set one.
    settle(&mut app);
    let mut app = modbus::power_cycle(&mut app, *rig.acq.map());
    let mut regs = SET;
    regs[2] = 30;
    assert_eq!(rule_regs(&mut app), regs, "stored");
    twin.host.last_ms = Some(rig.bus.now_ms() + 10_000);
    for i in 0..200 {
        let offset = (i == 60 || i == 120).then_some(if i == 60 { 50 } else { 260 });
        twin.step(&mut rig, &mut app, &p, offset);
    }
}

#[test]
fn a_value_out_of_range_is_refused_and_changes_nothing() {
    let rig = Rig::new();
    let mut app = board(&rig, MockFlash::new(2 * SLOT as usize));
    let reply = write_block(&mut app, HR_RULE, &SET);
    assert_eq!(reply[1], 16, "{reply:02x?}");
    settle(&mut app);
    // τ_b or τ_s of 0 min, gate k above 6000: exception 03, nothing changed.
    for (k, v) in [(2, 0), (4, 0), (5, 60_001)] {
        let reply = write_unlocked(&mut app, HR_RULE + k, v);
        assert_eq!(&reply[1..3], &[0x86, 3], "register {} = {v}", HR_RULE + k);
        assert_eq!(rule_regs(&mut app), SET);
    }
    // A block with one bad value: the whole write is refused.
    let mut bad = DEFAULT_REGS;
    bad[4] = 0;
    let reply = write_block(&mut app, HR_RULE, &bad);
    assert_eq!(&reply[1..3], &[0x90, 3], "{reply:02x?}");
    assert_eq!(rule_regs(&mut app), SET);
    // Locked: exception 01.
    let mut reply = Reply::new();
    app.request(&modbus::write1(1, HR_RULE, 7), 0, &mut reply);
    assert_eq!(&reply[1..3], &[0x86, 1], "locked");
    // The edges are taken; 0xFFFF is the default (read as its value).
    for (k, v) in [(5u16, 60_000u16), (0, 0), (3, 0), (2, 1), (9, 65_534)] {
        let reply = write_unlocked(&mut app, HR_RULE + k, v);
        assert_eq!(reply[1], 6, "register {} = {v}: {reply:02x?}", HR_RULE + k);
        settle(&mut app);
    }
    let reply = write_unlocked(&mut app, HR_RULE + 6, 0xFFFF);
    assert_eq!(reply[1], 6);
    settle(&mut app);
    let expect = [0, 250, 1, 0, 45, 60_000, 3_000, 1_500, 4_000, 65_534];
    assert_eq!(rule_regs(&mut app), expect);
    // Past the block: no register.
    let mut reply = Reply::new();
    app.request(&modbus::read(1, 3, HR_LAST_RULE, 2), 0, &mut reply);
    assert_eq!(&reply[1..3], &[0x83, 2], "past the map");
    // A new model keeps them; a power cycle too; command 7 restores the
    // defaults, stored.
    app.program(&demo_image(2, 2)).unwrap();
    settle(&mut app);
    let mut app = modbus::power_cycle(&mut app, *rig.acq.map());
    assert_eq!(rule_regs(&mut app), expect);
    write_unlocked(&mut app, HR_COMMAND, CMD_RESTORE_DEFAULTS);
    settle(&mut app);
    assert_eq!(rule_regs(&mut app), DEFAULT_REGS);
    let mut app = modbus::power_cycle(&mut app, *rig.acq.map());
    assert_eq!(rule_regs(&mut app), DEFAULT_REGS);
}

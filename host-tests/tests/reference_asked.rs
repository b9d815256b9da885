//! The board asks for a probe reference (issue 51, item 3): holding
//! registers 46–48 set the rule, input register 23 says what is wanted and
//! why, at exactly the cycles `thermocomp_core::ask` (which `tcomp replay
//! --reference-when-asked` runs) says; an accepted reference clears it, a
//! refused one does not; a power cycle keeps the rule's settings and a
//! raised request; all three registers 0 (the default) or no probe
//! direction: the board never asks.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{self, demo_image, read_holding, read_inputs, write_unlocked, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::ProbeReading;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp_core::ask::{AskParams, AskReason, AskState};
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::IR_REF_WANTED;
use thermocomp_protocol::states::ProbeState;

const MIN: u64 = 60_000;

struct Rig {
    _bus: Bus,
    acq: TemperatureAcquisition,
}

impl Rig {
    fn new() -> Rig {
        let bus = bus_with_sensors(6, 0x2EF_0051, 20 * 16);
        let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        Rig { _bus: bus, acq }
    }
}

fn settle(app: &mut App<MockFlash>) {
    while app.poll_flash() {}
}

fn set(app: &mut App<MockFlash>, addr: u16, v: u16) {
    let reply = write_unlocked(app, addr, v);
    assert_eq!(reply[1], 6, "write {addr} = {v}: {reply:02x?}");
    settle(app);
    assert_eq!(app.result(), result::OK, "stored");
}

fn board(rig: &Rig, params: Option<AskParams>, direction: bool) -> App<MockFlash> {
    let mut app = modbus::boot(MockFlash::new(2 * SLOT as usize), *rig.acq.map());
    app.program(&demo_image(1, 1)).unwrap();
    app.update_channel_map(*rig.acq.map());
    settle(&mut app);
    if direction {
        set(&mut app, HR_PROBE_DIRECTION, 0);
    }
    if let Some(p) = params {
        set(&mut app, HR_ASK_SETTLE, p.settle_s);
        set(&mut app, HR_ASK_INTERVAL, p.max_interval_s);
        set(&mut app, HR_ASK_SPEED_STEP, p.speed_step_rpm);
    }
    app
}

fn wanted(app: &mut App<MockFlash>) -> u16 {
    read_inputs(app, IR_REF_WANTED, 1, 0)[0]
}

/// The spindle schedule: 1,000 rpm, 3,000 from 20 min, 500 from 100 min.
fn rpm_at(t: u64) -> i32 {
    match t {
        t if t < 20 * MIN => 1000,
        t if t < 100 * MIN => 3000,
        _ => 500,
    }
}

/// One cycle at `t` with the spindle at `rpm` (the PLC's register on the
/// bench board is replaced by the trace's speed the same way).
fn cycle(app: &mut App<MockFlash>, rig: &Rig, t: u64, rpm: i32) -> i32 {
    let out = app.cycle(&rig.acq, t, t, Some(rpm));
    app.poll_flash();
    out.corrections[0]
}

/// Command 12 and the probe's reading `offset` (0.1 µm) off the model's
/// served output at `t`: the result code.
fn reference(app: &mut App<MockFlash>, rig: &Rig, t: u64, offset: i32) -> u16 {
    write_unlocked(app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    let model = cycle(app, rig, t, rpm_at(t));
    let reading = ProbeReading {
        state: ProbeState::Ok,
        tenth_um: Some(model + offset),
        mean_x16: 0,
        min_code: 100,
        max_code: 200,
    };
    app.set_probe(&reading, Some((&rig.acq, t)));
    settle(app);
    app.result()
}

#[test]
fn the_board_asks_when_the_rule_says_and_only_an_accepted_reference_clears_it() {
    let rig = Rig::new();
    let p = AskParams::SUGGESTED;
    let mut app = board(&rig, Some(p), true);
    let t0 = 10 * MIN;
    let mut rule = AskState::new(t0);
    let (mut raised, mut taken, mut refused_once) = (vec![], 0, false);
    let mut t = t0;
    while t < t0 + 5 * 60 * MIN {
        let rpm = rpm_at(t - t0);
        cycle(&mut app, &rig, t, rpm);
        if rule.step(&p, t, Some(rpm)) {
            raised.push((t - t0, rule.wanted()));
        }
        assert_eq!(
            wanted(&mut app),
            rule.wanted() as u16,
            "at {} s",
            (t - t0) / 1000
        );
        if rule.wanted() != AskReason::None {
            // The PLC probes a minute after it sees the request; the
            // first time with a chip on the gauge (refused: still wanted).
            t += MIN;
            let offset = if refused_once { 20 } else { 900_000 };
            let code = reference(&mut app, &rig, t, offset);
            if refused_once {
                assert_eq!(code, result::OK);
                rule.referenced(&p, t);
                taken += 1;
            } else {
                assert_eq!(code, result::REFERENCE_REFUSED);
                refused_once = true;
            }
            assert_eq!(
                wanted(&mut app),
                rule.wanted() as u16,
                "after the reference"
            );
        }
        t += 10_000;
    }
    // The speed change at 20 min: asked 15 min on; then the interval; the
    // change at 100 min: asked 15 min on.
    let reasons: Vec<AskReason> = raised.iter().map(|r| r.1).collect();
    assert!(reasons.contains(&AskReason::SpeedChange), "{raised:?}");
    assert!(reasons.contains(&AskReason::Interval), "{raised:?}");
    assert_eq!(raised[0], (35 * MIN, AskReason::SpeedChange), "{raised:?}");
    assert!(taken >= 3, "{taken} references taken: {raised:?}");
}

#[test]
fn a_power_cycle_keeps_the_rule_and_a_raised_request() {
    let rig = Rig::new();
    let p = AskParams {
        settle_s: 600,
        max_interval_s: 1800,
        speed_step_rpm: 300,
    };
    let mut app = board(&rig, Some(p), true);
    let mut t = 0;
    while wanted(&mut app) == 0 {
        t += 10_000;
        cycle(&mut app, &rig, t, 1000);
        assert!(t <= 31 * MIN, "no request by {t} ms");
    }
    assert_eq!(wanted(&mut app), AskReason::Interval as u16);
    settle(&mut app);
    let mut app = modbus::power_cycle(&mut app, *rig.acq.map());
    assert_eq!(
        read_holding(&mut app, HR_ASK_SETTLE, 3, 0),
        vec![600, 1800, 300],
        "the rule's registers"
    );
    // Uptime restarts at 5 s: the request is still raised at the first cycle.
    cycle(&mut app, &rig, 5_000, 1000);
    assert_eq!(wanted(&mut app), AskReason::Interval as u16);
}

#[test]
fn by_default_or_without_a_probe_direction_the_board_never_asks() {
    let rig = Rig::new();
    for (params, direction) in [(None, true), (Some(AskParams::SUGGESTED), false)] {
        let mut app = board(&rig, params, direction);
        if params.is_none() {
            assert_eq!(read_holding(&mut app, HR_ASK_SETTLE, 3, 0), vec![0, 0, 0]);
        }
        let mut t = 0;
        while t < 10 * 60 * MIN {
            t += 30_000;
            let rpm = if (t / (7 * MIN)).is_multiple_of(2) {
                800
            } else {
                4000
            };
            cycle(&mut app, &rig, t, rpm);
            assert_eq!(
                wanted(&mut app),
                0,
                "{params:?}, direction {direction}, {t} ms"
            );
        }
    }
}

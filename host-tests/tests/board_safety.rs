//! The board's fault path and watchdog rule on the host: the fault record's
//! RAM format (magic + CRC, counting), the order safe state → record →
//! reset, the rule for feeding the watchdog, and the record served over
//! Modbus until command 6 clears it.
use std::cell::RefCell;

use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{blank_app, frame, read_inputs, write1, Reply};
use thermocomp::app::{App, LinkChange};
use thermocomp::fault::{self, kind, FaultBoard, FaultRecord, WORDS};
use thermocomp::watchdog::{stalled, Feeder, Progress};
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;

thread_local! {
    static RAM: RefCell<[u32; WORDS]> = const { RefCell::new([0; WORDS]) };
    static EVENTS: RefCell<Vec<&'static str>> = const { RefCell::new(Vec::new()) };
}

/// A board whose "RAM" survives the simulated reset (a panic caught below).
struct HostBoard;

impl FaultBoard for HostBoard {
    fn safe_state() {
        EVENTS.with(|e| e.borrow_mut().push("safe_state"));
    }
    fn uptime_ms() -> u64 {
        123_456
    }
    fn load() -> [u32; WORDS] {
        RAM.with(|r| *r.borrow())
    }
    fn store(words: &[u32; WORDS]) {
        EVENTS.with(|e| e.borrow_mut().push("store"));
        RAM.with(|r| *r.borrow_mut() = *words);
    }
    fn reset() -> ! {
        EVENTS.with(|e| e.borrow_mut().push("reset"));
        std::panic::panic_any("reset")
    }
}

fn crash(k: u16, pc: u32, detail: u32) {
    let r = std::panic::catch_unwind(|| {
        fault::fault::<HostBoard>(k, pc, detail);
    });
    assert_eq!(
        r.err().and_then(|e| e.downcast_ref::<&str>().copied()),
        Some("reset")
    );
}

#[test]
fn record_round_trips_and_rejects_power_on_contents_and_bit_flips() {
    let r = FaultRecord {
        kind: kind::HARD_FAULT,
        pc: 0x0000_1234,
        uptime_ms: 5_000_000_123,
        count: 3,
        detail: 0x8200,
    };
    let w = r.encode();
    assert_eq!(FaultRecord::decode(&w), Some(r));
    assert_eq!(FaultRecord::decode(&[0; WORDS]), None, "zeroed RAM");
    assert_eq!(FaultRecord::decode(&[0xFFFF_FFFF; WORDS]), None);
    for word in 0..WORDS {
        for bit in [0, 7, 31] {
            let mut bad = w;
            bad[word] ^= 1 << bit;
            assert_eq!(FaultRecord::decode(&bad), None, "word {word} bit {bit}");
        }
    }
}

#[test]
fn a_fault_drives_the_safe_state_first_then_records_then_resets_and_counts() {
    RAM.with(|r| *r.borrow_mut() = [0xDEAD_BEEF; WORDS]); // power-on garbage
    EVENTS.with(|e| e.borrow_mut().clear());
    crash(kind::PANIC, 0, 42);
    assert_eq!(
        EVENTS.with(|e| e.borrow().clone()),
        ["safe_state", "store", "reset"]
    );
    let r = fault::recorded::<HostBoard>().expect("a record after the reset");
    assert_eq!((r.kind, r.pc, r.detail, r.count), (kind::PANIC, 0, 42, 1));
    assert_eq!(r.uptime_ms, 123_456);
    crash(kind::WATCHDOG, 0x0800_0100, stalled::MEASUREMENT);
    let r = fault::recorded::<HostBoard>().unwrap();
    assert_eq!((r.kind, r.pc, r.count), (kind::WATCHDOG, 0x0800_0100, 2));
    fault::clear::<HostBoard>();
    assert_eq!(fault::recorded::<HostBoard>(), None);
    crash(kind::INIT_FAILED, 0, fault::init_step::UART);
    assert_eq!(
        fault::recorded::<HostBoard>().unwrap().count,
        1,
        "counts from 1 after a clear"
    );
}

#[test]
fn the_watchdog_is_fed_only_when_both_activities_progressed() {
    let mut p = Progress::default();
    let mut f = Feeder::new(&p);
    // Nothing happened yet: the measurement loop has not made progress.
    assert_eq!(f.check(&p), Err(stalled::MEASUREMENT));
    // A cycle, Modbus idle (no master on the bus): feed.
    p.cycles += 1;
    assert_eq!(f.check(&p), Ok(()));
    // Modbus busy with one request since the last feed and no reply: not fed,
    // however many cycles run.
    p.modbus_busy = true;
    for _ in 0..5 {
        p.cycles += 1;
        assert_eq!(f.check(&p), Err(stalled::MODBUS));
    }
    // The request finishes: fed again.
    p.requests += 1;
    assert_eq!(f.check(&p), Ok(()));
    // Modbus busy but it made progress since the feed, and a cycle ran: fed.
    p.requests += 1;
    p.cycles += 1;
    assert_eq!(f.check(&p), Ok(()));
    // Both stalled.
    assert_eq!(f.check(&p), Err(stalled::MEASUREMENT | stalled::MODBUS));
    // Counters wrap without a false stall.
    let mut p = Progress {
        cycles: u32::MAX,
        ..Progress::default()
    };
    let mut f = Feeder::new(&p);
    p.cycles = p.cycles.wrapping_add(1);
    assert_eq!(f.check(&p), Ok(()));
}

fn app() -> App<MockFlash> {
    let mut app = blank_app();
    host_tests::commission(&mut app);
    app
}

#[test]
fn the_record_is_served_with_status_bit_9_until_command_6() {
    let mut app = app();
    assert_eq!(read_inputs(&mut app, IR_FAULT_KIND, 20, 0), vec![0; 20]);
    assert_eq!(
        read_inputs(&mut app, IR_STATUS, 1, 0)[0] & STATUS_FAULT_RECORDED,
        0
    );
    app.set_fault_record(Some(FaultRecord {
        kind: kind::WATCHDOG,
        pc: 0x0001_2345,
        uptime_ms: 7_250,
        count: 2,
        detail: stalled::MEASUREMENT,
    }));
    let r = read_inputs(&mut app, IR_FAULT_KIND, 20, 0);
    assert_eq!(&r[..9], &[3, 0x0001, 0x2345, 0, 7, 0, 2, 0, 1]);
    assert_eq!(&r[9..], &[0; 11], "reserved");
    assert_ne!(
        read_inputs(&mut app, IR_STATUS, 1, 0)[0] & STATUS_FAULT_RECORDED,
        0
    );
    // The register after the map's last one is past the map.
    let mut reply = Reply::new();
    let [hi, lo] = IR_LAST.to_be_bytes();
    app.request(&frame(&[1, 4, hi, lo, 0, 2]), 0, &mut reply);
    assert_eq!((reply[1], reply[2]), (0x84, 2));
    // Command 6 needs the unlock, like every command.
    app.request(&write1(1, HR_COMMAND, CMD_CLEAR_FAULT), 0, &mut reply);
    assert_eq!(reply[1], 0x86);
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    let change = app.request(&write1(1, HR_COMMAND, CMD_CLEAR_FAULT), 0, &mut reply);
    assert_eq!(
        change,
        LinkChange::ClearFaultRecord,
        "the board clears its RAM copy"
    );
    assert_eq!(read_inputs(&mut app, IR_FAULT_KIND, 9, 0), vec![0; 9]);
    assert_eq!(
        read_inputs(&mut app, IR_STATUS, 1, 0)[0] & STATUS_FAULT_RECORDED,
        0
    );
}

#[test]
fn test_only_commands_are_refused_without_the_feature() {
    // host-tests builds the application without `test-faults`: a field
    // board answers commands 8 and 9 with ILLEGAL DATA VALUE.
    let mut app = app();
    let mut reply = Reply::new();
    // 99: a number without a command (12 and 13 are probe references;
    // 14–16 are allocated to another branch).
    for cmd in [CMD_TEST_PANIC, CMD_TEST_STALL, 99] {
        // Unlocked each time: a refused command locks the board again.
        app.request(
            &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
            0,
            &mut reply,
        );
        let change = app.request(&write1(1, HR_COMMAND, cmd), 0, &mut reply);
        assert_eq!((reply[1], reply[2]), (0x86, 3), "command {cmd}");
        assert_eq!(change, LinkChange::None);
    }
    assert!(!app.stall_requested());
}

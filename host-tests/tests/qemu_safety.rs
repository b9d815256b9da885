//! A board that is safe in the field, shown on the QEMU bench board with a
//! real Modbus master (pymodbus): an injected panic (test-only command 8)
//! ends in a reset and the fault record is read back over Modbus after it;
//! a stalled measurement loop (test-only command 9) trips the watchdog;
//! settings written over Modbus survive the reboot; a model commit is
//! answered at once and written in the background (the flash model takes
//! the real 1 s erase) while the measurement loop keeps its period.
use std::time::{Duration, Instant};

use host_tests::qemu::{
    export_demo, modbus_master as python, one_board, warming_trace, BenchBoard, BOOT, SERVING,
};
use serde_json::Value;

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("thermocomp-safety-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A long trace (the board must still be replaying when the test ends) and
/// the demo model.
fn files(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let (t, m) = (dir.join("trace.csv"), dir.join("model.img"));
    warming_trace(&t, 5000, 0.0001);
    export_demo(1, 1, &m);
    (t, m)
}

fn boot(dir: &std::path::Path) -> (BenchBoard, u16) {
    boot_paced(dir, "50")
}

fn boot_paced(dir: &std::path::Path, pace_ms: &str) -> (BenchBoard, u16) {
    boot_with(dir, &[pace_ms])
}

fn boot_with(dir: &std::path::Path, extra: &[&str]) -> (BenchBoard, u16) {
    let (t, m) = files(dir);
    BenchBoard::serve_tcp(&t, &m, extra)
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn an_injected_panic_resets_the_board_and_the_record_is_read_back_over_modbus() {
    let _one = one_board();
    let (board, port) = boot(&scratch("panic"));
    let p = port.to_string();
    let before = python(&["fault", "--port", &p]);
    assert_eq!(before["kind"], 0, "{before}");
    assert_eq!(before["status"].as_u64().unwrap() & (1 << 9), 0, "{before}");
    // Command 8: answered, then the panic; the fault path resets the board.
    let cmd = python(&["command", "--port", &p, "--code", "8"]);
    assert_eq!(cmd["exception"], Value::Null, "{cmd}");
    board.wait_for_boots(2, BOOT);
    let log = board.log();
    assert!(log.contains("test panic requested by command 8"), "{log}");
    let after = python(&["fault", "--port", &p]);
    println!("{after}");
    assert_eq!(after["kind"], 1, "panic: {after}");
    assert_eq!(after["count"], 1, "{after}");
    assert!(
        after["detail"].as_u64().unwrap() > 0,
        "source line: {after}"
    );
    assert_ne!(
        after["status"].as_u64().unwrap() & (1 << 9),
        0,
        "FAULT_RECORDED: {after}"
    );
    // The board serves normally after the reset: model and test pattern.
    let snap = &python(&["read", "--port", &p])[0];
    assert_eq!(snap["pattern"], 0x1234_5678, "{snap}");
    assert_eq!(snap["model_version"], 1, "{snap}");
    // A second panic counts on.
    python(&["command", "--port", &p, "--code", "8"]);
    board.wait_for_boots(3, BOOT);
    assert_eq!(python(&["fault", "--port", &p])["count"], 2);
    // Command 6 clears the record and the status bit; it stays cleared.
    let clear = python(&["command", "--port", &p, "--code", "6"]);
    assert_eq!(clear["exception"], Value::Null, "{clear}");
    let cleared = python(&["fault", "--port", &p]);
    assert_eq!(cleared["kind"], 0, "{cleared}");
    assert_eq!(cleared["count"], 0, "{cleared}");
    assert_eq!(
        cleared["status"].as_u64().unwrap() & (1 << 9),
        0,
        "{cleared}"
    );
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn a_stalled_measurement_loop_trips_the_watchdog_and_the_record_says_so() {
    let _one = one_board();
    let (board, port) = boot(&scratch("watchdog"));
    let p = port.to_string();
    // Fed while both tasks run: several timeouts' worth of serving, no reset.
    std::thread::sleep(Duration::from_secs(9));
    let ok = python(&["read", "--port", &p, "--samples", "5"]);
    assert_eq!(ok.as_array().unwrap().len(), 5);
    assert_eq!(board.log().matches(SERVING).count(), 1, "{}", board.log());
    // Command 9: the measurement loop stops; Modbus keeps answering.
    let cmd = python(&["command", "--port", &p, "--code", "9"]);
    assert_eq!(cmd["exception"], Value::Null, "{cmd}");
    let stalled_at = Instant::now();
    std::thread::sleep(Duration::from_secs(1));
    let still = python(&["read", "--port", &p]);
    assert_eq!(
        still[0]["pattern"], 0x1234_5678,
        "Modbus still serves while stalled"
    );
    let took = stalled_at.elapsed() + board.wait_for_boots(2, BOOT);
    println!("watchdog reset {took:?} after the stall");
    // The 4 s timeout, and not much more (feeder period, host load).
    assert!(took >= Duration::from_millis(3_900), "{took:?}");
    assert!(took < Duration::from_secs(15), "{took:?}");
    let log = board.log();
    assert!(log.contains("watchdog expired at pc="), "{log}");
    let rec = python(&["fault", "--port", &p]);
    println!("{rec}");
    assert_eq!(rec["kind"], 3, "watchdog: {rec}");
    assert_eq!(rec["count"], 1, "{rec}");
    assert_eq!(rec["detail"], 1, "the measurement loop, not Modbus: {rec}");
    assert_ne!(rec["pc"], 0, "the interrupted PC: {rec}");
    assert_ne!(rec["status"].as_u64().unwrap() & (1 << 9), 0, "{rec}");
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn settings_written_over_modbus_survive_a_reboot_and_command_7_restores_defaults() {
    let _one = one_board();
    let (board, port) = boot(&scratch("settings"));
    let p = port.to_string();
    // Clamp direction 0 to 12.3 µm, rate of direction 1 to 5.0 µm/s, unit 7.
    let w = python(&[
        "hold",
        "--port",
        &p,
        "--write",
        "20=123",
        "--write",
        "27=50",
        "--write",
        "3=7",
        "--no-read",
    ]);
    assert_eq!(w["exceptions"], serde_json::json!({}), "{w}");
    // Wait until they are in flash (HR_RESULT 23 → 0), then reboot (the
    // panic command, at the new unit address).
    let cmd = python(&["hold", "--port", &p, "--unit", "7", "--write", "0=0x7E57"]);
    assert_eq!(cmd["registers"][3], 7, "{cmd}");
    assert_eq!(cmd["registers"][2], 0, "stored: {cmd}");
    let panic = python(&["command", "--port", &p, "--unit", "7", "--code", "8"]);
    assert_eq!(panic["exception"], Value::Null, "{panic}");
    board.wait_for_boots(2, BOOT);
    // The boot log names the stored unit, not the default (issue 30).
    let log = board.log();
    let second = log.rsplit(SERVING).next().unwrap_or_default();
    assert!(
        second.starts_with(" on UART0: unit 7, 115200 baud"),
        "{log}"
    );
    let after = python(&["hold", "--port", &p, "--unit", "7"]);
    let r = &after["registers"];
    assert_eq!(
        (r[3].clone(), r[20].clone(), r[27].clone()),
        (7.into(), 123.into(), 50.into()),
        "{after}"
    );
    assert_eq!(r[21], 0xFFFF, "{after}");
    // Command 7: defaults again (the reply comes from unit 7, then unit 1).
    let w = python(&[
        "hold",
        "--port",
        &p,
        "--unit",
        "7",
        "--write",
        "1=7",
        "--no-read",
    ]);
    assert_eq!(w["exceptions"], serde_json::json!({}), "{w}");
    let d = python(&["hold", "--port", &p]);
    let r = &d["registers"];
    assert_eq!(
        (r[3].clone(), r[20].clone(), r[27].clone()),
        (1.into(), 0xFFFF.into(), 0xFFFF.into()),
        "{d}"
    );
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn a_model_commit_is_answered_within_100_ms_while_the_loop_keeps_its_period() {
    let _one = one_board();
    let dir = scratch("commit");
    // One sample per second, as on the NUCLEO.
    let (board, port) = boot_paced(&dir, "1000");
    let v2 = dir.join("v2.img");
    let mut fm = thermocomp_core::float::demo_model(2);
    fm.model_version = 2;
    tcomp_model::export::export(&fm, &v2).unwrap();
    let p = port.to_string();
    let r = python(&[
        "upload",
        "--port",
        &p,
        "--image",
        v2.to_str().unwrap(),
        "--watch",
        "4",
    ]);
    println!("{r}");
    assert_eq!(r["commit_exception"], Value::Null, "{r}");
    assert_eq!(r["result"], 0, "{r}");
    assert_eq!(r["after"]["model_version"], 2, "{r}");
    let reply = r["commit_reply_ms"].as_f64().unwrap();
    assert!(reply < 100.0, "the commit's reply took {reply} ms: {r}");
    // The write really waited for the erase (1 s), outside the lock.
    let done = r["commit_done_ms"].as_f64().unwrap();
    assert!(done >= 1000.0, "{r}");
    let base = r["baseline_max_sample_gap_ms"].as_f64().unwrap();
    let during = r["commit_max_sample_gap_ms"].as_f64().unwrap();
    assert!(
        base > 900.0 && base < 1600.0,
        "period before the commit: {r}"
    );
    assert!(
        during < base + 300.0,
        "the loop kept its period during the commit: {r}"
    );
    // A reset keeps the uploaded model: the command line's version 1 is
    // programmed only into blank slots (issue 30).
    let panic = python(&["command", "--port", &p, "--code", "8"]);
    assert_eq!(panic["exception"], Value::Null, "{panic}");
    board.wait_for_boots(2, BOOT);
    let snap = &python(&["read", "--port", &p])[0];
    assert_eq!(snap["model_version"], 2, "{snap}\n{}", board.log());
    assert!(
        board
            .log()
            .contains("not programmed: the flash slots hold version 2"),
        "{}",
        board.log()
    );
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn a_swapped_sensor_is_reported_missing_and_new_and_the_model_never_reads_it() {
    let _one = one_board();
    // Sensor 2 (channel 2, the model's third input) is swapped at row 20.
    let (board, port) = boot_with(&scratch("swap"), &["50", "swap=2@20"]);
    let p = port.to_string();
    let start = Instant::now();
    let regs = loop {
        let r = python(&["inputs", "--port", &p, "--addr", "170", "--count", "4"]);
        let w: Vec<u64> = r
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        if w[1] != 0 && w[3] != 0 {
            break w;
        }
        assert!(start.elapsed() < BOOT, "no swap seen:\n{}", board.log());
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(
        regs,
        [0, 1 << 2, 0, 1 << 6],
        "missing: channel 2; added: channel 6"
    );
    // Channel 2 reads "no presence"/"disconnected" and no temperature; the new sensor's
    // value is on channel 6 (and only there): the model's input on channel 2
    // is a sensor fault, never the new sensor's reading.
    std::thread::sleep(Duration::from_secs(2));
    let states = python(&["inputs", "--port", &p, "--addr", "130", "--count", "7"]);
    // 3 no presence / 7 disconnected: the ROM code does not answer.
    assert!(states[2] == 3 || states[2] == 7, "{states}");
    assert_eq!(states[6], 2, "the new sensor is ok: {states}");
    let temps = python(&["inputs", "--port", &p, "--addr", "110", "--count", "7"]);
    assert_eq!(temps[2], 0x8000, "{temps}");
    assert_ne!(temps[6], 0x8000, "{temps}");
    let status = python(&["inputs", "--port", &p, "--addr", "3"])[0]
        .as_u64()
        .unwrap();
    assert_ne!(status & 0x2, 0, "SENSOR_FAULT: {status:#x}");
}

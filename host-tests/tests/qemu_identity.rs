//! Sensor identity on the QEMU bench board (issue 12, item 3), with the
//! real masters of `tcomp`: `record` reads the emulated sensors' ROM codes
//! (input registers 200–279) into the run's metadata, `export` names the
//! model's sensors by them, `upload` commits the image; then a sensor is
//! swapped on the emulated bus: the model sensor that named it is reported
//! missing (290–291, 170–171), the new sensor is added on a free channel
//! (172–173) without renumbering, and the board serves a sensor fault —
//! never the new sensor's reading.
use std::time::{Duration, Instant};

use host_tests::qemu::{export_demo, one_board, warming_trace, BenchBoard, BOOT};
use tcomp_link::board_link::{record, upload, BoardLink, Commit};
use thermocomp_protocol::registers::*;

fn u32_of(w: &[u16]) -> u32 {
    u32::from(w[0]) << 16 | u32::from(w[1])
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn a_model_named_by_rom_codes_survives_a_swap_on_the_bench_board() {
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-qemu-rom-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (trace, v1, v2) = (
        dir.join("trace.csv"),
        dir.join("v1.img"),
        dir.join("v2.img"),
    );
    warming_trace(&trace, 5000, 0.0001);
    export_demo(1, 1, &v1);
    // Sensor 2 is swapped for a new one at row 300 (15 s of serving at 50 ms a row).
    let (board, port) = BenchBoard::serve_tcp(&trace, &v1, &["50", "swap=2@300"]);
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    // The calibration run: record names each column by its sensor's ROM code.
    let run_path = dir.join("recorded.csv");
    record(&mut link, &run_path, Duration::from_millis(200), 2, false).unwrap();
    let run = tcomp_data::runcsv::Run::read(&run_path).unwrap();
    let roms = run.sensor_roms().unwrap();
    assert_eq!(roms.len(), 6, "{:?}\n{}", run.meta, board.log());
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    assert_eq!(columns, ["T01", "T02", "T03", "T04", "T05", "T06"]);
    let mut fm = thermocomp_core::float::demo_model(2);
    fm.model_version = 2;
    assert_eq!(
        tcomp_model::export::name_sensors_by_rom(&mut fm, &columns, &roms).unwrap(),
        6
    );
    let summary = tcomp_model::export::export(&fm, &v2).unwrap();
    assert_eq!(summary.sensors_by_rom, 6);
    host_tests::commission_link(&mut link);
    let opts = host_tests::upload_opts(Commit::NewerOnly, false);
    let s = upload(&mut link, &std::fs::read(&v2).unwrap(), &opts).unwrap();
    assert_eq!(s.model_version, 2);
    // Model sensor i reads channel i (the channels its ROM codes are on).
    assert_eq!(
        link.read_inputs(IR_SENSOR_CHANNELS, 3).unwrap(),
        vec![0x0001, 0x0203, 0x0405]
    );
    let old_rom_2 = link.read_inputs(IR_CHANNEL_ROMS + 8, 4).unwrap();
    // Wait for the swap to be seen.
    let start = Instant::now();
    loop {
        let missing = u32_of(&link.read_inputs(IR_SENSORS_MISSING, 2).unwrap());
        if missing != 0 {
            assert_eq!(missing, 1 << 2, "model sensor 2 is missing");
            break;
        }
        assert!(start.elapsed() < BOOT, "no swap seen:\n{}", board.log());
        std::thread::sleep(Duration::from_millis(200));
    }
    let start = Instant::now();
    let map = loop {
        let w = link.read_inputs(IR_MAP_MISSING, 4).unwrap();
        if u32_of(&w[2..]) != 0 {
            break w;
        }
        assert!(
            start.elapsed() < BOOT,
            "no new sensor seen:\n{}",
            board.log()
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(u32_of(&map[..2]), 1 << 2, "channel 2 missing");
    assert_eq!(u32_of(&map[2..]), 1 << 6, "the new sensor on channel 6");
    // Nothing renumbered: the old ROM stays on channel 2, sensor 2 still names it.
    assert_eq!(link.read_inputs(IR_CHANNEL_ROMS + 8, 4).unwrap(), old_rom_2);
    let new_rom = link.read_inputs(IR_CHANNEL_ROMS + 24, 4).unwrap();
    assert_ne!(new_rom, vec![0; 4]);
    assert_ne!(new_rom, old_rom_2);
    assert_eq!(
        link.read_inputs(IR_SENSOR_CHANNELS, 3).unwrap(),
        vec![0x0001, 0x0203, 0x0405]
    );
    // A sensor fault is served (the demo image has no fallbacks), while the
    // new sensor reads a temperature on channel 6.
    std::thread::sleep(Duration::from_secs(2));
    let status = link.read_inputs(IR_STATUS, 1).unwrap()[0];
    assert_ne!(status & 0x2, 0, "SENSOR_FAULT: {status:#x}");
    let temps = link.read_inputs(IR_TEMPERATURES, 7).unwrap();
    assert_eq!(temps[2], NOT_AVAILABLE, "{temps:?}");
    assert_ne!(temps[6], NOT_AVAILABLE, "{temps:?}");
}

fn command(link: &mut BoardLink, code: u16) {
    use thermocomp_protocol::holding::{HR_COMMAND, HR_UNLOCK};
    host_tests::commission_link(link);
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(HR_COMMAND, code).unwrap();
}

/// Poll until input register `addr` reads `want`.
fn wait_input(link: &mut BoardLink, board: &BenchBoard, addr: u16, want: u16) {
    let start = Instant::now();
    while link.read_inputs(addr, 1).unwrap()[0] != want {
        assert!(
            start.elapsed() < BOOT,
            "IR {addr} != {want}:\n{}",
            board.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn a_kept_reference_survives_a_reset_of_the_bench_board_until_command_11() {
    let _one = one_board();
    use thermocomp_protocol::holding::{
        result, CMD_FORGET_REFERENCE, CMD_KEEP_REFERENCE, HR_RESULT,
    };
    let dir = std::env::temp_dir().join(format!("thermocomp-qemu-ref-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (trace, img) = (dir.join("trace.csv"), dir.join("v1.img"));
    warming_trace(&trace, 5000, 0.0001);
    export_demo(1, 1, &img);
    let (board, port) = BenchBoard::serve_tcp(&trace, &img, &["50"]);
    let addr = format!("127.0.0.1:{port}");
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    assert_eq!(link.read_inputs(IR_REFERENCE_STATE, 1).unwrap(), vec![0]);
    command(&mut link, CMD_KEEP_REFERENCE);
    wait_input(&mut link, &board, IR_REFERENCE_STATE, 1);
    // Stored (HR_RESULT 23 → 0), then a reset (the test panic, command 8).
    let start = Instant::now();
    while link.read_holdings(HR_RESULT, 1).unwrap()[0] != result::OK {
        assert!(start.elapsed() < BOOT, "{}", board.log());
        std::thread::sleep(Duration::from_millis(100));
    }
    command(&mut link, 8);
    board.wait_for_boots(2, BOOT);
    // (The same connection: QEMU keeps the socket across the guest's reset.)
    assert_eq!(
        link.read_inputs(IR_REFERENCE_STATE, 1).unwrap(),
        vec![1],
        "kept across the reset:\n{}",
        board.log()
    );
    // Command 11: forgotten, and still after the next reset.
    command(&mut link, CMD_FORGET_REFERENCE);
    wait_input(&mut link, &board, IR_REFERENCE_STATE, 0);
    let start = Instant::now();
    while link.read_holdings(HR_RESULT, 1).unwrap()[0] != result::OK {
        assert!(start.elapsed() < BOOT, "{}", board.log());
        std::thread::sleep(Duration::from_millis(100));
    }
    command(&mut link, 8);
    board.wait_for_boots(3, BOOT);
    assert_eq!(link.read_inputs(IR_REFERENCE_STATE, 1).unwrap(), vec![0]);
}

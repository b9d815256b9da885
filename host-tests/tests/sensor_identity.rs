//! Sensors named by ROM code, end to end (issue 12, item 3): a run that
//! records each column's ROM code → `tcomp export` names the model's
//! sensors by ROM → the board (App over the pin-level 1-Wire emulator and
//! the mock flash) reads each model sensor from its own physical sensor:
//! in another channel order, and after a swap (the old sensor reported
//! missing, the new one added on a free channel, nothing renumbered, and
//! the model never reading the new sensor's value). `tcomp record` writes
//! the ROM codes the board serves (input registers 200–279).
use std::collections::BTreeMap;
use std::time::Duration;

use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{app_on_socket, read_inputs, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, Ds18b20, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::rom::RomCode;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition, Validity};
use thermocomp::app::App;
use thermocomp_core::{Compensator, Model, StepInput, StepOutput};
use thermocomp_protocol::registers::*;

fn inputs(app: &mut App<MockFlash>, addr: u16, n: u16) -> Vec<u16> {
    read_inputs(app, addr, n, 0)
}

fn u32_at(app: &mut App<MockFlash>, addr: u16) -> u32 {
    let w = inputs(app, addr, 2);
    u32::from(w[0]) << 16 | u32::from(w[1])
}

/// Six DS18B20s at distinct temperatures (20, 21.5, 23, … °C), so a model
/// sensor reading the wrong one changes the correction.
fn six_sensor_bus() -> Bus {
    let bus = bus_with_sensors(6, 0x1D_E471_7100, 20 * 16);
    for k in 0..6 {
        bus.with_device(k, |d| d.temperature = 20 * 16 + 24 * k as i16);
    }
    bus
}

fn rom_of(bus: &Bus, k: usize) -> RomCode {
    bus.with_device(k, |d| d.rom).unwrap()
}

fn config() -> AcquisitionConfig {
    AcquisitionConfig {
        // A lost sensor's last value is held for 3 s, then invalid.
        hold_ms: 3_000,
        ..AcquisitionConfig::default()
    }
}

/// The run a calibration recorded: columns T01…T06, sensor k on column
/// T0(k+1), each named by its ROM code as `tcomp record` writes them.
fn recorded_run(bus: &Bus) -> tcomp_data::runcsv::Run {
    let mut csv = String::from("time_s,T01,T02,T03,T04,T05,T06,dx_um\n");
    for i in 0..20 {
        csv += &format!("{}", i * 60);
        for k in 0..6 {
            // Each sensor warms at its own rate, so the columns are not interchangeable.
            csv += &format!(
                ",{:.2}",
                20.0 + 1.5 * k as f64 + 0.05 * (k + 1) as f64 * i as f64
            );
        }
        csv += ",0\n";
    }
    let mut run = tcomp_data::runcsv::Run::from_reader(csv.as_bytes()).unwrap();
    for k in 0..6 {
        run.set_sensor_rom(&format!("T{:02}", k + 1), &rom_of(bus, k).0);
    }
    // Written and read back: the metadata survives the file.
    let mut text = Vec::new();
    run.write_to(&mut text).unwrap();
    tcomp_data::runcsv::Run::from_reader(text.as_slice()).unwrap()
}

/// The demo model (six sensors, sensor i trained on column i) named by the
/// run's ROM codes through tcomp's export path; the image bytes.
fn export_by_rom(run: &tcomp_data::runcsv::Run) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(7);
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    let roms = run.sensor_roms().unwrap();
    assert_eq!(
        tcomp_model::export::name_sensors_by_rom(&mut fm, &columns, &roms).unwrap(),
        6
    );
    // a directory of its own: the tests of this file run side by side
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("by-rom.img");
    let summary = tcomp_model::export::export(&fm, &path).unwrap();
    assert_eq!(summary.sensors_by_rom, 6);
    std::fs::read(&path).unwrap()
}

/// The board: acquisition (from a stored map, as the boards search) and the App.
struct Board {
    bus: Bus,
    acq: TemperatureAcquisition,
    app: App<MockFlash>,
    /// What the board must compute: the core fed, per model sensor, the
    /// reading of the channel holding that sensor's ROM (held values and
    /// the stale flag as the board's compensation passes them).
    oracle: Compensator,
}

impl Board {
    fn boot(bus: Bus, map: ChannelMap, image: &[u8]) -> Board {
        let mut acq = TemperatureAcquisition::new(config(), map);
        block_on(acq.discover(&mut master(&bus))).unwrap();
        block_on(acq.configure(&mut master(&bus))).unwrap();
        let mut app = App::new(MockFlash::new(2 * SLOT as usize), SLOT, 1, 115_200, map);
        app.update_channel_map(*acq.map());
        app.program(image).unwrap();
        let oracle = Compensator::new(Some(Model::parse(image).unwrap()));
        Board {
            bus,
            acq,
            app,
            oracle,
        }
    }

    /// One acquisition cycle 1 s on, one App cycle; the App's output must
    /// equal the oracle's.
    fn cycle(&mut self) -> StepOutput {
        self.bus.advance_ns(1_000 * MS);
        let now = self.bus.now_ms();
        block_on(
            self.acq
                .cycle(&mut master(&self.bus), &mut self.bus.delay(), now),
        );
        let out = self.app.cycle(&self.acq, now, now, Some(0));
        let model = self.oracle.model().unwrap().clone();
        let mut stale = false;
        let temps: Vec<Option<i32>> = model
            .sensors
            .iter()
            .map(|s| {
                let ch = self.acq.map().channel_of(&RomCode(s.rom))?;
                let v = self.acq.value(ch, now);
                stale |= v.validity == Validity::Held;
                v.usable().map(i32::from)
            })
            .collect();
        let expect = self.oracle.step(&StepInput {
            now_ms: now,
            temps: &temps,
            spindle_rpm: 0,
            positions: &[0; 6],
            stale,
        });
        assert_eq!(out, expect, "the board reads each model sensor by its ROM");
        out
    }

    fn channel_of(&self, rom: RomCode) -> usize {
        self.acq.map().channel_of(&rom).unwrap()
    }
}

#[test]
fn a_model_exported_with_rom_codes_reads_each_sensor_in_any_channel_order() {
    let bus = six_sensor_bus();
    let run = recorded_run(&bus);
    let image = export_by_rom(&run);
    let model = Model::parse(&image).unwrap();
    for (k, s) in model.sensors.iter().enumerate() {
        assert_eq!(s.rom, rom_of(&bus, k).0, "sensor {k} named by its ROM");
        assert_eq!(usize::from(s.channel), k, "its training column kept");
    }
    // The sensors' channels in reverse order of the training columns (a
    // board whose map was built in another order).
    let mut map = ChannelMap::new();
    for k in 0..6 {
        map.set(5 - k, Some(rom_of(&bus, k))).unwrap();
    }
    let mut board = Board::boot(bus, map, &image);
    assert_eq!(board.channel_of(rom_of(&board.bus, 0)), 5);
    // IR 280-289: model sensor i reads channel 5 - i.
    let pairs = inputs(&mut board.app, IR_SENSOR_CHANNELS, 3);
    assert_eq!(pairs, vec![0x0504, 0x0302, 0x0100]);
    // The same model by channel, fed what the channels read: what a board
    // without ROM codes would compute (the check below can fail).
    let mut by_channel = model.clone();
    for s in by_channel.sensors.iter_mut() {
        s.rom = [0; 8];
    }
    let mut wrong = Compensator::new(Some(by_channel));
    let mut step_both = |board: &mut Board| {
        let out = board.cycle();
        let now = board.bus.now_ms();
        let temps: Vec<Option<i32>> = (0..6)
            .map(|c| board.acq.value(c, now).usable().map(i32::from))
            .collect();
        let w = wrong.step(&StepInput {
            now_ms: now,
            temps: &temps,
            spindle_rpm: 0,
            positions: &[0; 6],
            stale: false,
        });
        (out, w)
    };
    for _ in 0..3 {
        step_both(&mut board);
    }
    assert_eq!(u32_at(&mut board.app, IR_SENSORS_MISSING), 0);
    // Sensor 0 (channel 5) warms by 2.5 °C in small steps.
    let mut last = None;
    for _ in 0..5 {
        board.bus.with_device(0, |d| d.temperature += 8);
        last = Some(step_both(&mut board));
    }
    let (out, w) = last.unwrap();
    assert_eq!(board.acq.value(5, board.bus.now_ms()).raw, 20 * 16 + 40);
    assert!(
        out.status & thermocomp_core::compensator::status::VALID != 0,
        "{:#x}",
        out.status
    );
    assert_ne!(
        out.predicted, w.predicted,
        "by channel the model would read sensor 5 as sensor 0"
    );
}

#[test]
fn a_swapped_sensor_is_missing_plus_new_and_the_model_never_reads_the_new_one() {
    let bus = six_sensor_bus();
    let run = recorded_run(&bus);
    let image = export_by_rom(&run);
    let mut map = ChannelMap::new();
    for k in 0..6 {
        map.set(k, Some(rom_of(&bus, k))).unwrap();
    }
    let mut board = Board::boot(bus, map, &image);
    for _ in 0..3 {
        board.cycle();
    }
    let roms_before: Vec<u16> = inputs(&mut board.app, IR_CHANNEL_ROMS, 28);
    // IR 200-203: channel 0's ROM code in bus order.
    let r0 = rom_of(&board.bus, 0).0;
    assert_eq!(
        roms_before[..4],
        [
            u16::from_be_bytes([r0[0], r0[1]]),
            u16::from_be_bytes([r0[2], r0[3]]),
            u16::from_be_bytes([r0[4], r0[5]]),
            u16::from_be_bytes([r0[6], r0[7]])
        ]
    );
    assert_eq!(roms_before[24..], [0; 4], "channel 6 unmapped");
    // Sensor 2 is replaced by a new one (another ROM) reading 45 °C.
    board.bus.unplug(2);
    let new = Ds18b20::rom_for(0xBEEF_0042);
    board.bus.attach(Ds18b20::new(new, 45 * 16));
    block_on(board.acq.discover(&mut master(&board.bus))).unwrap();
    block_on(board.acq.configure(&mut master(&board.bus))).unwrap();
    board.app.update_channel_map(*board.acq.map());
    board.app.poll_flash();
    assert_eq!(
        board.channel_of(new),
        6,
        "the new sensor on the free channel"
    );
    for k in [0, 1, 3, 4, 5] {
        assert_eq!(board.channel_of(rom_of(&board.bus, k)), k, "not renumbered");
    }
    assert_eq!(
        board.channel_of(rom_of(&board.bus, 2)),
        2,
        "the old one keeps its channel"
    );
    let mut seen_new_value = false;
    for _ in 0..8 {
        board.cycle();
        let v = board.acq.value(6, board.bus.now_ms());
        seen_new_value |= v.validity == Validity::Fresh && v.raw == 45 * 16;
    }
    assert!(seen_new_value, "the new sensor is read on channel 6");
    // Reported: channel 2 missing, channel 6 added; model sensor 2 missing.
    assert_eq!(u32_at(&mut board.app, IR_MAP_MISSING), 1 << 2);
    assert_eq!(u32_at(&mut board.app, IR_MAP_ADDED), 1 << 6);
    assert_eq!(u32_at(&mut board.app, IR_SENSORS_MISSING), 1 << 2);
    assert_eq!(inputs(&mut board.app, IR_SENSOR_CHANNELS, 2)[1], 0x0203);
    assert_eq!(
        inputs(&mut board.app, IR_CHANNEL_ROMS + 4 * 6, 4)[0],
        u16::from_be_bytes([new.0[0], new.0[1]])
    );
    // The model serves without sensor 2 (held; the demo image has no
    // fallbacks), never from the new sensor's 45 °C.
    let out = board.cycle();
    assert!(
        out.status & thermocomp_core::compensator::status::SENSOR_FAULT != 0,
        "{:#x}",
        out.status
    );
    // After a reboot (the map from flash) the same holds.
    let mut flash = std::mem::replace(board.app.flash_mut(), MockFlash::new(0));
    flash.power_on();
    let app = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
    assert_eq!(app.channel_map(), *board.acq.map());
    assert_eq!(app.compensation().channel_of(2), Some(2));
}

#[test]
fn export_refuses_a_run_with_rom_codes_for_only_some_sensors() {
    let bus = six_sensor_bus();
    let mut run = recorded_run(&bus);
    run.meta.retain(|(k, _)| k != "rom.T04");
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    let mut fm = thermocomp_core::float::demo_model(7);
    let e =
        tcomp_model::export::name_sensors_by_rom(&mut fm, &columns, &run.sensor_roms().unwrap())
            .unwrap_err()
            .to_string();
    assert!(e.contains("not for T04") && !e.contains('\n'), "{e}");
    // None at all: by channel, as before.
    let none = BTreeMap::new();
    assert_eq!(
        tcomp_model::export::name_sensors_by_rom(&mut fm, &columns, &none).unwrap(),
        0
    );
    assert!(fm.sensors.iter().all(|s| s.rom == [0; 8]));
    // A mistyped code is refused naming its key.
    run.set_meta("rom.T02", "28FF4C1A0216035F");
    let e = format!("{:#}", run.sensor_roms().unwrap_err());
    assert!(e.contains("rom.T02") && e.contains("CRC-8"), "{e}");
}

#[test]
fn record_names_each_column_by_the_rom_code_the_board_serves() {
    let bus = six_sensor_bus();
    let mut acq = TemperatureAcquisition::new(config(), ChannelMap::new());
    block_on(acq.discover(&mut master(&bus))).unwrap();
    block_on(acq.configure(&mut master(&bus))).unwrap();
    let mut app = App::new(
        MockFlash::new(2 * SLOT as usize),
        SLOT,
        1,
        115_200,
        ChannelMap::new(),
    );
    host_tests::commission(&mut app);
    app.update_channel_map(*acq.map());
    app.poll_flash();
    for _ in 0..2 {
        bus.advance_ns(1_000 * MS);
        let now = bus.now_ms();
        block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), now));
        app.cycle(&acq, now, now, Some(0));
    }
    let map = *acq.map();
    let shared = std::sync::Arc::new(std::sync::Mutex::new(app));
    let addr = app_on_socket(shared.clone());
    let dir = std::env::temp_dir().join(format!("thermocomp-rec-rom-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("recorded.csv");
    let mut link = tcomp_link::board_link::BoardLink::tcp(&addr, 1).unwrap();
    tcomp_link::board_link::record(&mut link, &out, Duration::from_millis(10), 2, false).unwrap();
    let run = tcomp_data::runcsv::Run::read(&out).unwrap();
    let roms = run.sensor_roms().unwrap();
    assert_eq!(roms.len(), 6);
    for (c, rom) in map.iter() {
        assert_eq!(roms[&format!("T{:02}", c + 1)], rom.0, "channel {c}");
    }
    // Kept by the run reader and writer.
    let mut again = Vec::new();
    run.write_to(&mut again).unwrap();
    let back = tcomp_data::runcsv::Run::from_reader(again.as_slice()).unwrap();
    assert_eq!(back.sensor_roms().unwrap(), roms);
    // Upload a model named by these ROM codes, one of them on no channel:
    // the upload says which model sensor the board will serve without.
    let mut run_by_rom = recorded_run(&bus);
    run_by_rom.meta.retain(|(k, _)| !k.starts_with("rom."));
    for (c, rom) in map.iter() {
        run_by_rom.set_sensor_rom(&format!("T{:02}", c + 1), &rom.0);
    }
    let mut model = Model::parse(&export_by_rom(&run_by_rom)).unwrap();
    model.sensors[4].rom = Ds18b20::rom_for(0xABC_0004).0;
    let mut image = vec![0u8; model.encoded_len()];
    model.encode(&mut image).unwrap();
    // The upload names the missing sensor and sends nothing ...
    let commit = tcomp_link::board_link::Commit::NewerOnly;
    let e =
        tcomp_link::board_link::upload(&mut link, &image, &host_tests::upload_opts(commit, false))
            .unwrap_err()
            .to_string();
    assert!(
        e.contains("model sensor 4 (ROM") && e.contains("not sent"),
        "{e}"
    );
    // ... unless told to: the board then serves without it.
    let s =
        tcomp_link::board_link::upload(&mut link, &image, &host_tests::upload_opts(commit, true))
            .unwrap();
    assert_eq!(s.sensors_not_on_board, vec![4]);
    // A sensor swapped on channel 0 before an append: refused, one line.
    let mut swapped = map;
    swapped.set(0, Some(Ds18b20::rom_for(0x5_1234))).unwrap();
    shared.lock().unwrap().update_channel_map(swapped);
    shared.lock().unwrap().poll_flash();
    let e = tcomp_link::board_link::record(&mut link, &out, Duration::from_millis(10), 1, true)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the sensor of T01 was") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn replay_reads_sensors_named_by_rom_from_the_column_the_run_records_them_on() {
    let bus = six_sensor_bus();
    let run = recorded_run(&bus);
    let image = export_by_rom(&run);
    let by_rom = Model::parse(&image).unwrap();
    let mut by_channel = by_rom.clone();
    for s in by_channel.sensors.iter_mut() {
        s.rom = [0; 8];
    }
    let text = |run: &tcomp_data::runcsv::Run| {
        let mut t = Vec::new();
        run.write_to(&mut t).unwrap();
        String::from_utf8(t).unwrap()
    };
    let outs = |rows: Vec<tcomp_model::replay::ReplayRow>| -> Vec<StepOutput> {
        rows.into_iter().map(|r| r.out).collect()
    };
    let same = outs(tcomp_model::replay::replay(&text(&run), by_channel.clone()).unwrap());
    assert!(outs(tcomp_model::replay::replay(&text(&run), by_rom.clone()).unwrap()) == same);
    // The sensors of T01 and T02 recorded the other way round: by ROM the
    // replay follows the sensors, by channel it would not.
    let mut swapped = run.clone();
    let (r1, r2) = (rom_of(&bus, 0).0, rom_of(&bus, 1).0);
    swapped.set_sensor_rom("T01", &r2);
    swapped.set_sensor_rom("T02", &r1);
    let t1 = run.col("T01").unwrap().to_vec();
    let t2 = run.col("T02").unwrap().to_vec();
    let (c1, c2) = (run.col_index("T01").unwrap(), run.col_index("T02").unwrap());
    swapped.data[c1] = t2;
    swapped.data[c2] = t1;
    let by_rom_swapped =
        outs(tcomp_model::replay::replay(&text(&swapped), by_rom.clone()).unwrap());
    assert!(
        by_rom_swapped == same,
        "by ROM the replay follows the sensors"
    );
    assert!(
        outs(tcomp_model::replay::replay(&text(&swapped), by_channel).unwrap()) != same,
        "by channel the replay reads the other sensor"
    );
    // A run recording ROM codes without sensor 3's: sensor 3 is missing.
    let mut partial = run.clone();
    partial.meta.retain(|(k, _)| k != "rom.T04");
    let rows = outs(tcomp_model::replay::replay(&text(&partial), by_rom).unwrap());
    assert!(rows
        .iter()
        .all(|o| o.status & thermocomp_core::compensator::status::SENSOR_FAULT != 0));
}

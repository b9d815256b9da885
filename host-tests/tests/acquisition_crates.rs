//! Evidence for the crate decision in `src/acquisition/mod.rs`: the
//! customer-named `one-wire-bus` 0.1.1 and `ds18b20` 0.1.1, run unchanged on
//! the same pin-level emulator the board's own code runs on.

use ds18b20::{Ds18b20 as CrateSensor, Resolution as CrateResolution};
use embedded_hal_02::blocking::delay::DelayMs;
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, EmuDelay, EmuPin, Fault};
use one_wire_bus::{Address, OneWire};
use thermocomp::acquisition::temperature::read_scratchpad;
use thermocomp_protocol::states::ChannelState;

fn crate_bus(bus: &Bus) -> (OneWire<EmuPin>, EmuDelay, CrateSensor) {
    let ow = OneWire::new(bus.pin()).unwrap();
    let rom = bus.with_device(0, |d| d.rom).unwrap();
    let sensor =
        CrateSensor::new::<core::convert::Infallible>(Address(u64::from_le_bytes(rom.0))).unwrap();
    (ow, bus.delay(), sensor)
}

/// Convert T + wait + read with the crate; returns its temperature in °C.
fn crate_read(bus: &Bus) -> Result<f32, String> {
    let (mut ow, mut delay, sensor) = crate_bus(bus);
    ds18b20::start_simultaneous_temp_measurement(&mut ow, &mut delay)
        .map_err(|e| format!("{e:?}"))?;
    delay.delay_ms(750u16);
    sensor
        .read_data(&mut ow, &mut delay)
        .map(|d| d.temperature)
        .map_err(|e| format!("{e:?}"))
}

/// The board's own read of the same sensor, 1/16 °C.
fn own_read(bus: &Bus) -> Result<i16, ChannelState> {
    let rom = bus.with_device(0, |d| d.rom).unwrap();
    let mut m = master(bus);
    block_on(read_scratchpad(&mut m, &rom)).map(|s| s.raw)
}

#[test]
fn crate_search_works_with_exact_timing() {
    let bus = bus_with_sensors(5, 7, 0);
    let mut ow = OneWire::new(bus.pin()).unwrap();
    let mut delay = bus.delay();
    let found: Vec<_> = ow.devices(false, &mut delay).collect();
    assert_eq!(found.len(), 5);
    assert!(found.iter().all(|r| r.is_ok()));
}

#[test]
fn ds18b20_crate_decodes_negative_temperatures_as_unsigned() {
    let bus = bus_with_sensors(1, 3, -162); // −10.125 °C
    let t = crate_read(&bus).unwrap();
    assert_eq!(t, 4085.875, "the u16 defect");
    assert_eq!(own_read(&bus), Ok(-162));
}

#[test]
fn ds18b20_crate_scales_twice_below_twelve_bits() {
    let bus = bus_with_sensors(1, 3, 376); // 23.5 °C
    let (mut ow, mut delay, sensor) = crate_bus(&bus);
    sensor
        .set_config(0, 0, CrateResolution::Bits9, &mut ow, &mut delay)
        .unwrap();
    let t = crate_read(&bus).unwrap();
    assert_eq!(t, 188.0, "divided by 2 instead of 16");
    assert_eq!(own_read(&bus), Ok(376));
}

#[test]
fn nine_zero_bytes_pass_the_crate_crc_and_are_misnamed() {
    let bus = bus_with_sensors(1, 3, 400);
    crate_read(&bus).unwrap();
    bus.with_device(0, |d| d.set_fault(Fault::AllZero));
    let (mut ow, mut delay, sensor) = crate_bus(&bus);
    // The scratchpad read (CRC checked) accepts nine zeros...
    let sp = ds18b20::read_scratchpad(sensor.address(), &mut ow, &mut delay);
    assert_eq!(sp.map_err(|e| format!("{e:?}")), Ok([0u8; 9]));
    // ...and `read_data` rejects them only because config byte 0 is not a
    // resolution, reported as a CRC mismatch.
    assert_eq!(crate_read(&bus), Err("CrcMismatch".to_string()));
    assert_eq!(own_read(&bus), Err(ChannelState::AllZero));
}

#[test]
fn ds18b20_crate_returns_the_power_on_value_as_a_reading() {
    let bus = bus_with_sensors(1, 3, 400);
    bus.with_device(0, |d| d.set_fault(Fault::PowerOn));
    assert_eq!(crate_read(&bus), Ok(85.0));
    // The acquisition names it (the scratchpad lost its reset marker).
    use thermocomp::acquisition::channel_map::ChannelMap;
    use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    bus.with_device(0, |d| d.set_fault(Fault::None));
    assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(1));
    assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
    bus.with_device(0, |d| d.set_fault(Fault::PowerOn));
    block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), 0));
    let rom = bus.with_device(0, |d| d.rom).unwrap();
    let ch = acq.map().channel_of(&rom).unwrap();
    assert_eq!(acq.state(ch), ChannelState::PowerOnValue);
}

#[test]
fn one_wire_bus_samples_at_the_window_edge_and_fails_with_1us_overshoot() {
    let bus = bus_with_sensors(1, 3, 400);
    // Exact delays: sample at 15.0 µs, just inside t_RDV.
    assert_eq!(crate_read(&bus), Ok(25.0));
    assert_eq!(bus.stats().violations.late_read, 0);
    // 1 µs of overshoot per delay (pin access + loop): sample at 17 µs.
    bus.set_delay_overhead_ns(1_000);
    bus.reset_stats();
    let late = crate_read(&bus);
    assert!(bus.stats().violations.late_read > 0);
    assert_ne!(late, Ok(25.0), "{late:?}");
    // The board's master samples at 10 µs: still correct with 2 µs overshoot.
    bus.set_delay_overhead_ns(2_000);
    bus.reset_stats();
    assert_eq!(own_read(&bus), Ok(400));
    assert_eq!(bus.stats().violations.late_read, 0);
}

#[test]
fn crate_scratchpad_read_takes_longer_per_sensor() {
    let bus = bus_with_sensors(1, 3, 400);
    crate_read(&bus).unwrap();
    let (mut ow, mut delay, sensor) = crate_bus(&bus);
    let t0 = bus.now_ns();
    ds18b20::read_scratchpad(sensor.address(), &mut ow, &mut delay).unwrap();
    let crate_ns = bus.now_ns() - t0;
    let t0 = bus.now_ns();
    own_read(&bus).unwrap();
    let own_ns = bus.now_ns() - t0;
    // one-wire-bus: 70 µs slots + 960 µs reset; ours: 62 µs slots + 1000 µs.
    assert!(crate_ns > own_ns, "crate {crate_ns} ns, own {own_ns} ns");
    println!("scratchpad read: one-wire-bus {crate_ns} ns, board {own_ns} ns");
}

#[test]
fn without_a_strong_pull_up_parasite_sensors_read_85_through_the_crates() {
    let bus = bus_with_sensors(1, 3, 400);
    bus.with_device(0, |d| d.parasite = true);
    // one-wire-bus has no strong pull-up: the conversion browns out and the
    // crate reports the power-on value as a temperature.
    assert_eq!(crate_read(&bus), Ok(85.0));
}

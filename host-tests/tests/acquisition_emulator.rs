//! The board's real acquisition code (bit-banged master, ROM search, cycle,
//! fault logic) against the pin-level DS18B20 emulator.

use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, Fault, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::rom::{search, RomCode};
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition, Validity};
use thermocomp_protocol::states::ChannelState;
use thermocomp_protocol::MAX_CHANNELS;

fn roms(bus: &Bus) -> Vec<RomCode> {
    (0..bus.device_count())
        .map(|i| bus.with_device(i, |d| d.rom).unwrap())
        .collect()
}

/// Channel of device `i` in the acquisition's map.
fn channel_of(acq: &TemperatureAcquisition, bus: &Bus, i: usize) -> usize {
    let rom = bus.with_device(i, |d| d.rom).unwrap();
    acq.map().channel_of(&rom).unwrap()
}

fn setup(n: usize, config: AcquisitionConfig) -> (Bus, TemperatureAcquisition) {
    let bus = bus_with_sensors(n, 0x5EED_0003, 20 * 16);
    let mut acq = TemperatureAcquisition::new(config, ChannelMap::new());
    let mut m = master(&bus);
    assert_eq!(block_on(acq.discover(&mut m)), Ok(n));
    assert_eq!(block_on(acq.configure(&mut m)), Ok(true));
    (bus, acq)
}

fn cycle(
    bus: &Bus,
    acq: &mut TemperatureAcquisition,
) -> thermocomp::acquisition::temperature::CycleReport {
    let mut m = master(bus);
    let mut d = bus.delay();
    let now = bus.now_ms();
    block_on(acq.cycle(&mut m, &mut d, now))
}

#[test]
fn search_finds_twenty_devices_without_timing_violations() {
    let bus = bus_with_sensors(20, 42, 0);
    let mut found = heapless::Vec::<RomCode, MAX_CHANNELS>::new();
    let mut m = master(&bus);
    assert_eq!(block_on(search(&mut m, &mut found)), Ok(20));
    let mut expected = roms(&bus);
    expected.sort();
    let mut got: Vec<RomCode> = found.iter().copied().collect();
    got.sort();
    assert_eq!(got, expected);
    assert!(got.iter().all(|r| r.is_valid() && r.family() == 0x28));
    assert_eq!(bus.stats().violations.total(), 0, "{:?}", bus.stats());
}

/// Deterministic 4-hour trace of 20 sensors as a run CSV, values in exact
/// sixteenths (4 decimals), two sensors below 0 °C.
fn generate_trace(period_s: u64, hours: u64) -> String {
    let mut csv = String::from("# machine: emulator\n# source: simulated\ntime_s,spindle_rpm");
    for c in 1..=20 {
        csv.push_str(&format!(",T{c:02}"));
    }
    csv.push('\n');
    for step in 0..=(hours * 3600 / period_s) {
        let t = (step * period_s) as f64;
        csv.push_str(&format!(
            "{},{}",
            step * period_s,
            if step % 50 < 30 { 4500 } else { 0 }
        ));
        for c in 0..20 {
            let cf = c as f64;
            let (base, rise) = if c >= 18 {
                (-12.0 + 2.0 * cf - 36.0, 6.0) // chiller lines: −12 .. +0.x °C
            } else {
                (18.0 + 0.3 * cf, 4.0 + cf)
            };
            let tau = 1800.0 + 300.0 * cf;
            let v = base
                + rise * (1.0 - (-t / tau).exp())
                + 0.6 * (t / (900.0 + 37.0 * cf)).sin()
                + 0.2 * (t / 211.0 + cf).cos();
            let raw = (v * 16.0).round() as i64;
            csv.push_str(&format!(",{:.4}", raw as f64 / 16.0));
        }
        csv.push('\n');
    }
    csv
}

#[test]
fn four_hour_trace_of_twenty_sensors_comes_back_exactly() {
    let csv = generate_trace(60, 4);
    let mut lines = csv.lines().filter(|l| !l.starts_with('#'));
    let header = thermocomp_protocol::trace::TraceHeader::parse(lines.next().unwrap()).unwrap();
    assert_eq!(header.channels(), 20);
    let (bus, mut acq) = setup(20, AcquisitionConfig::default());
    let mut rows = 0;
    let mut below_zero = 0;
    let mut checked = 0;
    for line in lines {
        let sample = thermocomp_protocol::trace::TraceSample::parse(&header, line).unwrap();
        // Trace column k feeds device k.
        for (k, t) in sample.temperatures.iter().take(20).enumerate() {
            let raw = i16::try_from(t.unwrap()).unwrap();
            bus.with_device(k, |d| d.temperature = raw);
        }
        let target_ns = sample.time_ms * MS;
        if bus.now_ns() < target_ns {
            bus.advance_ns(target_ns - bus.now_ns());
        }
        let report = cycle(&bus, &mut acq);
        assert_eq!(report.ok, 20, "row {rows}: {report:?}");
        let now = bus.now_ms();
        for k in 0..20 {
            let expected = sample.temperatures[k].unwrap();
            let v = acq.value(channel_of(&acq, &bus, k), now);
            assert_eq!(v.state, ChannelState::Ok, "row {rows} sensor {k}");
            assert_eq!(v.validity, Validity::Fresh);
            assert_eq!(i32::from(v.raw), expected, "row {rows} sensor {k}");
            if v.raw < 0 {
                below_zero += 1;
            }
            checked += 1;
        }
        rows += 1;
    }
    assert_eq!(rows, 241);
    assert_eq!(checked, 241 * 20);
    assert!(below_zero > 100, "{below_zero} readings below 0 °C");
    assert_eq!(bus.stats().violations.total(), 0, "{:?}", bus.stats());
}

/// Drives one device into a fault and checks state, hold, invalid, recovery.
/// `inject(bus, n)` runs before the n-th faulty cycle; `bus_wide` faults hit
/// every channel.
fn fault_scenario(
    expected: ChannelState,
    bus_wide: bool,
    inject: impl Fn(&Bus, u32),
    clear: impl Fn(&Bus),
) {
    let config = AcquisitionConfig::default();
    let (bus, mut acq) = setup(3, config);
    let ch = channel_of(&acq, &bus, 1);
    let other = channel_of(&acq, &bus, 0);
    for i in 0..3 {
        bus.with_device(1, |d| d.temperature = 320 + i);
        cycle(&bus, &mut acq);
        bus.advance_ns(10_000 * MS);
    }
    assert_eq!(acq.state(ch), ChannelState::Ok);
    let good = acq.value(ch, bus.now_ms()).raw;
    assert_eq!(good, 322);
    inject(&bus, 0);
    let t_fault = bus.now_ms();
    cycle(&bus, &mut acq);
    let v = acq.value(ch, bus.now_ms());
    assert_eq!(v.state, expected);
    assert_eq!(v.validity, Validity::Held, "held within hold_ms");
    assert_eq!(v.usable(), Some(good));
    if bus_wide {
        assert_eq!(acq.state(other), expected);
    } else {
        assert_eq!(
            acq.state(other),
            ChannelState::Ok,
            "other channels unaffected"
        );
    }
    // Past the hold time: invalid, never the faulty value.
    let mut n = 1;
    while bus.now_ms() <= t_fault + config.hold_ms {
        bus.advance_ns(15_000 * MS);
        inject(&bus, n);
        n += 1;
        cycle(&bus, &mut acq);
        assert_eq!(acq.state(ch), expected);
    }
    let v = acq.value(ch, bus.now_ms());
    assert_eq!(v.state, expected);
    assert_eq!(v.validity, Validity::Invalid);
    assert_eq!(v.usable(), None);
    // Recovery.
    clear(&bus);
    bus.advance_ns(10_000 * MS);
    cycle(&bus, &mut acq);
    if matches!(
        expected,
        ChannelState::Disconnected | ChannelState::NoPresence
    ) {
        // Back on the bus: its reading counts after one whole cycle there.
        assert_eq!(acq.state(ch), ChannelState::Intermittent);
        assert_eq!(acq.value(ch, bus.now_ms()).validity, Validity::Invalid);
        bus.advance_ns(1_000 * MS);
        cycle(&bus, &mut acq);
    }
    let v = acq.value(ch, bus.now_ms());
    assert_eq!(v.state, ChannelState::Ok);
    assert_eq!(v.validity, Validity::Fresh);
    assert_eq!(v.raw, bus.with_device(1, |d| d.temperature).unwrap());
}

#[test]
fn persistent_crc_error() {
    fault_scenario(
        ChannelState::CrcError,
        false,
        |b, _| {
            b.with_device(1, |d| d.set_fault(Fault::CorruptScratchpad(u32::MAX)));
        },
        |b| {
            b.with_device(1, |d| d.set_fault(Fault::None));
        },
    );
}

#[test]
fn all_zero_scratchpad() {
    fault_scenario(
        ChannelState::AllZero,
        false,
        |b, _| {
            b.with_device(1, |d| d.set_fault(Fault::AllZero));
        },
        |b| {
            b.with_device(1, |d| d.set_fault(Fault::None));
        },
    );
}

#[test]
fn power_on_value() {
    fault_scenario(
        ChannelState::PowerOnValue,
        false,
        |b, _| {
            b.with_device(1, |d| d.set_fault(Fault::PowerOn));
        },
        |b| {
            b.with_device(1, |d| d.set_fault(Fault::None));
        },
    );
}

#[test]
fn disconnected_sensor() {
    fault_scenario(
        ChannelState::Disconnected,
        false,
        |b, _| {
            b.with_device(1, |d| d.set_fault(Fault::Silent));
        },
        |b| {
            b.with_device(1, |d| d.set_fault(Fault::None));
        },
    );
}

#[test]
fn out_of_range() {
    fault_scenario(
        ChannelState::OutOfRange,
        false,
        |b, _| {
            b.with_device(1, |d| d.temperature = 120 * 16);
        },
        |b| {
            b.with_device(1, |d| d.temperature = 323);
        },
    );
}

#[test]
fn implausible_step_then_back() {
    fault_scenario(
        ChannelState::ImplausibleStep,
        false,
        |b, n| {
            // ±10 °C spikes, alternating: never confirmed as a real step.
            let spike = if n % 2 == 0 { 160 } else { -160 };
            b.with_device(1, |d| d.temperature = 322 + spike);
        },
        |b| {
            b.with_device(1, |d| d.temperature = 323);
        },
    );
}

#[test]
fn stuck_value_while_others_move() {
    let config = AcquisitionConfig {
        stuck_ms: 10 * 60 * 1000,
        hold_ms: 15 * 60 * 1000,
        ..AcquisitionConfig::default()
    };
    let (bus, mut acq) = setup(3, config);
    let ch = channel_of(&acq, &bus, 2);
    let mut seen_stuck_at = None;
    for minute in 0..30i16 {
        bus.with_device(0, |d| d.temperature = 320 + minute);
        bus.with_device(1, |d| d.temperature = 330 + minute / 2);
        if minute == 3 {
            // The converter freezes: the register keeps minute 2's value.
            bus.with_device(2, |d| d.set_fault(Fault::Stuck));
        }
        bus.with_device(2, |d| d.temperature = 340 + minute);
        cycle(&bus, &mut acq);
        if acq.state(ch) == ChannelState::Stuck && seen_stuck_at.is_none() {
            seen_stuck_at = Some(minute);
            let v = acq.value(ch, bus.now_ms());
            assert_eq!(v.validity, Validity::Held);
            assert_eq!(v.raw, 340 + 2);
        }
        bus.advance_ns(60_000 * MS);
    }
    // Last change at minute 2; stuck once 10 min passed.
    let at = seen_stuck_at.expect("stuck detected");
    assert!((12..=13).contains(&at), "stuck detected at minute {at}");
    // Past the hold time: invalid.
    assert_eq!(acq.value(ch, bus.now_ms()).validity, Validity::Invalid);
    // The sensor moves again: recovered.
    bus.with_device(2, |d| d.set_fault(Fault::None));
    bus.with_device(2, |d| d.temperature = 360);
    cycle(&bus, &mut acq);
    assert_eq!(acq.state(ch), ChannelState::Ok);
    assert_eq!(acq.value(ch, bus.now_ms()).raw, 360);
}

#[test]
fn bus_open_gives_no_presence_on_every_channel() {
    fault_scenario(
        ChannelState::NoPresence,
        true,
        |b, _| b.set_open(true),
        |b| b.set_open(false),
    );
}

#[test]
fn shorted_bus_reads_as_all_zero() {
    fault_scenario(
        ChannelState::AllZero,
        true,
        |b, _| b.set_short(true),
        |b| b.set_short(false),
    );
}

#[test]
fn transient_crc_error_is_retried() {
    let (bus, mut acq) = setup(3, AcquisitionConfig::default());
    let ch = channel_of(&acq, &bus, 1);
    cycle(&bus, &mut acq);
    bus.with_device(1, |d| d.set_fault(Fault::CorruptScratchpad(2)));
    let before = bus.with_device(1, |d| d.scratchpad_reads).unwrap();
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.retries, 2);
    assert_eq!(acq.state(ch), ChannelState::Ok);
    assert_eq!(
        bus.with_device(1, |d| d.scratchpad_reads).unwrap() - before,
        3
    );
    // Persistent: bounded at 1 + read_retries attempts.
    bus.with_device(1, |d| d.set_fault(Fault::CorruptScratchpad(u32::MAX)));
    let before = bus.with_device(1, |d| d.scratchpad_reads).unwrap();
    cycle(&bus, &mut acq);
    assert_eq!(acq.state(ch), ChannelState::CrcError);
    let attempts = bus.with_device(1, |d| d.scratchpad_reads).unwrap() - before;
    assert_eq!(attempts, 1 + u64::from(acq.config().read_retries));
}

#[test]
fn large_step_confirmed_by_consecutive_readings_is_accepted() {
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    let ch = channel_of(&acq, &bus, 0);
    cycle(&bus, &mut acq);
    bus.with_device(0, |d| d.temperature = 20 * 16 + 160);
    let mut states = Vec::new();
    for _ in 0..3 {
        bus.advance_ns(1_000 * MS);
        cycle(&bus, &mut acq);
        states.push(acq.state(ch));
    }
    assert_eq!(
        states,
        [
            ChannelState::ImplausibleStep,
            ChannelState::ImplausibleStep,
            ChannelState::Ok
        ]
    );
    assert_eq!(acq.value(ch, bus.now_ms()).raw, 20 * 16 + 160);
}

#[test]
fn late_read_sampling_fails_like_hardware_and_overshoot_is_tolerated() {
    use thermocomp::acquisition::bitbang::{BitBangBus, SlotTiming};
    // Sampling at 20 µs: past t_RDV, zeros read as ones.
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    let late = SlotTiming {
        read_sample: 20,
        ..SlotTiming::STANDARD
    };
    let mut m = BitBangBus::new(bus.pin(), bus.delay(), late);
    let mut d = bus.delay();
    block_on(acq.cycle(&mut m, &mut d, bus.now_ms()));
    assert!(bus.stats().violations.late_read > 0);
    for k in 0..2 {
        let s = acq.state(channel_of(&acq, &bus, k));
        assert!(s.is_fault(), "{s:?}");
    }
    // Standard timing with 2 µs of overshoot on every delay still reads.
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    bus.set_delay_overhead_ns(2_000);
    bus.reset_stats();
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.ok, 2);
    assert_eq!(bus.stats().violations.late_read, 0);
}

#[test]
fn channel_map_persists_and_a_replaced_sensor_takes_a_free_channel() {
    let (bus, acq) = setup(4, AcquisitionConfig::default());
    let stored = acq.map().to_bytes();
    let map = ChannelMap::from_bytes(&stored).unwrap();
    assert_eq!(&map, acq.map());
    // Sensor 2 replaced by a new one.
    let old = bus.with_device(2, |d| d.rom).unwrap();
    let old_ch = map.channel_of(&old).unwrap();
    let new_rom = host_tests::onewire_emu::Ds18b20::rom_for(0xABCDEF);
    bus.with_device(2, |d| d.rom = new_rom);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), map);
    block_on(acq.discover(&mut master(&bus))).unwrap();
    let new_ch = acq.map().channel_of(&new_rom).unwrap();
    assert_ne!(new_ch, old_ch);
    assert_eq!(acq.map().get(old_ch), Some(old));
    for k in [0, 1, 3] {
        let rom = bus.with_device(k, |d| d.rom).unwrap();
        assert_eq!(acq.map().channel_of(&rom), map.channel_of(&rom));
    }
    // The old sensor's channel reports its absence as Disconnected.
    cycle(&bus, &mut acq);
    assert_eq!(acq.state(old_ch), ChannelState::Disconnected);
    assert_eq!(acq.state(new_ch), ChannelState::Ok);
}

#[test]
fn low_resolution_and_parasite_power() {
    use thermocomp::acquisition::ds18b20::Resolution;
    use thermocomp::acquisition::temperature::PowerMode;
    let config = AcquisitionConfig {
        resolution: Resolution::Bits9,
        power: PowerMode::Parasite,
        ..AcquisitionConfig::default()
    };
    let (bus, mut acq) = setup(2, config);
    bus.with_device(0, |d| d.temperature = -162); // −10.125 °C
    bus.with_device(1, |d| d.temperature = 376); // 23.5 °C
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.conversion_wait_us, 93_750);
    // 9 bits: 0.5 °C steps, still in 1/16 °C units.
    assert_eq!(acq.value(channel_of(&acq, &bus, 0), bus.now_ms()).raw, -168);
    assert_eq!(acq.value(channel_of(&acq, &bus, 1), bus.now_ms()).raw, 376);
}

#[test]
fn parasite_sensors_need_the_strong_pull_up() {
    use thermocomp::acquisition::temperature::PowerMode;
    let parasite = AcquisitionConfig {
        power: PowerMode::Parasite,
        ..AcquisitionConfig::default()
    };
    let (bus, mut acq) = setup(3, parasite);
    for k in 0..3 {
        bus.with_device(k, |d| d.parasite = true);
    }
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.ok, 3, "strong pull-up held through the conversion");
    assert_eq!(report.conversion_wait_us, 750_000);
    // Without it (polling read slots as for powered sensors) every
    // conversion browns out: the 85.0 °C power-on value, named as such.
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), *acq.map());
    bus.advance_ns(1_000 * MS);
    cycle(&bus, &mut acq);
    for k in 0..3 {
        assert_eq!(
            acq.state(channel_of(&acq, &bus, k)),
            ChannelState::PowerOnValue
        );
    }
}

#[test]
fn a_cycle_yields_to_the_executor_between_bytes() {
    use std::future::Future;
    use std::task::{Context, Waker};
    let (bus, mut acq) = setup(20, AcquisitionConfig::default());
    let mut m = master(&bus);
    let mut d = bus.delay();
    let now = bus.now_ms();
    let mut fut = std::pin::pin!(acq.cycle(&mut m, &mut d, now));
    let mut cx = Context::from_waker(Waker::noop());
    let mut pending = 0u32;
    let mut longest_ns = 0u64;
    let mut last = bus.stats().busy_ns;
    loop {
        let done = fut.as_mut().poll(&mut cx).is_ready();
        // CPU held by busy-waits within this poll (async delays excluded).
        let busy = bus.stats().busy_ns;
        longest_ns = longest_ns.max(busy - last);
        last = busy;
        if done {
            break;
        }
        pending += 1;
    }
    // Per sensor: reset + 10 bytes written + 9 read.
    assert!(pending >= 20 * 20, "{pending}");
    // No poll holds the CPU longer than a reset plus one byte (~1.5 ms).
    assert!(longest_ns <= 1_500_000, "{longest_ns} ns");
}

#[test]
fn search_separates_consecutive_serials() {
    use host_tests::onewire_emu::Ds18b20;
    // ROM codes that differ only in their low bits: the search branches at
    // every level of the tree.
    let bus = Bus::new();
    for s in 0..16u64 {
        bus.attach(Ds18b20::new(Ds18b20::rom_for(0x1000 + s), 0));
    }
    let mut found = heapless::Vec::<RomCode, MAX_CHANNELS>::new();
    assert_eq!(block_on(search(&mut master(&bus), &mut found)), Ok(16));
    let mut got: Vec<_> = found.to_vec();
    got.sort();
    got.dedup();
    assert_eq!(got.len(), 16);
}

#[test]
fn more_sensors_than_channels_maps_the_first_twenty() {
    use thermocomp::acquisition::rom::SearchError;
    let bus = bus_with_sensors(21, 99, 20 * 16);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    assert_eq!(
        block_on(acq.discover(&mut master(&bus))),
        Err(SearchError::TooMany)
    );
    assert_eq!(acq.map().len(), MAX_CHANNELS);
    assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.ok, 20);
}

/// 85.0 °C in 1/16 °C: the DS18B20's power-on register value.
const EIGHTY_FIVE: i16 = 85 * 16;

#[test]
fn a_genuine_85_degrees_is_a_temperature_for_as_long_as_it_lasts() {
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    let ch = channel_of(&acq, &bus, 0);
    // Warm up to 85.0 °C in 1/16 °C steps, then stay there for 30 cycles.
    let mut temps: Vec<i16> = (EIGHTY_FIVE - 8..=EIGHTY_FIVE).collect();
    temps.extend([EIGHTY_FIVE; 30]);
    temps.extend([EIGHTY_FIVE + 1, EIGHTY_FIVE]);
    for (i, &t) in temps.iter().enumerate() {
        bus.with_device(0, |d| d.temperature = t);
        cycle(&bus, &mut acq);
        let v = acq.value(ch, bus.now_ms());
        assert_eq!(v.state, ChannelState::Ok, "cycle {i} at {t}");
        assert_eq!(v.validity, Validity::Fresh);
        assert_eq!(v.raw, t);
        bus.advance_ns(1_000 * MS);
    }
}

#[test]
fn a_genuine_85_degrees_at_power_up_is_confirmed_by_the_second_conversion() {
    // Every sensor at 85.0 °C from the start: the first conversion after the
    // configuration could be a missed Convert T, the second cannot.
    let (bus, mut acq) = setup(3, AcquisitionConfig::default());
    for k in 0..3 {
        bus.with_device(k, |d| d.temperature = EIGHTY_FIVE);
    }
    cycle(&bus, &mut acq);
    for k in 0..3 {
        let v = acq.value(channel_of(&acq, &bus, k), bus.now_ms());
        assert_eq!(v.state, ChannelState::PowerOnValue);
        assert_eq!(v.usable(), None);
    }
    for _ in 0..5 {
        bus.advance_ns(1_000 * MS);
        cycle(&bus, &mut acq);
        for k in 0..3 {
            let v = acq.value(channel_of(&acq, &bus, k), bus.now_ms());
            assert_eq!((v.state, v.raw), (ChannelState::Ok, EIGHTY_FIVE));
        }
    }
}

#[test]
fn a_missed_first_conversion_leaves_the_power_on_value_named() {
    // Powered up (register 85.0 °C), configured, then the first Convert T
    // is missed: the scratchpad carries the marker and 85.0 °C, and the
    // sensor is at 30 °C. That 85.0 °C must not come out as a reading.
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    let ch = channel_of(&acq, &bus, 1);
    bus.with_device(1, |d| {
        d.temperature = 30 * 16;
        d.set_fault(Fault::MissConvert(1));
    });
    cycle(&bus, &mut acq);
    let v = acq.value(ch, bus.now_ms());
    assert_eq!(v.state, ChannelState::PowerOnValue);
    assert_eq!(v.usable(), None);
    bus.advance_ns(1_000 * MS);
    cycle(&bus, &mut acq);
    let v = acq.value(ch, bus.now_ms());
    assert_eq!((v.state, v.raw), (ChannelState::Ok, 30 * 16));
}

#[test]
fn a_brownout_at_85_degrees_is_named_then_the_temperature_returns() {
    let (bus, mut acq) = setup(2, AcquisitionConfig::default());
    let ch = channel_of(&acq, &bus, 0);
    for t in [EIGHTY_FIVE - 2, EIGHTY_FIVE - 1, EIGHTY_FIVE] {
        bus.with_device(0, |d| d.temperature = t);
        cycle(&bus, &mut acq);
        bus.advance_ns(1_000 * MS);
    }
    assert_eq!(acq.state(ch), ChannelState::Ok);
    // A brownout between two cycles: the device converts again (a genuine
    // 85.0 °C) but its scratchpad lost the marker, so nothing tells this
    // 85.0 °C from the power-on value yet.
    bus.with_device(0, |d| d.power_on_reset());
    let report = cycle(&bus, &mut acq);
    assert_eq!(report.reconfigured, 1);
    let v = acq.value(ch, bus.now_ms());
    assert_eq!(
        (v.state, v.validity),
        (ChannelState::PowerOnValue, Validity::Held)
    );
    let restored = bus.with_device(0, |d| d.scratchpad_config()).unwrap();
    assert_eq!(
        restored,
        [
            thermocomp::acquisition::temperature::MARKER_TH,
            thermocomp::acquisition::temperature::MARKER_TL,
            acq.config().resolution.config_byte()
        ]
    );
    // Confirmed by the second conversion after the rewrite, then steady.
    let mut states = Vec::new();
    for _ in 0..4 {
        bus.advance_ns(1_000 * MS);
        cycle(&bus, &mut acq);
        states.push(acq.state(ch));
    }
    assert_eq!(
        states,
        [
            ChannelState::PowerOnValue,
            ChannelState::Ok,
            ChannelState::Ok,
            ChannelState::Ok
        ]
    );
    assert_eq!(acq.value(ch, bus.now_ms()).raw, EIGHTY_FIVE);
}

//! 1-Wire faults injected on the pin-level emulator, against the board's real
//! acquisition: each ends in a named channel state, and no channel ever
//! reports a value the sensor did not measure ("wild output"): a fresh value
//! is the sensor's temperature, a held one the last good value, an invalid
//! one is not usable.

use host_tests::onewire_emu::{
    block_on, bus_with_sensors, master, Bus, Ds18b20, Fault, LineEvent, Trigger, MS,
};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::ds18b20::Resolution;
use thermocomp::acquisition::rom::{RomCode, SearchError};
use thermocomp::acquisition::temperature::{
    AcquisitionConfig, CycleReport, TemperatureAcquisition, Validity, MARKER_TH, MARKER_TL,
};
use thermocomp_protocol::states::ChannelState;

/// 85.0 °C, the power-on register value, 1/16 °C.
const POWER_ON: i16 = 85 * 16;

/// The bus, the acquisition and what the test knows to be true.
struct Rig {
    bus: Bus,
    acq: TemperatureAcquisition,
    /// Last value each device was read good at (by device index).
    last_good: Vec<Option<i16>>,
    /// Each device's temperature at the previous cycle.
    previous_truth: Vec<i16>,
    /// A fresh value may be the previous cycle's conversion (a contact that
    /// opens exactly at Convert T: the documented limit).
    allow_one_cycle_old: bool,
}

impl Rig {
    fn new(n: usize, config: AcquisitionConfig) -> Rig {
        let bus = bus_with_sensors(n, 0xFA17_0001, 20 * 16);
        for k in 0..n {
            bus.with_device(k, |d| d.temperature = 20 * 16 + 8 * k as i16);
        }
        let mut acq = TemperatureAcquisition::new(config, ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(n));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        let mut rig = Rig {
            bus,
            acq,
            last_good: vec![None; n],
            previous_truth: vec![0; n],
            allow_one_cycle_old: false,
        };
        rig.cycle();
        for k in 0..n {
            assert_eq!(rig.state(k), ChannelState::Ok, "device {k} after setup");
        }
        rig
    }

    fn channel(&self, device: usize) -> usize {
        let rom = self.bus.with_device(device, |d| d.rom).unwrap();
        self.acq.map().channel_of(&rom).unwrap()
    }

    fn state(&self, device: usize) -> ChannelState {
        self.acq.state(self.channel(device))
    }

    fn validity(&self, device: usize) -> Validity {
        self.acq
            .value(self.channel(device), self.bus.now_ms())
            .validity
    }

    /// One cycle 1 s after the last, then the no-wild-output check.
    fn cycle(&mut self) -> CycleReport {
        self.bus.advance_ns(1_000 * MS);
        let mut m = master(&self.bus);
        let mut d = self.bus.delay();
        let now = self.bus.now_ms();
        let report = block_on(self.acq.cycle(&mut m, &mut d, now));
        self.check_no_wild_output();
        report
    }

    fn check_no_wild_output(&mut self) {
        let now = self.bus.now_ms();
        let mask = self.acq.config().resolution.raw_mask();
        for k in 0..self.last_good.len() {
            let rom = self.bus.with_device(k, |d| d.rom).unwrap();
            let Some(ch) = self.acq.map().channel_of(&rom) else {
                continue;
            };
            let v = self.acq.value(ch, now);
            let truth = self.bus.with_device(k, |d| d.temperature).unwrap() & mask;
            let previous = std::mem::replace(&mut self.previous_truth[k], truth);
            match v.validity {
                Validity::Fresh => {
                    assert_eq!(v.state, ChannelState::Ok);
                    if !(self.allow_one_cycle_old && v.raw == previous) {
                        assert_eq!(
                            v.raw, truth,
                            "device {k}: fresh value is not its temperature"
                        );
                    }
                    self.last_good[k] = Some(v.raw);
                }
                Validity::Held => {
                    assert!(v.state.is_fault(), "{:?}", v.state);
                    assert_eq!(Some(v.raw), self.last_good[k], "device {k}: held value");
                }
                Validity::Invalid => assert_eq!(v.usable(), None),
            }
        }
    }

    /// Cycles until `hold_ms` has passed since the last good reading of
    /// `device`, asserting its state all along.
    fn run_past_hold(&mut self, device: usize, expected: ChannelState) {
        let hold = self.acq.config().hold_ms;
        let start = self.bus.now_ms();
        while self.bus.now_ms() <= start + hold {
            self.bus.advance_ns(9_000 * MS);
            self.cycle();
            assert_eq!(self.state(device), expected);
        }
        assert_eq!(self.validity(device), Validity::Invalid);
    }
}

// --- no presence on one sensor -------------------------------------------

#[test]
fn a_sensor_without_presence_pulse_among_others_still_reads() {
    // Presence is a wired-OR: the others' pulse covers it, and its data is
    // CRC-checked like any other.
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus
        .with_device(1, |d| d.set_fault(Fault::NoPresencePulse));
    for i in 0..5 {
        rig.bus.with_device(1, |d| d.temperature = 300 + i);
        let report = rig.cycle();
        assert_eq!(report.ok, 3);
        assert_eq!(report.retries, 0);
    }
}

#[test]
fn a_lone_sensor_without_presence_pulse_is_no_presence_then_recovers() {
    let mut rig = Rig::new(1, AcquisitionConfig::default());
    rig.bus
        .with_device(0, |d| d.set_fault(Fault::NoPresencePulse));
    rig.cycle();
    assert_eq!(rig.state(0), ChannelState::NoPresence);
    assert_eq!(rig.validity(0), Validity::Held);
    rig.run_past_hold(0, ChannelState::NoPresence);
    rig.bus.with_device(0, |d| d.set_fault(Fault::None));
    rig.cycle();
    assert_eq!(rig.state(0), ChannelState::Intermittent);
    rig.cycle();
    assert_eq!(rig.state(0), ChannelState::Ok);
}

// --- sensors added and removed at run time ----------------------------------

#[test]
fn a_sensor_unplugged_and_plugged_back_is_disconnected_then_reconfigured() {
    let config = AcquisitionConfig {
        resolution: Resolution::Bits11,
        ..AcquisitionConfig::default()
    };
    let mut rig = Rig::new(3, config);
    rig.bus.unplug(1);
    rig.cycle();
    assert_eq!(rig.state(1), ChannelState::Disconnected);
    assert_eq!(rig.validity(1), Validity::Held);
    for k in [0, 2] {
        assert_eq!(rig.state(k), ChannelState::Ok);
    }
    rig.run_past_hold(1, ChannelState::Disconnected);
    // Plugged back: it powers up (85.0 °C, 12 bit and factory TH/TL from
    // EEPROM). Its first conversion runs at 12 bit, longer than the 11-bit
    // wait: the register still holds the power-on value.
    rig.bus.with_device(1, |d| d.temperature = 22 * 16);
    rig.bus.plug(1);
    let report = rig.cycle();
    assert_eq!(rig.state(1), ChannelState::PowerOnValue);
    assert_eq!(report.reconfigured, 1);
    assert_eq!(
        rig.bus.with_device(1, |d| d.scratchpad_config()).unwrap(),
        [MARKER_TH, MARKER_TL, Resolution::Bits11.config_byte()]
    );
    rig.cycle();
    assert_eq!(rig.state(1), ChannelState::Ok);
    assert_eq!(rig.validity(1), Validity::Fresh);
}

#[test]
fn a_sensor_replugged_that_converts_is_config_lost_for_one_cycle() {
    // Same resolution in EEPROM and configuration: the replugged sensor
    // converts in time, but its TH/TL show it was reset.
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.unplug(2);
    rig.cycle();
    assert_eq!(rig.state(2), ChannelState::Disconnected);
    rig.bus.plug(2);
    let report = rig.cycle();
    assert_eq!(rig.state(2), ChannelState::ConfigLost);
    assert_eq!(rig.validity(2), Validity::Held);
    assert_eq!(report.reconfigured, 1);
    rig.cycle();
    assert_eq!(rig.state(2), ChannelState::Ok);
}

#[test]
fn a_sensor_added_at_run_time_is_mapped_without_disturbing_the_others() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    let before = *rig.acq.map();
    let added = rig
        .bus
        .attach(Ds18b20::new(Ds18b20::rom_for(0x00AD_DED0), 31 * 16));
    rig.last_good.push(None);
    rig.previous_truth.push(0);
    // Not mapped yet: the cycle ignores it (and it ignores nothing else).
    let report = rig.cycle();
    assert_eq!(report.ok, 3);
    assert_eq!(block_on(rig.acq.discover(&mut master(&rig.bus))), Ok(4));
    for k in 0..3 {
        let rom = rig.bus.with_device(k, |d| d.rom).unwrap();
        assert_eq!(rig.acq.map().channel_of(&rom), before.channel_of(&rom));
    }
    // First reading: never configured (factory TH/TL), so not used; the
    // configuration is written.
    let report = rig.cycle();
    assert_eq!(rig.state(added), ChannelState::Pending);
    assert_eq!(report.reconfigured, 1);
    rig.cycle();
    assert_eq!(rig.state(added), ChannelState::Ok);
    assert_eq!(rig.last_good[added], Some(31 * 16));
}

#[test]
fn a_sensor_removed_at_run_time_keeps_its_channel_through_discovery() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    let ch = rig.channel(0);
    rig.bus.unplug(0);
    assert_eq!(block_on(rig.acq.discover(&mut master(&rig.bus))), Ok(2));
    // The persisted map keeps the absent sensor on its channel.
    assert_eq!(rig.channel(0), ch);
    rig.cycle();
    assert_eq!(rig.state(0), ChannelState::Disconnected);
    // Every sensor gone: no presence anywhere.
    rig.bus.unplug(1);
    rig.bus.unplug(2);
    rig.cycle();
    for k in 0..3 {
        assert_eq!(rig.state(k), ChannelState::NoPresence);
    }
}

// --- errors during the ROM search -------------------------------------------

/// Device indices in the order the search finds them (0 branch first, bit 0
/// first).
fn search_order(bus: &Bus) -> Vec<usize> {
    let key =
        |r: &RomCode| -> Vec<bool> { (0..64).map(|i| r.0[i / 8] & (1 << (i % 8)) != 0).collect() };
    let mut order: Vec<usize> = (0..bus.device_count()).collect();
    order.sort_by_key(|&k| key(&bus.with_device(k, |d| d.rom).unwrap()));
    order
}

fn mapped_roms(acq: &TemperatureAcquisition) -> Vec<RomCode> {
    (0..20).filter_map(|c| acq.map().get(c)).collect()
}

#[test]
fn a_crc_error_during_the_search_is_retried() {
    let bus = bus_with_sensors(5, 0x5EA2_C400, 20 * 16);
    // Five passes find five sensors: the burst spoils every pass of the
    // first search, including the one that would find the last sensor.
    let last = *search_order(&bus).last().unwrap();
    bus.with_device(last, |d| d.set_fault(Fault::SearchCorrupt(5)));
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(5));
    assert_eq!(acq.map().len(), 5);
}

#[test]
fn a_persistent_crc_error_during_the_search_maps_only_codes_that_exist() {
    let bus = bus_with_sensors(5, 0x5EA2_C400, 20 * 16);
    let last = *search_order(&bus).last().unwrap();
    bus.with_device(last, |d| d.set_fault(Fault::SearchCorrupt(u32::MAX)));
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    let result = block_on(acq.discover(&mut master(&bus)));
    assert!(
        matches!(result, Err(SearchError::Crc | SearchError::NoResponse)),
        "{result:?}"
    );
    // The four found before the failing one are mapped, nothing else.
    let mapped = mapped_roms(&acq);
    let on_bus: Vec<RomCode> = (0..5)
        .map(|k| bus.with_device(k, |d| d.rom).unwrap())
        .collect();
    assert_eq!(mapped.len(), 4);
    for rom in &mapped {
        assert!(rom.is_valid());
        assert!(on_bus.contains(rom));
    }
    assert!(!mapped.contains(&on_bus[last]));
    // They read normally.
    block_on(acq.configure(&mut master(&bus))).unwrap();
    let report = block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), bus.now_ms()));
    assert_eq!(report.ok, 4);
}

#[test]
fn a_device_vanishing_during_the_search_is_retried() {
    let bus = bus_with_sensors(5, 0x5EA2_C401, 20 * 16);
    let last = *search_order(&bus).last().unwrap();
    bus.with_device(last, |d| d.set_fault(Fault::SearchDropout(2)));
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(5));
    // For good: no response, the others mapped.
    bus.with_device(last, |d| d.set_fault(Fault::SearchDropout(u32::MAX)));
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    assert_eq!(
        block_on(acq.discover(&mut master(&bus))),
        Err(SearchError::NoResponse)
    );
    assert_eq!(acq.map().len(), 4);
    assert!(mapped_roms(&acq).iter().all(|r| r.is_valid()));
}

#[test]
fn a_data_contact_back_after_minutes_does_not_serve_its_old_conversion() {
    // The data wire (not the supply) is off for ten minutes and comes back
    // after this cycle's Convert T: the register still holds the conversion
    // from before the outage, with a valid CRC and the marker.
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    let before = rig.bus.with_device(1, |d| d.register()).unwrap();
    rig.bus.with_device(1, |d| d.set_fault(Fault::Silent));
    for minute in 1..=10 {
        rig.bus
            .with_device(1, |d| d.temperature = before + 4 * minute);
        rig.bus.advance_ns(59_000 * MS);
        rig.cycle();
        assert_eq!(rig.state(1), ChannelState::Disconnected);
    }
    // Back 30 falling edges into the next cycle: after Skip ROM + Convert T
    // (17 edges), during the wait for the conversion.
    rig.bus
        .schedule(Trigger::AfterFalls(30), LineEvent::SetFault(1, Fault::None));
    rig.cycle();
    assert_eq!(rig.bus.pending_events(), 0);
    assert_eq!(
        rig.bus.with_device(1, |d| d.register()).unwrap(),
        before,
        "the register is ten minutes old"
    );
    assert_eq!(rig.state(1), ChannelState::Intermittent);
    assert_eq!(rig.validity(1), Validity::Invalid);
    // Present through a whole cycle: its own conversion, used.
    rig.cycle();
    assert_eq!(rig.state(1), ChannelState::Ok);
    assert_eq!(rig.last_good[1], Some(before + 40));
}

// --- faults in the middle of a transaction -----------------------------------

#[test]
fn a_short_glitch_in_the_middle_of_a_read_is_retried() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.schedule(
        Trigger::ReadBit { device: 1, bit: 20 },
        LineEvent::Short { falls: 5 },
    );
    let report = rig.cycle();
    assert_eq!(rig.bus.pending_events(), 0, "the glitch happened");
    assert_eq!(report.retries, 1);
    assert_eq!(report.ok, 3);
}

#[test]
fn a_short_from_the_middle_of_a_read_on_is_all_zero() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.schedule(
        Trigger::ReadBit { device: 1, bit: 30 },
        LineEvent::Short { falls: 10_000 },
    );
    rig.cycle();
    assert_eq!(rig.bus.pending_events(), 0);
    let ch1 = rig.channel(1);
    for k in 0..3 {
        // Channels read before the short are good, the rest all zero.
        let expected = if rig.channel(k) < ch1 {
            ChannelState::Ok
        } else {
            ChannelState::AllZero
        };
        assert_eq!(rig.state(k), expected, "device {k}");
    }
}

#[test]
fn a_short_from_the_middle_of_a_match_rom_on_is_all_zero() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.schedule(
        Trigger::MatchBit { device: 1, bit: 30 },
        LineEvent::Short { falls: 10_000 },
    );
    rig.cycle();
    assert_eq!(rig.bus.pending_events(), 0);
    let ch1 = rig.channel(1);
    for k in 0..3 {
        let expected = if rig.channel(k) < ch1 {
            ChannelState::Ok
        } else {
            ChannelState::AllZero
        };
        assert_eq!(rig.state(k), expected, "device {k}");
    }
    // Still shorted at the next Convert T: every channel, held.
    rig.cycle();
    for k in 0..3 {
        assert_eq!(rig.state(k), ChannelState::AllZero);
        assert_eq!(rig.validity(k), Validity::Held);
    }
    // Short gone: every channel back at once (a short is not an absence).
    rig.bus.set_short(false);
    let report = rig.cycle();
    assert_eq!(report.ok, 3);
}

#[test]
fn a_cable_cut_in_the_middle_of_a_read_is_no_presence() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.schedule(
        Trigger::ReadBit { device: 0, bit: 10 },
        LineEvent::Open { falls: 10_000 },
    );
    rig.cycle();
    let ch0 = rig.channel(0);
    for k in 0..3 {
        let expected = if rig.channel(k) < ch0 {
            ChannelState::Ok
        } else {
            ChannelState::NoPresence
        };
        assert_eq!(rig.state(k), expected, "device {k}");
    }
}

#[test]
fn a_brownout_in_the_middle_of_a_read_is_the_power_on_value() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.bus.schedule(
        Trigger::ReadBit { device: 1, bit: 30 },
        LineEvent::PowerOnReset(1),
    );
    let report = rig.cycle();
    // The cut read fails its CRC; the retry reads the power-on contents.
    assert_eq!(report.retries, 1);
    assert_eq!(rig.state(1), ChannelState::PowerOnValue);
    assert_eq!(rig.validity(1), Validity::Held);
    assert_eq!(report.reconfigured, 1);
    rig.bus.with_device(1, |d| d.temperature += 1);
    rig.cycle();
    assert_eq!(rig.state(1), ChannelState::Ok);
}

// --- a read cut off partway ---------------------------------------------------

#[test]
fn a_read_cut_off_at_any_bit_never_gives_a_wrong_value() {
    let mut rig = Rig::new(2, AcquisitionConfig::default());
    let (mut crc_errors, mut passed_crc) = (0, 0);
    for bits in 0..72u8 {
        // Each cut on a new temperature, so an old value cannot pass.
        rig.bus.with_device(0, |d| {
            d.temperature = 300 + i16::from(bits % 8);
            d.set_fault(Fault::CutRead { bits });
        });
        rig.cycle();
        let state = rig.state(0);
        match bits {
            // Nothing sent: nine bytes of ones.
            0 => assert_eq!(state, ChannelState::Disconnected),
            // The bits sent were ones up to the cut; or the cut bytes
            // happened to pass the CRC: then the marker bytes (2..5) must
            // be whole, and the temperature before them is whole too (the
            // rig checks the value).
            _ => assert!(
                matches!(
                    state,
                    ChannelState::CrcError | ChannelState::ConfigLost | ChannelState::Disconnected
                ) || (state == ChannelState::Ok && bits >= 40),
                "cut after {bits} bits: {state:?}"
            ),
        }
        crc_errors += usize::from(state == ChannelState::CrcError);
        passed_crc += usize::from(state == ChannelState::Ok);
        assert_eq!(rig.state(1), ChannelState::Ok);
        // Healthy again before the next cut.
        rig.bus.with_device(0, |d| d.set_fault(Fault::None));
        rig.cycle();
        rig.cycle();
        assert_eq!(rig.state(0), ChannelState::Ok, "after the cut at {bits}");
    }
    println!("cut reads: {crc_errors} CRC errors, {passed_crc} passed the CRC");
    assert!(crc_errors >= 60, "{crc_errors}");
}

// --- configuration changed under a valid CRC ----------------------------------

#[test]
fn a_resolution_reset_after_a_brownout_is_noticed_and_rewritten() {
    let config = AcquisitionConfig {
        resolution: Resolution::Bits10,
        ..AcquisitionConfig::default()
    };
    let mut rig = Rig::new(3, config);
    // Brownout between cycles: 12 bit and factory TH/TL from EEPROM; the
    // 12-bit conversion outlasts the 10-bit wait.
    rig.bus.with_device(0, |d| d.power_on_reset());
    let report = rig.cycle();
    assert!(report.conversion_timeout);
    assert_eq!(rig.state(0), ChannelState::PowerOnValue);
    assert_eq!(report.reconfigured, 1);
    assert_eq!(
        rig.bus.with_device(0, |d| d.resolution()).unwrap(),
        Resolution::Bits10
    );
    let report = rig.cycle();
    assert!(!report.conversion_timeout);
    assert_eq!(report.ok, 3);
}

#[test]
fn a_changed_configuration_byte_with_a_valid_crc_is_rewritten() {
    let config = AcquisitionConfig {
        resolution: Resolution::Bits10,
        ..AcquisitionConfig::default()
    };
    let mut rig = Rig::new(3, config);
    // The configuration register alone flips to 12 bit; TH/TL intact. The
    // device computes its CRC over it: only the acquisition can notice.
    rig.bus
        .with_device(2, |d| d.set_scratchpad_config([MARKER_TH, MARKER_TL, 0x7F]));
    let report = rig.cycle();
    assert_eq!(rig.state(2), ChannelState::ConfigLost);
    assert_eq!(rig.validity(2), Validity::Held);
    assert_eq!(report.reconfigured, 1);
    assert_eq!(
        rig.bus.with_device(2, |d| d.scratchpad_config()).unwrap(),
        [MARKER_TH, MARKER_TL, Resolution::Bits10.config_byte()]
    );
    rig.bus.with_device(2, |d| d.temperature += 4);
    rig.cycle();
    assert_eq!(rig.state(2), ChannelState::Ok);
}

#[test]
fn changed_alarm_bytes_alone_mean_a_reset() {
    let mut rig = Rig::new(2, AcquisitionConfig::default());
    rig.bus
        .with_device(1, |d| d.set_scratchpad_config([0x4B, 0x46, 0x7F]));
    let report = rig.cycle();
    assert_eq!(rig.state(1), ChannelState::ConfigLost);
    assert_eq!(report.reconfigured, 1);
    rig.cycle();
    assert_eq!(rig.state(1), ChannelState::Ok);
}

// --- flapping presence ----------------------------------------------------------

#[test]
fn a_flapping_data_contact_is_retried_or_named_never_wrong() {
    for (on, off) in [(1, 1), (2, 1), (1, 2), (3, 5)] {
        let mut rig = Rig::new(3, AcquisitionConfig::default());
        rig.allow_one_cycle_old = true;
        rig.bus
            .with_device(1, |d| d.set_fault(Fault::FlappingResets { on, off }));
        let mut seen = Vec::new();
        for i in 0..40i16 {
            rig.bus.with_device(1, |d| d.temperature = 300 + i / 4);
            rig.cycle();
            let s = rig.state(1);
            assert!(
                matches!(
                    s,
                    ChannelState::Ok | ChannelState::Disconnected | ChannelState::Intermittent
                ),
                "on {on} off {off}: {s:?}"
            );
            seen.push(s);
            for k in [0, 2] {
                assert_eq!(rig.state(k), ChannelState::Ok);
            }
        }
        println!("on {on} off {off}: {seen:?}");
    }
}

#[test]
fn a_contact_flapping_in_time_cuts_transactions_and_is_named() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    rig.allow_one_cycle_old = true;
    rig.bus.with_device(1, |d| {
        d.set_fault(Fault::FlappingMs {
            on_ms: 170,
            off_ms: 230,
        })
    });
    let mut states = std::collections::BTreeSet::new();
    for i in 0..60i16 {
        rig.bus.with_device(1, |d| d.temperature = 300 + i / 4);
        rig.cycle();
        states.insert(format!("{:?}", rig.state(1)));
    }
    println!("{states:?}");
    for s in &states {
        assert!(
            ["Ok", "Disconnected", "CrcError", "Intermittent"].contains(&s.as_str()),
            "{states:?}"
        );
    }
}

#[test]
fn a_sensor_whose_supply_flaps_is_never_read_as_85_degrees() {
    let mut rig = Rig::new(3, AcquisitionConfig::default());
    let mut states = Vec::new();
    for i in 0..10 {
        if i % 2 == 0 {
            rig.bus.unplug(0);
        } else {
            rig.bus.plug(0);
        }
        rig.cycle();
        states.push(rig.state(0));
    }
    // Every reconnection is a power-up: reset detected each time.
    assert_eq!(
        states,
        [ChannelState::Disconnected, ChannelState::ConfigLost].repeat(5)
    );
    rig.cycle();
    assert_eq!(rig.state(0), ChannelState::Ok);
    assert_ne!(rig.last_good[0], Some(POWER_ON));
}

//! A measured run (the first 8.2 h of the licensed FL_THERMAL excerpt in
//! `demo/trace.csv`: 16 temperatures, spindle idle, 1,250 rpm, cooling) replayed through
//! the emulated sensors and read back by the board's acquisition: every value
//! comes back as the DS18B20 would have reported it (1/16 °C), and real
//! thermal behaviour trips no fault.

use host_tests::onewire_emu::replay::{apply, parse_run};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition, Validity};
use thermocomp_protocol::states::ChannelState;

#[test]
fn measured_spindle_run_comes_back_exactly() {
    // Compiled in: the data is part of the repository, a missing file is a
    // build error, never a silent skip.
    let run = parse_run(include_str!("../../demo/trace.csv")).unwrap();
    assert_eq!(run.samples.len(), 8_892);
    let n = run.header.channels();
    assert_eq!(n, 16);
    let bus = bus_with_sensors(n, 0xCA1F, 0);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    let mut m = master(&bus);
    assert_eq!(block_on(acq.discover(&mut m)), Ok(n));
    assert_eq!(block_on(acq.configure(&mut m)), Ok(true));
    let channel: Vec<usize> = (0..n)
        .map(|k| {
            acq.map()
                .channel_of(&bus.with_device(k, |d| d.rom).unwrap())
                .unwrap()
        })
        .collect();
    // Every sample (15 s): 1,968 cycles over 8.2 h.
    let mut checked = 0;
    let (mut coldest, mut warmest) = (i32::MAX, i32::MIN);
    for sample in run.samples.iter().take(1_968) {
        apply(&bus, sample).unwrap();
        let target = sample.time_ms * MS;
        if bus.now_ns() < target {
            bus.advance_ns(target - bus.now_ns());
        }
        let mut d = bus.delay();
        block_on(acq.cycle(&mut m, &mut d, bus.now_ms()));
        for (k, &ch) in channel.iter().enumerate() {
            let v = acq.value(ch, bus.now_ms());
            assert_eq!(
                v.state,
                ChannelState::Ok,
                "t={} s sensor {k}",
                sample.time_ms / 1000
            );
            assert_eq!(v.validity, Validity::Fresh);
            assert_eq!(Some(i32::from(v.raw)), sample.temperatures[k]);
            coldest = coldest.min(i32::from(v.raw));
            warmest = warmest.max(i32::from(v.raw));
            checked += 1;
        }
    }
    assert_eq!(checked, 1_968 * 16);
    // The run really moves: the spindle warms the machine by several kelvin
    // (1/16 °C units), so the readings were not one value repeated.
    assert!(warmest - coldest > 5 * 16, "{coldest}..{warmest}");
    assert_eq!(bus.stats().violations.total(), 0);
}

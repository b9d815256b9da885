//! A measured run (CAIVIAC FL_THERMAL, 16 temperatures, 46 h, in
//! `shared/data`) replayed through the emulated sensors and read back by the
//! board's acquisition: every value comes back as the DS18B20 would have
//! reported it (1/16 °C), and real thermal behaviour trips no fault.

use host_tests::onewire_emu::replay::{apply, parse_run};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition, Validity};
use thermocomp::process_image::ChannelState;

#[test]
fn measured_spindle_run_comes_back_exactly() {
    let path = host_tests::qemu::workspace_root().join("../shared/data/caiviac-fl-thermal/run.csv");
    let Ok(text) = std::fs::read_to_string(&path) else {
        eprintln!("skipped: {} not present", path.display());
        return;
    };
    let run = parse_run(&text).unwrap();
    let n = run.header.channels();
    assert_eq!(n, 16);
    let bus = bus_with_sensors(n, 0xCA1F, 0);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    let mut m = master(&bus);
    assert_eq!(block_on(acq.discover(&mut m)), Ok(n));
    let channel: Vec<usize> = (0..n)
        .map(|k| {
            acq.map()
                .channel_of(&bus.with_device(k, |d| d.rom).unwrap())
                .unwrap()
        })
        .collect();
    // Every 4th sample (1 min): 2,779 cycles over 46 h.
    let mut checked = 0;
    for sample in run.samples.iter().step_by(4) {
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
            checked += 1;
        }
    }
    assert!(checked > 40_000, "{checked}");
    assert_eq!(bus.stats().violations.total(), 0);
}

//! The emulated DS18B20 bus of the bench board and the application's real
//! acquisition on it: one emulated sensor per trace column.

use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{
    AcquisitionConfig, CycleReport, TemperatureAcquisition,
};
use thermocomp::runtime;
use thermocomp_protocol::trace::TraceSample;

use crate::emulated_bus::EmulatedBus;
use crate::exit::exit_code;
use crate::semihost::{self, log};

pub struct Sensors {
    pub bus: EmulatedBus,
    pub acquisition: TemperatureAcquisition,
    /// Emulated sensors on the bus (one per trace column).
    channels: usize,
}

impl Sensors {
    /// One emulated sensor per trace column, and the channel map that puts
    /// them on channels in column order (the configured map, as the
    /// engineer would persist it).
    pub fn emulate(channels: usize) -> (Sensors, ChannelMap) {
        let bus = EmulatedBus::new(channels);
        let mut map = ChannelMap::new();
        for c in 0..channels {
            if map.set(c, bus.rom(c)).is_err() {
                log!("channel map refused channel {}", c);
                semihost::exit(exit_code::SELFTEST_FAILED)
            }
        }
        let acquisition =
            TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        (
            Sensors {
                bus,
                acquisition,
                channels,
            },
            map,
        )
    }

    /// A ROM search that must find every emulated sensor, then `map` in
    /// force and every sensor configured; anything else ends the run.
    pub async fn start(&mut self, map: ChannelMap) {
        let channels = self.channels;
        let start = runtime::start_sensors(&mut self.acquisition, &mut self.bus, Some(map)).await;
        match start.found {
            Ok(n) if n == channels => {}
            other => {
                log!("ROM search found {:?} of {} sensors", other, channels);
                semihost::exit(exit_code::SELFTEST_FAILED)
            }
        }
        if !start.configured {
            log!("sensor configuration failed");
            semihost::exit(exit_code::SELFTEST_FAILED)
        }
    }

    /// Put the sample's temperatures on the emulated sensors and run one
    /// acquisition cycle at the sample's time.
    pub async fn acquire(&mut self, sample: &TraceSample) -> CycleReport {
        put_sample(&mut self.bus, sample);
        self.acquisition
            .cycle(&mut self.bus, &mut embassy_time::Delay, sample.time_ms)
            .await
    }
}

/// The sample's temperatures onto the emulated sensors (read at the next
/// Convert T).
pub fn put_sample(bus: &mut EmulatedBus, sample: &TraceSample) {
    for (c, t) in sample.temperatures.iter().enumerate() {
        // A value outside i16 cannot come from a DS18B20: the sensor is
        // treated as absent, and acquisition reports it.
        bus.set_temperature(c, t.and_then(|v| i16::try_from(v).ok()));
    }
}

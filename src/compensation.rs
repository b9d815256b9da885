//! Application glue between acquisition and the math core: resolve the
//! model's sensors to bus channels, hand the core fresh or held values (never
//! a faulty one), and keep the compensator's state between cycles.

use crate::acquisition::channel_map::ChannelMap;
use crate::acquisition::rom::RomCode;
use crate::acquisition::temperature::{TemperatureAcquisition, Validity};
use thermocomp_core::image::SensorRef;
use thermocomp_core::limits::{MAX_AXES, MAX_SENSORS};
use thermocomp_core::volumetric::MAX_VOL_SENSORS;
use thermocomp_core::{Compensator, Model, StepInput, StepOutput};
use thermocomp_protocol::MAX_CHANNELS;

/// Machine data the PLC writes (spindle speed, axis positions), with its age.
#[derive(Debug, Clone, Copy, Default)]
pub struct PlcInputs {
    pub spindle_rpm: i32,
    /// µm (or 0.001°), in the model's axis order.
    pub positions: [i32; MAX_AXES],
    /// The PLC has not written for longer than its timeout.
    pub stale: bool,
}

pub struct Compensation {
    compensator: Compensator,
    /// Bus channel of each model sensor; `None` when the model names a ROM
    /// code that is not on the bus (that input is then invalid).
    channel_of: [Option<u8>; MAX_SENSORS],
    /// Bus channel of each sensor of the volumetric section (same rule).
    vol_channel_of: [Option<u8>; MAX_VOL_SENSORS],
}

/// The bus channel a sensor record names: its channel when the ROM code is
/// all zero, else where the channel map has that ROM code (`None`: not on the bus).
fn resolve(s: &SensorRef, map: &ChannelMap) -> Option<u8> {
    if s.rom == [0; 8] {
        (usize::from(s.channel) < MAX_CHANNELS).then_some(s.channel)
    } else {
        map.channel_of(&RomCode(s.rom))
            .and_then(|c| u8::try_from(c).ok())
    }
}

impl Compensation {
    pub fn new(model: Option<Model>, map: &ChannelMap) -> Self {
        let mut c = Self::empty();
        c.load(model, map);
        c
    }

    /// `Compensation::new(None, _)` as one value, so that the app can be
    /// built straight into its static (no model on the stack).
    #[inline(always)]
    pub fn empty() -> Self {
        Compensation {
            compensator: Compensator::empty(),
            channel_of: [None; MAX_SENSORS],
            vol_channel_of: [None; MAX_VOL_SENSORS],
        }
    }

    /// Back to [`Compensation::empty`], in place.
    pub fn clear(&mut self) {
        self.compensator.clear();
        self.channel_of = [None; MAX_SENSORS];
        self.vol_channel_of = [None; MAX_VOL_SENSORS];
    }

    /// Swap the model (after an upload) and resolve its sensors again.
    pub fn load(&mut self, model: Option<Model>, map: &ChannelMap) {
        self.compensator.load(model);
        self.resolve(map);
    }

    /// Resolve the model's sensors to bus channels through `map`.
    pub fn resolve(&mut self, map: &ChannelMap) {
        self.channel_of = [None; MAX_SENSORS];
        self.vol_channel_of = [None; MAX_VOL_SENSORS];
        if let Some(m) = self.compensator.model() {
            for (slot, s) in self.channel_of.iter_mut().zip(&m.sensors) {
                *slot = resolve(s, map);
            }
            if let Some(v) = &m.volumetric {
                for (slot, s) in self.vol_channel_of.iter_mut().zip(&v.sensors) {
                    *slot = resolve(&s.sensor, map);
                }
            }
        }
    }

    pub fn compensator(&mut self) -> &mut Compensator {
        &mut self.compensator
    }

    pub fn model(&self) -> Option<&Model> {
        self.compensator.model()
    }

    /// Bus channel feeding model sensor `i`.
    pub fn channel_of(&self, i: usize) -> Option<u8> {
        self.channel_of.get(i).copied().flatten()
    }

    /// Bus channel feeding sensor `i` of the volumetric section.
    pub fn vol_channel_of(&self, i: usize) -> Option<u8> {
        self.vol_channel_of.get(i).copied().flatten()
    }

    /// The volumetric section's sensors on the latest acquisition cycle
    /// (1/16 °C; `None`: faulty or not on the bus) and whether one is a
    /// held rather than a fresh value.
    pub fn vol_temperatures(
        &self,
        acq: &TemperatureAcquisition,
        now_ms: u64,
    ) -> ([Option<i32>; MAX_VOL_SENSORS], bool) {
        let mut temps = [None; MAX_VOL_SENSORS];
        let mut held = false;
        let n = self
            .model()
            .and_then(|m| m.volumetric.as_ref())
            .map_or(0, |v| v.sensors.len());
        for (t, ch) in temps.iter_mut().zip(self.vol_channel_of.iter()).take(n) {
            if let Some(ch) = ch {
                let v = acq.value(usize::from(*ch), now_ms);
                held |= v.validity == Validity::Held;
                *t = v.usable().map(i32::from);
            }
        }
        (temps, held)
    }

    /// One compensation step on the latest acquisition cycle.
    pub fn step(
        &mut self,
        acq: &TemperatureAcquisition,
        now_ms: u64,
        plc: &PlcInputs,
    ) -> StepOutput {
        let mut temps = [None; MAX_SENSORS];
        let mut stale = plc.stale;
        let n = self.compensator.model().map_or(0, |m| m.sensors.len());
        for (t, ch) in temps.iter_mut().zip(self.channel_of.iter()).take(n) {
            if let Some(ch) = ch {
                let v = acq.value(usize::from(*ch), now_ms);
                stale |= v.validity == Validity::Held;
                *t = v.usable().map(i32::from);
            }
        }
        #[allow(
            clippy::indexing_slicing,
            reason = "n = sensors.len() <= MAX_SENSORS: heapless::Vec<_, MAX_SENSORS>"
        )]
        let temps = &temps[..n];
        self.compensator.step(&StepInput {
            now_ms,
            temps,
            spindle_rpm: plc.spindle_rpm,
            positions: &plc.positions,
            stale,
        })
    }
}

//! What the board reports, as one value the measurement cycle publishes
//! and every read is answered from (the Modbus codec, `modbus/registers.rs`,
//! encodes it into input registers): a 32-bit value or an axis block read in one
//! request always comes from one snapshot.

use thermocomp_core::eval::AxisPair;
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS, MAX_SENSORS};
use thermocomp_core::volumetric::MAX_VOL_SENSORS;

use thermocomp_protocol::registers::{IR_REF_LAST, IR_REF_TIME, NOT_AVAILABLE_32};
use thermocomp_protocol::MAX_CHANNELS;

use crate::fault::FaultRecord;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Snapshot {
    pub sequence: u32,
    pub status: u16,
    pub heartbeat: u32,
    pub uptime_s: u32,
    /// Time of the compensated sample, s (board uptime, or trace time on the bench).
    pub sample_time_s: u32,
    pub model_version: u32,
    pub model_crc: u32,
    pub n_directions: u16,
    pub n_axes: u16,
    pub n_sensors: u16,
    /// Probe reading, 0.1 µm, and its state code.
    pub probe: i32,
    pub probe_state: u16,
    /// Input register 23: why a probe reference is wanted (0: nothing).
    pub reference_wanted: u16,
    pub corrections: [i32; MAX_DIRECTIONS],
    pub predictions: [i32; MAX_DIRECTIONS],
    pub axes: [AxisPair; MAX_AXES],
    /// 0.01 °C, `None` where no valid value.
    pub temperatures: [Option<i16>; MAX_CHANNELS],
    pub states: [u16; MAX_CHANNELS],
    /// The fault record from before the last reset, until cleared.
    pub fault: Option<FaultRecord>,
    /// Mapped channels whose sensor is missing (bit per channel).
    pub map_missing: u32,
    /// Channels added to the map since boot (bit per channel).
    pub map_added: u32,
    /// Per direction, the model serving it ([`thermocomp_core::compensator::ACTIVE_NONE`]: none).
    pub active: [u8; MAX_DIRECTIONS],
    /// ROM code per channel, bus order (all zero: unmapped).
    pub roms: [[u8; 8]; MAX_CHANNELS],
    /// Channel of each model sensor (0xFF: none).
    pub sensor_channels: [u8; MAX_SENSORS],
    /// Model sensors with no answering sensor (bit per model sensor).
    pub sensors_missing: u32,
    /// 0 no kept reference, 1 kept, 2 pending.
    pub reference_state: u16,
    /// The volumetric correction (input registers 180–199).
    pub vol: VolSnapshot,
    /// Probe references (input registers 300–329), as the app published them.
    pub references: [u16; REFERENCE_REGS],
    /// Per direction, steps served beyond the training envelope (360–371).
    pub envelope_steps: [u32; MAX_DIRECTIONS],
}

/// Registers of the probe-reference block (300–329).
pub const REFERENCE_REGS: usize = (IR_REF_LAST - IR_REF_TIME + 1) as usize;

/// The volumetric block of the snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VolSnapshot {
    /// 0.1 µm; [`NOT_AVAILABLE_32`] unless `status` has VALID.
    pub corrections: [i32; 3],
    pub status: u16,
    pub terms: u16,
    /// µm; [`NOT_AVAILABLE_32`] unless VALID.
    pub tool_um: i32,
    /// 1/16 °C per section sensor; `None`: no value (or no such sensor).
    pub temps: [Option<i16>; MAX_VOL_SENSORS],
    pub sequence: u32,
    /// The five-axis part (input registers 330–359).
    pub five: FiveSnapshot,
}

/// The five-axis block of the snapshot (input registers 330–359).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FiveSnapshot {
    /// A and C used, 0.001°; [`NOT_AVAILABLE_32`] unless `status` has INCLUDED.
    pub angles: [i32; 2],
    /// [`thermocomp_core::five_axis::fstatus`] bits.
    pub status: u16,
    /// Fourier order of the section (0: none).
    pub order: u16,
    /// The rotary part alone, 0.1 µm; [`NOT_AVAILABLE_32`] unless INCLUDED.
    pub rotary: [i32; 3],
}

impl Default for FiveSnapshot {
    fn default() -> Self {
        FiveSnapshot {
            angles: [NOT_AVAILABLE_32; 2],
            status: thermocomp_core::five_axis::fstatus::NO_SECTION,
            order: 0,
            rotary: [NOT_AVAILABLE_32; 3],
        }
    }
}

impl Default for VolSnapshot {
    fn default() -> Self {
        VolSnapshot {
            corrections: [NOT_AVAILABLE_32; 3],
            status: thermocomp_core::volumetric::vstatus::NO_SECTION,
            terms: 0,
            tool_um: NOT_AVAILABLE_32,
            temps: [None; MAX_VOL_SENSORS],
            sequence: 0,
            five: FiveSnapshot::default(),
        }
    }
}

impl Default for Snapshot {
    fn default() -> Self {
        Snapshot {
            sequence: 0,
            status: thermocomp_core::compensator::status::NO_MODEL,
            heartbeat: 0,
            uptime_s: 0,
            sample_time_s: 0,
            model_version: 0,
            model_crc: 0,
            n_directions: 0,
            n_axes: 0,
            n_sensors: 0,
            probe: 0,
            probe_state: 0,
            reference_wanted: 0,
            corrections: [0; MAX_DIRECTIONS],
            predictions: [0; MAX_DIRECTIONS],
            axes: [AxisPair::default(); MAX_AXES],
            temperatures: [None; MAX_CHANNELS],
            states: [0; MAX_CHANNELS],
            fault: None,
            map_missing: 0,
            map_added: 0,
            active: [thermocomp_core::compensator::ACTIVE_NONE; MAX_DIRECTIONS],
            roms: [[0; 8]; MAX_CHANNELS],
            sensor_channels: [0xFF; MAX_SENSORS],
            sensors_missing: 0,
            reference_state: 0,
            vol: VolSnapshot::default(),
            references: [0; REFERENCE_REGS],
            envelope_steps: [0; MAX_DIRECTIONS],
        }
    }
}

/// 1/16 °C → 0.01 °C (×6.25, rounded half away from zero), saturating.
pub fn centidegrees(sixteenths: i16) -> i16 {
    let v = i32::from(sixteenths) * 25;
    let r = if v >= 0 { (v + 2) / 4 } else { (v - 2) / 4 };
    let saturated = r.clamp(i32::from(i16::MIN) + 1, i32::from(i16::MAX));
    i16::try_from(saturated).unwrap_or(i16::MAX)
}

//! Input registers (FC04): one [`Snapshot`] of everything the board reports.
//! A request is answered from one snapshot, so every 32-bit value and every
//! axis block in it is consistent; the sequence number (also inside each
//! axis block) tells a PLC whether two requests saw the same snapshot.
//! 32-bit values: high word first (register n = bits 31..16).

use thermocomp_core::eval::AxisPair;
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS, MAX_SENSORS};
use thermocomp_core::volumetric::MAX_VOL_SENSORS;

use crate::fault::FaultRecord;
use crate::process_image::MAX_CHANNELS;

/// Version of this register map (input register 2), so a PLC can tell which
/// blocks the board serves. 2 added input registers 150–299, status bits 8–9,
/// holding registers 34–35 and commands 6–11 to version 1 (README).
pub const MAP_VERSION: u16 = 2;
pub const TEST_PATTERN: u32 = 0x1234_5678;
/// "Not available" for 16-bit measurements.
pub const NOT_AVAILABLE: u16 = 0x8000;

pub const IR_TEST_PATTERN: u16 = 0;
pub const IR_MAP_VERSION: u16 = 2;
pub const IR_STATUS: u16 = 3;
pub const IR_SEQUENCE: u16 = 4;
pub const IR_HEARTBEAT: u16 = 6;
pub const IR_UPTIME: u16 = 8;
pub const IR_SAMPLE_TIME: u16 = 10;
pub const IR_MODEL_VERSION: u16 = 12;
pub const IR_MODEL_CRC: u16 = 14;
pub const IR_N_DIRECTIONS: u16 = 16;
pub const IR_N_AXES: u16 = 17;
pub const IR_N_SENSORS: u16 = 18;
pub const IR_PROBE: u16 = 20;
pub const IR_PROBE_STATE: u16 = 22;
/// Served correction per direction, int32 0.1 µm, 2 registers each.
pub const IR_CORRECTIONS: u16 = 30;
/// Model prediction before clamp/rate limit, int32 0.1 µm, 2 registers each.
pub const IR_PREDICTIONS: u16 = 42;
/// Axis blocks: offset int32 0.1 µm, slope int32 0.01 µm/m, reference
/// position int32 µm, sequence u32: 8 registers each.
pub const IR_AXES: u16 = 60;
pub const AXIS_BLOCK: u16 = 8;
/// Sensor temperatures, int16 0.01 °C (0x8000: not available).
pub const IR_TEMPERATURES: u16 = 110;
/// Sensor states ([`crate::process_image::ChannelState::code`]).
pub const IR_STATES: u16 = 130;
/// Active model per direction: 0 main, k fallback k, 0xFFFF none (held / no model).
pub const IR_ACTIVE_MODEL: u16 = 150;
/// Bit d: direction d is served by a fallback model.
pub const IR_DEGRADED_DIRECTIONS: u16 = 156;
/// Bit d: direction d has no usable model (held).
pub const IR_HELD_DIRECTIONS: u16 = 157;
/// Last input register: the end of the sensor-identity block (158–159,
/// 169, 174–179, 196–199 and 293–299 reserved, read 0).
pub const IR_LAST: u16 = IR_IDENTITY_LAST;

/// "Not available" for 32-bit measurements: reads 0x8000, 0x0000 (i32::MIN).
pub const NOT_AVAILABLE_32: i32 = i32::MIN;
/// The volumetric correction (image section kind 3, issue 14): x, y, z,
/// int32 0.1 µm each ([`NOT_AVAILABLE_32`] unless status bit 0), 180–185.
pub const IR_VOL_CORRECTION: u16 = 180;
/// Volumetric status bits ([`thermocomp_core::volumetric::vstatus`]).
pub const IR_VOL_STATUS: u16 = 186;
/// Terms of the image's volumetric section (0: none).
pub const IR_VOL_TERMS: u16 = 187;
/// Tool length the correction used (after clamping), int32 µm.
pub const IR_VOL_TOOL: u16 = 188;
/// Temperatures the correction used, per section sensor, int16 1/16 °C
/// (the sensor's own unit; 0x8000 none), 190–193.
pub const IR_VOL_TEMPS: u16 = 190;
/// Evaluations since boot, u32 (a PLC that wrote positions waits for it to move).
pub const IR_VOL_SEQUENCE: u16 = 194;
/// Last register of the volumetric block (180–199).
pub const IR_VOL_LAST: u16 = 199;

/// Status bit 9: a fault record from before the last reset is held (input
/// registers 160–168) until command 6 clears it.
pub const STATUS_FAULT_RECORDED: u16 = 1 << 9;
/// The fault record ([`crate::fault::FaultRecord`]): kind (160), program
/// counter u32 (161–162), uptime at the fault u32 s (163–164), faults since
/// the record was cleared u32 (165–166), detail u32 (167–168); all 0 when
/// no record is held. 169, 174–179 reserved (read 0).
pub const IR_FAULT_KIND: u16 = 160;
pub const IR_FAULT_PC: u16 = 161;
pub const IR_FAULT_UPTIME: u16 = 163;
pub const IR_FAULT_COUNT: u16 = 165;
pub const IR_FAULT_DETAIL: u16 = 167;
/// Sensor identity: mapped channels whose sensor (ROM code) does not answer,
/// u32 bit mask, bit c = channel c (172–173: channels added to the map since
/// boot, new sensors on free channels). Always served.
pub const IR_MAP_MISSING: u16 = 170;
pub const IR_MAP_ADDED: u16 = 172;
/// Last register of the board-safety block (160–179).
pub const IR_SAFETY_LAST: u16 = 179;

/// Sensor identity block (200–299). ROM code of each channel's sensor, 4
/// registers per channel (channel c at 200 + 4c), the 8 bytes in bus order
/// (family code first: high byte of the first register, CRC last); all
/// zero for an unmapped channel.
pub const IR_CHANNEL_ROMS: u16 = 200;
/// The channel each model sensor reads, two per register (sensor 2k in the
/// high byte, 2k + 1 in the low byte; 0xFF: none — its ROM is not in the
/// channel map, or no such sensor), registers 280–289.
pub const IR_SENSOR_CHANNELS: u16 = 280;
/// Model sensors with no answering sensor (u32, bit i = model sensor i:
/// its ROM is not on the bus or its channel does not answer); their inputs
/// are invalid (degraded mode or held), never another sensor's value.
pub const IR_SENSORS_MISSING: u16 = 290;
/// The kept reference (commands 10/11): 0 none, 1 kept and in use, 2 to be
/// taken at the next cycle with every model sensor fresh.
pub const IR_REFERENCE_STATE: u16 = 292;
/// Last register of the identity block (293–299 reserved, read 0).
pub const IR_IDENTITY_LAST: u16 = 299;

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
}

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
        }
    }
}

/// 1/16 °C → 0.01 °C (×6.25, rounded half away from zero), saturating.
pub fn centidegrees(sixteenths: i16) -> i16 {
    let v = i32::from(sixteenths) * 25;
    let r = if v >= 0 { (v + 2) / 4 } else { (v - 2) / 4 };
    r.clamp(i32::from(i16::MIN) + 1, i32::from(i16::MAX)) as i16
}

fn hi(v: u32) -> u16 {
    (v >> 16) as u16
}

fn lo(v: u32) -> u16 {
    v as u16
}

/// Word `k` (0: high) of a 32-bit value starting at `base`, if `addr` is in it.
fn word32(addr: u16, base: u16, v: u32) -> Option<u16> {
    match addr.checked_sub(base)? {
        0 => Some(hi(v)),
        1 => Some(lo(v)),
        _ => None,
    }
}

impl Snapshot {
    /// The value of input register `addr`, or `None` past the end of the map
    /// (the server answers ILLEGAL DATA ADDRESS). Reserved gaps read 0.
    pub fn input_register(&self, addr: u16) -> Option<u16> {
        if (IR_FAULT_KIND..=IR_SAFETY_LAST).contains(&addr) {
            return Some(self.safety_register(addr));
        }
        if (IR_CHANNEL_ROMS..=IR_IDENTITY_LAST).contains(&addr) {
            return Some(self.identity_register(addr));
        }
        if (IR_VOL_CORRECTION..=IR_VOL_LAST).contains(&addr) {
            return Some(self.vol_register(addr));
        }
        if addr > IR_LAST {
            return None;
        }
        let in_block = |base: u16, n: u16| addr >= base && addr < base + n;
        let v = if let Some(w) = word32(addr, IR_TEST_PATTERN, TEST_PATTERN) {
            w
        } else if addr == IR_MAP_VERSION {
            MAP_VERSION
        } else if addr == IR_STATUS {
            self.status
                | if self.fault.is_some() {
                    STATUS_FAULT_RECORDED
                } else {
                    0
                }
        } else if let Some(w) = word32(addr, IR_SEQUENCE, self.sequence) {
            w
        } else if let Some(w) = word32(addr, IR_HEARTBEAT, self.heartbeat) {
            w
        } else if let Some(w) = word32(addr, IR_UPTIME, self.uptime_s) {
            w
        } else if let Some(w) = word32(addr, IR_SAMPLE_TIME, self.sample_time_s) {
            w
        } else if let Some(w) = word32(addr, IR_MODEL_VERSION, self.model_version) {
            w
        } else if let Some(w) = word32(addr, IR_MODEL_CRC, self.model_crc) {
            w
        } else if addr == IR_N_DIRECTIONS {
            self.n_directions
        } else if addr == IR_N_AXES {
            self.n_axes
        } else if addr == IR_N_SENSORS {
            self.n_sensors
        } else if let Some(w) = word32(addr, IR_PROBE, self.probe as u32) {
            w
        } else if addr == IR_PROBE_STATE {
            self.probe_state
        } else if in_block(IR_CORRECTIONS, 2 * MAX_DIRECTIONS as u16) {
            let k = addr - IR_CORRECTIONS;
            let v = self.corrections[usize::from(k / 2) % MAX_DIRECTIONS] as u32;
            if k.is_multiple_of(2) {
                hi(v)
            } else {
                lo(v)
            }
        } else if in_block(IR_PREDICTIONS, 2 * MAX_DIRECTIONS as u16) {
            let k = addr - IR_PREDICTIONS;
            let v = self.predictions[usize::from(k / 2) % MAX_DIRECTIONS] as u32;
            if k.is_multiple_of(2) {
                hi(v)
            } else {
                lo(v)
            }
        } else if in_block(IR_AXES, AXIS_BLOCK * MAX_AXES as u16) {
            let k = addr - IR_AXES;
            let a = self.axes[usize::from(k / AXIS_BLOCK) % MAX_AXES];
            let field = [
                a.offset as u32,
                a.slope as u32,
                a.ref_pos as u32,
                self.sequence,
            ];
            let v = field[usize::from((k % AXIS_BLOCK) / 2)];
            if k.is_multiple_of(2) {
                hi(v)
            } else {
                lo(v)
            }
        } else if in_block(IR_TEMPERATURES, MAX_CHANNELS as u16) {
            let t = self.temperatures[usize::from(addr - IR_TEMPERATURES) % MAX_CHANNELS];
            t.map_or(NOT_AVAILABLE, |v| v as u16)
        } else if in_block(IR_STATES, MAX_CHANNELS as u16) {
            self.states[usize::from(addr - IR_STATES) % MAX_CHANNELS]
        } else if in_block(IR_ACTIVE_MODEL, MAX_DIRECTIONS as u16) {
            match self.active[usize::from(addr - IR_ACTIVE_MODEL) % MAX_DIRECTIONS] {
                thermocomp_core::compensator::ACTIVE_NONE => 0xFFFF,
                k => u16::from(k),
            }
        } else if addr == IR_DEGRADED_DIRECTIONS || addr == IR_HELD_DIRECTIONS {
            let want = |a: u8| match addr {
                IR_DEGRADED_DIRECTIONS => a != 0 && a != thermocomp_core::compensator::ACTIVE_NONE,
                _ => a == thermocomp_core::compensator::ACTIVE_NONE,
            };
            let n = usize::from(self.n_directions).min(MAX_DIRECTIONS);
            self.active[..n]
                .iter()
                .enumerate()
                .filter(|(_, &a)| want(a))
                .fold(0u16, |m, (d, _)| m | (1 << d))
        } else {
            0
        };
        Some(v)
    }
}

impl Snapshot {
    /// Input registers 200–299: sensor identity and the kept reference.
    fn identity_register(&self, addr: u16) -> u16 {
        let k = usize::from(addr.saturating_sub(IR_CHANNEL_ROMS));
        if let Some(rom) = self.roms.get(k / 4) {
            let i = 2 * (k % 4);
            return u16::from_be_bytes([rom[i], rom[i + 1]]);
        }
        let k = usize::from(addr.saturating_sub(IR_SENSOR_CHANNELS));
        if addr >= IR_SENSOR_CHANNELS && k < MAX_SENSORS / 2 {
            let ch = |i: usize| self.sensor_channels.get(i).copied().unwrap_or(0xFF);
            return u16::from_be_bytes([ch(2 * k), ch(2 * k + 1)]);
        }
        if let Some(w) = word32(addr, IR_SENSORS_MISSING, self.sensors_missing) {
            return w;
        }
        if addr == IR_REFERENCE_STATE {
            return self.reference_state;
        }
        0
    }

    /// Input registers 180–199: the volumetric correction.
    fn vol_register(&self, addr: u16) -> u16 {
        let v = &self.vol;
        let k = addr.wrapping_sub(IR_VOL_CORRECTION);
        if k < 6 {
            let c = v.corrections[usize::from(k / 2) % 3] as u32;
            return if k.is_multiple_of(2) { hi(c) } else { lo(c) };
        }
        if addr == IR_VOL_STATUS {
            v.status
        } else if addr == IR_VOL_TERMS {
            v.terms
        } else if let Some(w) = word32(addr, IR_VOL_TOOL, v.tool_um as u32) {
            w
        } else if (IR_VOL_TEMPS..IR_VOL_TEMPS + MAX_VOL_SENSORS as u16).contains(&addr) {
            v.temps[usize::from(addr - IR_VOL_TEMPS) % MAX_VOL_SENSORS]
                .map_or(NOT_AVAILABLE, |t| t as u16)
        } else {
            word32(addr, IR_VOL_SEQUENCE, v.sequence).unwrap_or_default()
        }
    }

    /// Input registers 160–179: the fault record (0 without one).
    fn safety_register(&self, addr: u16) -> u16 {
        if let Some(w) = word32(addr, IR_MAP_MISSING, self.map_missing) {
            return w;
        }
        if let Some(w) = word32(addr, IR_MAP_ADDED, self.map_added) {
            return w;
        }
        let Some(f) = self.fault else {
            return 0;
        };
        let uptime_s = u32::try_from(f.uptime_ms / 1000).unwrap_or(u32::MAX);
        if addr == IR_FAULT_KIND {
            f.kind
        } else if let Some(w) = word32(addr, IR_FAULT_PC, f.pc) {
            w
        } else if let Some(w) = word32(addr, IR_FAULT_UPTIME, uptime_s) {
            w
        } else if let Some(w) = word32(addr, IR_FAULT_COUNT, f.count) {
            w
        } else {
            // The detail word, or a reserved register (0).
            word32(addr, IR_FAULT_DETAIL, f.detail).unwrap_or_default()
        }
    }
}

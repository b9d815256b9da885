//! Input registers (FC04): the encoding of one [`Snapshot`] of everything
//! the board reports (the application's, [`crate::snapshot`]) at the
//! addresses `thermocomp_protocol::registers` defines.
//! A request is answered from one snapshot, so every 32-bit value and every
//! axis block in it is consistent; the sequence number (also inside each
//! axis block) tells a PLC whether two requests saw the same snapshot.
//! 32-bit values: high word first (register n = bits 31..16).

use thermocomp_core::eval::AxisPair;
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS, MAX_SENSORS};

use thermocomp_protocol::registers::*;
use thermocomp_protocol::MAX_CHANNELS;

pub use crate::snapshot::{centidegrees, FiveSnapshot, Snapshot, VolSnapshot, REFERENCE_REGS};

fn hi(v: u32) -> u16 {
    (v >> 16) as u16
}

fn lo(v: u32) -> u16 {
    (v & 0xFFFF) as u16
}

/// Word `k` (0: high) of a 32-bit value starting at `base`, if `addr` is in it.
fn word32(addr: u16, base: u16, v: u32) -> Option<u16> {
    match addr.checked_sub(base)? {
        0 => Some(hi(v)),
        1 => Some(lo(v)),
        _ => None,
    }
}

/// Register `k` of consecutive 32-bit values: the high word when `k` is even.
fn half(v: u32, k: usize) -> u16 {
    if k.is_multiple_of(2) {
        hi(v)
    } else {
        lo(v)
    }
}

/// Register `k` of a block of 32-bit values (two registers each, high word
/// first), or `None` past the block's end.
fn block_word(values: &[i32], k: usize) -> Option<u16> {
    values.get(k / 2).map(|&v| half(v as u32, k))
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
        if (IR_REF_TIME..=IR_REF_LAST).contains(&addr) {
            let k = usize::from(addr - IR_REF_TIME);
            return Some(self.references.get(k).copied().unwrap_or(0));
        }
        if (IR_FIVE_FIRST..=IR_FIVE_LAST).contains(&addr) {
            return Some(self.five_register(addr));
        }
        if let Some(k) = addr.checked_sub(IR_ENVELOPE_STEPS) {
            let k = usize::from(k);
            return self.envelope_steps.get(k / 2).map(|&v| half(v, k));
        }
        // The offset of `addr` in the block at `base` of `n` registers.
        let in_block = |base: u16, n: usize| {
            addr.checked_sub(base)
                .filter(|&k| usize::from(k) < n)
                .map(usize::from)
        };
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
        } else if addr == IR_REF_WANTED {
            self.reference_wanted
        } else if let Some(k) = in_block(IR_CORRECTIONS, 2 * MAX_DIRECTIONS) {
            block_word(&self.corrections, k).unwrap_or(0)
        } else if let Some(k) = in_block(IR_PREDICTIONS, 2 * MAX_DIRECTIONS) {
            block_word(&self.predictions, k).unwrap_or(0)
        } else if let Some(k) = in_block(IR_AXES, usize::from(AXIS_BLOCK) * MAX_AXES) {
            let block = usize::from(AXIS_BLOCK);
            let word = |a: &AxisPair| {
                let field = [
                    a.offset as u32,
                    a.slope as u32,
                    a.ref_pos as u32,
                    self.sequence,
                ];
                field.get((k % block) / 2).map(|&v| half(v, k))
            };
            self.axes.get(k / block).and_then(word).unwrap_or(0)
        } else if let Some(k) = in_block(IR_TEMPERATURES, MAX_CHANNELS) {
            let t = self.temperatures.get(k).copied().flatten();
            t.map_or(NOT_AVAILABLE, |v| v as u16)
        } else if let Some(k) = in_block(IR_STATES, MAX_CHANNELS) {
            self.states.get(k).copied().unwrap_or(0)
        } else if let Some(k) = in_block(IR_ACTIVE_MODEL, MAX_DIRECTIONS) {
            match self.active.get(k).copied() {
                Some(thermocomp_core::compensator::ACTIVE_NONE) | None => 0xFFFF,
                Some(m) => u16::from(m),
            }
        } else if addr == IR_DEGRADED_DIRECTIONS || addr == IR_HELD_DIRECTIONS {
            let want = |a: u8| match addr {
                IR_DEGRADED_DIRECTIONS => a != 0 && a != thermocomp_core::compensator::ACTIVE_NONE,
                _ => a == thermocomp_core::compensator::ACTIVE_NONE,
            };
            let n = usize::from(self.n_directions);
            self.active
                .iter()
                .take(n)
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
            #[allow(
                clippy::indexing_slicing,
                reason = "i + 1 <= 7 < 8 = rom.len() (k % 4 <= 3)"
            )]
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
        if let Some(w) = block_word(&v.corrections, usize::from(k)) {
            return w;
        }
        if addr == IR_VOL_STATUS {
            v.status
        } else if addr == IR_VOL_TERMS {
            v.terms
        } else if let Some(w) = word32(addr, IR_VOL_TOOL, v.tool_um as u32) {
            w
        } else if let Some(t) = addr
            .checked_sub(IR_VOL_TEMPS)
            .and_then(|k| v.temps.get(usize::from(k)))
        {
            t.map_or(NOT_AVAILABLE, |t| t as u16)
        } else {
            word32(addr, IR_VOL_SEQUENCE, v.sequence).unwrap_or_default()
        }
    }

    /// Input registers 330–359: the five-axis part of the volumetric correction.
    fn five_register(&self, addr: u16) -> u16 {
        let f = &self.vol.five;
        let k = usize::from(addr.wrapping_sub(IR_FIVE_ANGLES));
        if let Some(w) = block_word(&f.angles, k) {
            return w;
        }
        if addr == IR_FIVE_STATUS {
            return f.status;
        }
        if addr == IR_FIVE_ORDER {
            return f.order;
        }
        let k = usize::from(addr.wrapping_sub(IR_FIVE_ROTARY));
        if let Some(w) = block_word(&f.rotary, k) {
            return w;
        }
        word32(addr, IR_FIVE_SEQUENCE, self.vol.sequence).unwrap_or_default()
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

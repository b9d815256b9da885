//! What the PLC writes in normal operation (spindle speed, axis positions,
//! tool length, rotary axes A and C) and when it last did: the machine data
//! the measurement cycle and the volumetric section read.

use thermocomp_core::limits::MAX_AXES;

use crate::compensation::PlcInputs;

/// PLC registers older than this make the inputs "stale".
pub const PLC_TIMEOUT_MS: u64 = 10_000;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlcState {
    /// Spindle speed, rpm.
    pub spindle_rpm: u16,
    /// Axis positions, µm (or 0.001°), in the model's axis order.
    pub positions: [i32; MAX_AXES],
    /// Tool length, µm.
    pub tool_length_um: i32,
    /// The PLC has written positions (or the tool length) since boot.
    pub positions_written: bool,
    /// Rotary axes A and C, 0.001°, for the five-axis section.
    pub rotary_mdeg: [i32; 2],
    /// The PLC has written A or C since boot.
    pub rotary_written: bool,
    /// ms time of the PLC's last write of speed, positions, tool length or angles.
    pub written_ms: Option<u64>,
}

/// What the volumetric section reads of the PLC's data: positions, tool
/// length, angles and whether each was written.
pub type Geometry = ([i32; MAX_AXES], i32, bool, [i32; 2], bool);

impl PlcState {
    /// Never written, or not for longer than [`PLC_TIMEOUT_MS`] at `uptime_ms`.
    pub fn stale(&self, uptime_ms: u64) -> bool {
        self.written_ms
            .is_none_or(|t| uptime_ms.saturating_sub(t) > PLC_TIMEOUT_MS)
    }

    /// The compensator's inputs at `uptime_ms`; `spindle_override` replaces
    /// the PLC's speed (the bench replays a trace's recorded speed) and is
    /// never stale.
    pub fn inputs(&self, uptime_ms: u64, spindle_override: Option<i32>) -> PlcInputs {
        PlcInputs {
            spindle_rpm: spindle_override.unwrap_or(i32::from(self.spindle_rpm)),
            positions: self.positions,
            stale: spindle_override.is_none() && self.stale(uptime_ms),
        }
    }

    /// What the volumetric correction depends on.
    pub fn geometry(&self) -> Geometry {
        (
            self.positions,
            self.tool_length_um,
            self.positions_written,
            self.rotary_mdeg,
            self.rotary_written,
        )
    }
}

//! The volumetric block of the snapshot (input registers 180–199 and the
//! five-axis block 330–359): the core's evaluation (`thermocomp_core::
//! volumetric`, and `five_axis` when the image has section kind 4) at the
//! PLC's positions, tool length and rotary axes, with the board's own
//! status bits (no positions or angles written yet, stale PLC registers or
//! a held sensor value).

use thermocomp_core::five_axis::{self, fstatus};
use thermocomp_core::volumetric::{vstatus, MAX_VOL_SENSORS};
use thermocomp_core::Model;
use thermocomp_protocol::registers::NOT_AVAILABLE_32;

use crate::plc::PlcState;
use crate::snapshot::{FiveSnapshot, VolSnapshot};

/// What one evaluation reads besides the model and the PLC's registers.
pub struct VolContext<'a> {
    /// The section's sensors at the last cycle (1/16 °C; `None`: no value).
    pub temps: &'a [Option<i32>; MAX_VOL_SENSORS],
    /// A sensor value was held (not fresh) at the last cycle.
    pub held: bool,
    /// The PLC's registers are older than the timeout (or never written).
    pub plc_stale: bool,
    /// The evaluation's sequence number.
    pub sequence: u32,
}

/// The volumetric block for `model` (none, or no section: "no section").
/// With a five-axis section the correction includes the rotary part and is
/// not available until the PLC has written A and C.
pub fn snapshot(model: Option<&Model>, h: &PlcState, cx: &VolContext<'_>) -> VolSnapshot {
    let Some(v) = model.and_then(|m| m.volumetric.as_ref()) else {
        return VolSnapshot {
            sequence: cx.sequence,
            ..VolSnapshot::default()
        };
    };
    let n = v.sensors.len().min(MAX_VOL_SENSORS);
    let temps = cx.temps.get(..n).unwrap_or(cx.temps);
    let (corrections, mut status, tool_um, mut five) =
        match model.and_then(|m| m.five_axis.as_ref()) {
            None => {
                let out = v.evaluate(&h.positions, h.tool_length_um, temps);
                let five = FiveSnapshot::default();
                (out.corrections, out.status, out.tool_um, five)
            }
            Some(f) => {
                let out =
                    five_axis::evaluate(v, f, &h.positions, h.tool_length_um, h.rotary_mdeg, temps);
                let mut five = FiveSnapshot {
                    angles: out.angles_mdeg,
                    status: out.five_status,
                    order: u16::from(f.order),
                    rotary: out.rotary,
                };
                let mut status = out.status;
                if !h.rotary_written {
                    status = (status & !vstatus::VALID) | vstatus::NO_POSITIONS;
                    five.status = (five.status & !fstatus::INCLUDED) | fstatus::NO_ANGLES;
                }
                (out.corrections, status, out.tool_um, five)
            }
        };
    if !h.positions_written {
        status = (status & !vstatus::VALID) | vstatus::NO_POSITIONS;
    }
    if cx.plc_stale || cx.held {
        status |= vstatus::STALE;
    }
    let valid = status & vstatus::VALID != 0;
    if !valid {
        five.status &= !fstatus::INCLUDED;
    }
    if five.status & fstatus::INCLUDED == 0 {
        five.angles = [NOT_AVAILABLE_32; 2];
        five.rotary = [NOT_AVAILABLE_32; 3];
    }
    VolSnapshot {
        corrections: if valid {
            corrections
        } else {
            [NOT_AVAILABLE_32; 3]
        },
        status,
        terms: u16::try_from(v.terms.len()).unwrap_or(u16::MAX),
        tool_um: if valid { tool_um } else { NOT_AVAILABLE_32 },
        temps: core::array::from_fn(|i| {
            cx.temps
                .get(i)
                .copied()
                .flatten()
                .filter(|_| i < n)
                .and_then(|t| i16::try_from(t).ok())
        }),
        sequence: cx.sequence,
        five,
    }
}

//! Input registers (FC04): the addresses of everything the board reports.
//! The board answers a request from one snapshot, so every 32-bit value and
//! every axis block in it is consistent; the sequence number (also inside
//! each axis block) tells a PLC whether two requests saw the same snapshot.
//! 32-bit values: high word first (register n = bits 31..16).

/// Version of this register map (input register 2), so a PLC can tell which
/// blocks the board serves. 2 added input registers 150–299, status bits 8–9,
/// holding registers 34–35 and commands 6–11 to version 1; 3 added input
/// registers 300–329, holding registers 40–45 and commands 12–13 (probe
/// references, issue 28; docs/register-map.md); 4 added input register 23
/// and holding registers 46–48 (the board asks for references, issue 51);
/// 5 added input registers 360–371 (steps beyond the training envelope,
/// issue 50); 6 added holding registers 90–99 (the probe-reference rule's
/// parameters, issue 51 item 5).
pub const MAP_VERSION: u16 = 6;
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
/// A probe reference is wanted (map version 4, issue 51; holding registers
/// 46–48 set the rule): 0 nothing, 1 the settling time after a
/// spindle-speed change has passed, 2 the longest interval since the last
/// reference has passed. Raised until a reference is accepted (a refused
/// one leaves it raised): the PLC probes (command 12) while it is not 0.
pub const IR_REF_WANTED: u16 = 23;
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
/// Sensor states ([`crate::states::ChannelState::code`]).
pub const IR_STATES: u16 = 130;
/// Active model per direction: 0 main, k fallback k, 0xFFFF none (held / no model).
pub const IR_ACTIVE_MODEL: u16 = 150;
/// Bit d: direction d is served by a fallback model.
pub const IR_DEGRADED_DIRECTIONS: u16 = 156;
/// Bit d: direction d has no usable model (held).
pub const IR_HELD_DIRECTIONS: u16 = 157;
/// Last input register: the end of the envelope block (158–159, 169,
/// 174–179, 196–199, 293–299 and 344–359 reserved, read 0).
pub const IR_LAST: u16 = IR_ENVELOPE_LAST;
/// Per direction, the model steps served with an input beyond its training
/// envelope by more than the image's margin (map version 5, issue 50;
/// `thermocomp_core::Compensator::envelope_steps`): u32, 2 registers each,
/// 360–371, since the model was loaded or the board booted; saturating.
pub const IR_ENVELOPE_STEPS: u16 = 360;
/// Last register of the envelope block.
pub const IR_ENVELOPE_LAST: u16 = 371;

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

/// The five-axis part of the volumetric correction (image section kind 4,
/// issue 31), input registers 330–359: what the evaluation used. A and C
/// after clamping, int32 0.001° each (330–333; [`NOT_AVAILABLE_32`] unless
/// status bit 0).
pub const IR_FIVE_ANGLES: u16 = 330;
/// Five-axis status bits ([`thermocomp_core::five_axis::fstatus`]).
pub const IR_FIVE_STATUS: u16 = 334;
/// Fourier order of the section's component errors (0: none or no section).
pub const IR_FIVE_ORDER: u16 = 335;
/// The rotary part alone of registers 180–185, x, y, z, int32 0.1 µm,
/// machine frame (336–341; [`NOT_AVAILABLE_32`] unless status bit 0).
pub const IR_FIVE_ROTARY: u16 = 336;
/// The volumetric evaluation these registers belong to (= 194–195 of the
/// same snapshot), u32.
pub const IR_FIVE_SEQUENCE: u16 = 342;
/// Last register of the five-axis block (344–359 reserved, read 0).
pub const IR_FIVE_FIRST: u16 = 330;
pub const IR_FIVE_LAST: u16 = 359;

/// Status bit 9: a fault record from before the last reset is held (input
/// registers 160–168) until command 6 clears it.
pub const STATUS_FAULT_RECORDED: u16 = 1 << 9;
/// The fault record (the firmware's `fault::FaultRecord`): kind (160), program
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

/// Probe references (issue 28, commands 12–13, holding registers 40–45):
/// the state of the direction the probe measures (holding register 40).
/// Time of its last accepted reference, u32 s of the board's sample time
/// (0xFFFF_FFFF: none since the terms were reset), 300–301.
pub const IR_REF_TIME: u16 = 300;
/// Innovation of its last reference (accepted or refused), int32 0.1 µm:
/// probe reading − model − bias at that moment, 302–303.
pub const IR_REF_INNOVATION: u16 = 302;
/// References accepted (304) and refused (305) since the terms were reset, u16.
pub const IR_REF_ACCEPTED: u16 = 304;
pub const IR_REF_REFUSED: u16 = 305;
/// Current bias term b(t) per direction, int16 0.1 µm (saturating), 306–311.
pub const IR_REF_BIAS: u16 = 306;
/// Current drift-rate term s(t) per direction, int16 0.1 µm/h (saturating), 312–317.
pub const IR_REF_RATE: u16 = 312;
/// Re-zero offset z per direction (command 2), int32 0.1 µm, 318–329.
pub const IR_REF_ZERO: u16 = 318;
/// Last register of the probe-reference block.
pub const IR_REF_LAST: u16 = 329;

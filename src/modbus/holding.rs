//! Holding registers (FC03 read, FC06/FC16 write): what the PLC writes
//! (spindle speed, axis positions), configuration and limits behind the
//! unlock code, commands, and the model staging area.
//!
//! Every write request is checked as a whole before any register changes:
//! a refused request leaves everything as it was.

use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS, MAX_IMAGE_BYTES};
use thermocomp_core::Model;

pub const HR_UNLOCK: u16 = 0;
pub const HR_COMMAND: u16 = 1;
pub const HR_RESULT: u16 = 2;
pub const HR_UNIT: u16 = 3;
pub const HR_BAUD: u16 = 4;
pub const HR_SPINDLE: u16 = 5;
/// Axis positions, int32 µm (or 0.001°), high word first, 2 registers each.
pub const HR_POSITIONS: u16 = 6;
/// Per-direction clamp override, 0.1 µm (0xFFFF: none, the image's limit).
pub const HR_CLAMP: u16 = 20;
/// Per-direction rate-limit override, 0.1 µm/s (0xFFFF: none).
pub const HR_RATE: u16 = 26;
/// Length in bytes of the staged model image.
pub const HR_STAGED_LEN: u16 = 32;
/// Tool length for the volumetric correction, int32 µm, high word first
/// (written by the PLC like the positions; 36–39 reserved).
pub const HR_TOOL_LENGTH: u16 = 34;
/// Last register of the plain block (33 and 36–39 reserved, read 0).
pub const HR_LAST_PLAIN: u16 = 39;
/// Model staging area: 2 bytes per register (first byte in the high half).
pub const HR_STAGING: u16 = 1000;
pub const STAGING_REGS: u16 = (MAX_IMAGE_BYTES / 2) as u16;

/// Write this to HR_UNLOCK to allow configuration and model writes for 60 s.
pub const UNLOCK_CODE: u16 = 0xA5C3;
pub const UNLOCK_MS: u64 = 60_000;

pub const CMD_COMMIT_MODEL: u16 = 1;
pub const CMD_REREFERENCE: u16 = 2;
pub const CMD_CLEAR_STAGING: u16 = 3;
pub const CMD_LOCK: u16 = 4;
/// Commit the staged model even when its version is not newer than the
/// running one (going back to an older model on purpose); every other check
/// of [`CMD_COMMIT_MODEL`] still applies.
pub const CMD_ROLLBACK_MODEL: u16 = 5;
/// Forget the fault record (input registers 160–168, status bit 9).
pub const CMD_CLEAR_FAULT: u16 = 6;
/// Restore the default settings (unit 1, 115200 baud, no clamp or rate
/// override, no fixed reference) and store them; link changes apply after the reply.
pub const CMD_RESTORE_DEFAULTS: u16 = 7;
/// Test builds only (feature `test-faults`, the QEMU bench board): panic
/// after the reply, to show the fault path end to end.
pub const CMD_TEST_PANIC: u16 = 8;
/// Test builds only (feature `test-faults`): the measurement loop stops
/// making progress, so the watchdog must trip.
pub const CMD_TEST_STALL: u16 = 9;
/// Keep a reference sample across reboots (a machine with a fixed
/// reference): the next cycle at which every model sensor reads fresh is
/// the new reference sample (per channel), used from then on and at every
/// boot, and stored with the settings (HR_RESULT 50, then 23, then 0 or 22).
/// While a reference is kept (or the image has a fixed reference),
/// [`CMD_REREFERENCE`] does the same.
pub const CMD_KEEP_REFERENCE: u16 = 10;
/// Forget the kept reference (stored); the reference in use stays until
/// the next boot or command 2.
pub const CMD_FORGET_REFERENCE: u16 = 11;

/// Command results (HR_RESULT): one code per reason a commit is refused.
pub mod result {
    use thermocomp_core::ImageError;

    pub const OK: u16 = 0;
    pub const NONE: u16 = 1;
    /// Staged length outside 1..=MAX_IMAGE_BYTES.
    pub const BAD_LENGTH: u16 = 2;
    /// The image's CRC-32 does not match (corrupted in transfer).
    pub const BAD_CRC: u16 = 3;
    /// Writing the model to flash failed; the previous model still serves.
    pub const STORE_FAILED: u16 = 4;
    /// Shorter than its header or than its own total length.
    pub const TOO_SHORT: u16 = 5;
    /// Total length above the staging area.
    pub const TOO_LONG: u16 = 6;
    /// Not a model image (magic).
    pub const BAD_MAGIC: u16 = 7;
    /// Image format version this firmware does not read.
    pub const UNSUPPORTED_FORMAT: u16 = 8;
    /// Units code this firmware does not read.
    pub const UNSUPPORTED_UNITS: u16 = 9;
    /// A count above its fixed maximum (sensors, inputs, nets, terms …).
    pub const TOO_MANY: u16 = 10;
    /// A reference to a sensor, input, direction or axis that does not exist.
    pub const BAD_INDEX: u16 = 11;
    /// An envelope or axis range whose minimum is not below its maximum.
    pub const BAD_RANGE: u16 = 12;
    /// Another field outside its domain (flags, step, lag, power …).
    pub const BAD_VALUE: u16 = 13;
    /// The sections do not fill the image's length exactly.
    pub const LENGTH_MISMATCH: u16 = 14;
    /// Bytes after the sealed image (staged length longer than the image).
    pub const TRAILING_BYTES: u16 = 15;
    /// A sensor channel the board does not have.
    pub const SENSOR_CHANNEL: u16 = 16;
    /// Model version 0.
    pub const ZERO_MODEL_VERSION: u16 = 17;
    /// A direction's max correction outside 1..=MAX_CORRECTION.
    pub const MAX_CORRECTION: u16 = 18;
    /// A direction's max rate outside 1..=MAX_RATE (0 would freeze the correction).
    pub const MAX_RATE: u16 = 19;
    /// Table coefficients whose sums could overflow the evaluation.
    pub const TABLE_SUM_TOO_LARGE: u16 = 20;
    /// Version not newer than the running model's (CMD_ROLLBACK_MODEL commits it).
    pub const NOT_NEWER: u16 = 21;
    /// A settings change (unit, baud, clamp, rate, command 7) is in force
    /// but could not be stored in flash: it is lost at the next reboot.
    pub const SETTINGS_NOT_STORED: u16 = 22;
    /// A commit (model or settings) is being written to flash in the
    /// background; poll until another code (0 OK, 4, 22).
    pub const COMMIT_IN_PROGRESS: u16 = 23;
    /// An image section (format v2) of a kind this firmware does not read.
    pub const UNKNOWN_SECTION: u16 = 30;
    /// An image section whose contents do not match its declared length.
    pub const SECTION_LENGTH: u16 = 31;
    /// The same image section kind twice.
    pub const DUPLICATE_SECTION: u16 = 32;
    /// A fallback model reads a sensor it is meant to do without.
    pub const FALLBACK_USES_EXCLUDED: u16 = 33;
    /// Command 10 (or 2 with a kept reference) accepted: the reference is
    /// taken at the next cycle with every model sensor fresh, then stored.
    pub const REFERENCE_PENDING: u16 = 50;
    /// The image names a sensor by a ROM code that fails its CRC-8.
    pub const SENSOR_ROM: u16 = 51;
    /// The image names two sensors by the same ROM code.
    pub const DUPLICATE_SENSOR_ROM: u16 = 52;
    /// Volumetric section: a position slot, stroke or tool-length scale out of range.
    pub const VOLUMETRIC_RANGE: u16 = 40;
    /// Volumetric section: a sensor's reference or envelope outside −55 … 125 °C.
    pub const VOLUMETRIC_TEMPERATURE: u16 = 41;
    /// Volumetric section: a max correction outside 1..=MAX_CORRECTION.
    pub const VOLUMETRIC_MAX_CORRECTION: u16 = 42;

    /// The name of a result code (as in the README's table), for messages.
    pub fn name(code: u16) -> &'static str {
        match code {
            OK => "OK",
            NONE => "NONE",
            BAD_LENGTH => "BAD_LENGTH",
            BAD_CRC => "BAD_CRC",
            STORE_FAILED => "STORE_FAILED",
            TOO_SHORT => "TOO_SHORT",
            TOO_LONG => "TOO_LONG",
            BAD_MAGIC => "BAD_MAGIC",
            UNSUPPORTED_FORMAT => "UNSUPPORTED_FORMAT",
            UNSUPPORTED_UNITS => "UNSUPPORTED_UNITS",
            TOO_MANY => "TOO_MANY",
            BAD_INDEX => "BAD_INDEX",
            BAD_RANGE => "BAD_RANGE",
            BAD_VALUE => "BAD_VALUE",
            LENGTH_MISMATCH => "LENGTH_MISMATCH",
            TRAILING_BYTES => "TRAILING_BYTES",
            SENSOR_CHANNEL => "SENSOR_CHANNEL",
            ZERO_MODEL_VERSION => "ZERO_MODEL_VERSION",
            MAX_CORRECTION => "MAX_CORRECTION",
            MAX_RATE => "MAX_RATE",
            TABLE_SUM_TOO_LARGE => "TABLE_SUM_TOO_LARGE",
            NOT_NEWER => "NOT_NEWER",
            SETTINGS_NOT_STORED => "SETTINGS_NOT_STORED",
            COMMIT_IN_PROGRESS => "COMMIT_IN_PROGRESS",
            UNKNOWN_SECTION => "UNKNOWN_SECTION",
            SECTION_LENGTH => "SECTION_LENGTH",
            DUPLICATE_SECTION => "DUPLICATE_SECTION",
            FALLBACK_USES_EXCLUDED => "FALLBACK_USES_EXCLUDED",
            REFERENCE_PENDING => "REFERENCE_PENDING",
            SENSOR_ROM => "SENSOR_ROM",
            DUPLICATE_SENSOR_ROM => "DUPLICATE_SENSOR_ROM",
            VOLUMETRIC_RANGE => "VOLUMETRIC_RANGE",
            VOLUMETRIC_TEMPERATURE => "VOLUMETRIC_TEMPERATURE",
            VOLUMETRIC_MAX_CORRECTION => "VOLUMETRIC_MAX_CORRECTION",
            _ => "unknown",
        }
    }

    /// The result code of an image refusal.
    pub fn of_image_error(e: &ImageError) -> u16 {
        match e {
            ImageError::TooShort { .. } => TOO_SHORT,
            ImageError::TooLong { .. } => TOO_LONG,
            ImageError::BadMagic => BAD_MAGIC,
            ImageError::UnsupportedVersion(_) => UNSUPPORTED_FORMAT,
            ImageError::UnsupportedUnits(_) => UNSUPPORTED_UNITS,
            ImageError::BadCrc { .. } => BAD_CRC,
            ImageError::TooMany { .. } => TOO_MANY,
            ImageError::BadIndex { .. } => BAD_INDEX,
            ImageError::NonMonotoneRange { .. } => BAD_RANGE,
            ImageError::BadValue { .. } => BAD_VALUE,
            ImageError::LengthMismatch => LENGTH_MISMATCH,
            ImageError::TrailingBytes { .. } => TRAILING_BYTES,
            ImageError::SensorChannelOutOfRange { .. } => SENSOR_CHANNEL,
            ImageError::ZeroModelVersion => ZERO_MODEL_VERSION,
            ImageError::MaxCorrectionOutOfRange { .. } => MAX_CORRECTION,
            ImageError::MaxRateOutOfRange { .. } => MAX_RATE,
            ImageError::TableSumTooLarge { .. } => TABLE_SUM_TOO_LARGE,
            ImageError::UnknownSection { .. } => UNKNOWN_SECTION,
            ImageError::SectionLength { .. } => SECTION_LENGTH,
            ImageError::DuplicateSection { .. } => DUPLICATE_SECTION,
            ImageError::FallbackUsesExcluded { .. } => FALLBACK_USES_EXCLUDED,
            ImageError::BadSensorRom { .. } => SENSOR_ROM,
            ImageError::DuplicateSensorRom { .. } => DUPLICATE_SENSOR_ROM,
            ImageError::VolumetricAxisSlot { .. }
            | ImageError::VolumetricStroke { .. }
            | ImageError::VolumetricTool { .. } => VOLUMETRIC_RANGE,
            ImageError::VolumetricTemperature { .. } => VOLUMETRIC_TEMPERATURE,
            ImageError::VolumetricMaxCorrection { .. } => VOLUMETRIC_MAX_CORRECTION,
        }
    }
}

/// Baud rates the board accepts (HR_BAUD holds baud / 100).
pub const BAUD_RATES: [u32; 6] = [9_600, 19_200, 38_400, 57_600, 115_200, 230_400];

/// Why a write was refused (mapped to a Modbus exception by the server).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteError {
    /// Not a writable holding register (ILLEGAL DATA ADDRESS).
    Address,
    /// Value outside its range (ILLEGAL DATA VALUE).
    Value,
    /// Needs the unlock code first (ILLEGAL FUNCTION: wrong state).
    Locked,
    /// The staged model was refused (SERVER DEVICE FAILURE); HR_RESULT says why.
    ModelRefused,
    /// A commit is being written to flash (SERVER DEVICE BUSY): staging,
    /// commits and settings wait until it is done.
    Busy,
}

/// How a write request was addressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addressing {
    /// To this board's unit address: every register the map allows.
    Unit,
    /// To unit 0, every board on the bus at once and with no reply: only the
    /// PLC's registers (spindle speed, axis positions). Unlocking, commands
    /// (commit, lock, re-reference), unit, baud, limits and staging are
    /// refused, so that one frame can never reconfigure or reload every board.
    Broadcast,
}

/// What the application must do after a write was accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    None,
    /// The staged image (this long) parsed: store it and swap it in.
    CommitModel {
        len: usize,
    },
    Rereference,
    /// Limits changed: apply them to the compensator.
    LimitsChanged,
    /// Unit address or baud rate changed: apply after the reply is sent.
    LinkChanged,
    /// Command 6: forget the fault record.
    ClearFault,
    /// Command 7: back to the default settings.
    RestoreDefaults,
    /// Command 8 (feature `test-faults`): panic after the reply.
    TestPanic,
    /// Command 9 (feature `test-faults`): stall the measurement loop.
    TestStall,
    /// Command 10: take a reference sample and keep it.
    KeepReference,
    /// Command 11: forget the kept reference.
    ForgetReference,
}

pub struct Holding {
    pub unit: u8,
    pub baud: u32,
    pub spindle_rpm: u16,
    pub positions: [i32; MAX_AXES],
    /// Tool length, µm (HR_TOOL_LENGTH).
    pub tool_length_um: i32,
    /// The PLC has written positions (or the tool length) since boot.
    pub positions_written: bool,
    /// ms time of the PLC's last write of speed or positions.
    pub plc_written_ms: Option<u64>,
    pub clamp: [u16; MAX_DIRECTIONS],
    pub rate: [u16; MAX_DIRECTIONS],
    pub result: u16,
    /// Version of the model serving now (0: none); a commit must be newer.
    pub running_version: u32,
    /// A commit is being written ([`WriteError::Busy`] for what it stores).
    pub busy: bool,
    unlocked_until_ms: Option<u64>,
    staged_len: u16,
    staging: [u8; MAX_IMAGE_BYTES],
}

impl Holding {
    pub fn new(unit: u8, baud: u32) -> Self {
        Holding {
            unit,
            baud,
            spindle_rpm: 0,
            positions: [0; MAX_AXES],
            tool_length_um: 0,
            positions_written: false,
            plc_written_ms: None,
            clamp: [u16::MAX; MAX_DIRECTIONS],
            rate: [u16::MAX; MAX_DIRECTIONS],
            result: result::NONE,
            running_version: 0,
            busy: false,
            unlocked_until_ms: None,
            staged_len: 0,
            staging: [0; MAX_IMAGE_BYTES],
        }
    }

    pub fn unlocked(&self, now_ms: u64) -> bool {
        self.unlocked_until_ms.is_some_and(|t| now_ms < t)
    }

    /// The staged image bytes.
    pub fn staged(&self) -> &[u8] {
        &self.staging[..usize::from(self.staged_len).min(MAX_IMAGE_BYTES)]
    }

    /// Scratch buffer (the staging area) for reading a stored image at boot.
    pub fn scratch(&mut self) -> &mut [u8; MAX_IMAGE_BYTES] {
        &mut self.staging
    }

    pub fn read(&self, addr: u16, now_ms: u64) -> Option<u16> {
        let pos = |a: u16| -> Option<u16> {
            let k = a.checked_sub(HR_POSITIONS)?;
            let v = *self.positions.get(usize::from(k / 2))? as u32;
            Some(if k % 2 == 0 {
                (v >> 16) as u16
            } else {
                v as u16
            })
        };
        Some(match addr {
            HR_UNLOCK => u16::from(self.unlocked(now_ms)),
            HR_COMMAND => 0,
            HR_RESULT => self.result,
            HR_UNIT => u16::from(self.unit),
            HR_BAUD => (self.baud / 100) as u16,
            HR_SPINDLE => self.spindle_rpm,
            a if (HR_POSITIONS..HR_POSITIONS + 2 * MAX_AXES as u16).contains(&a) => pos(a)?,
            HR_TOOL_LENGTH => (self.tool_length_um as u32 >> 16) as u16,
            a if a == HR_TOOL_LENGTH + 1 => self.tool_length_um as u16,
            a if (HR_CLAMP..HR_CLAMP + MAX_DIRECTIONS as u16).contains(&a) => {
                self.clamp[usize::from(a - HR_CLAMP)]
            }
            a if (HR_RATE..HR_RATE + MAX_DIRECTIONS as u16).contains(&a) => {
                self.rate[usize::from(a - HR_RATE)]
            }
            HR_STAGED_LEN => self.staged_len,
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                u16::from_be_bytes([self.staging[i], self.staging[i + 1]])
            }
            a if a <= HR_LAST_PLAIN => 0, // reserved
            _ => return None,
        })
    }

    /// Write `values` to consecutive registers from `addr`, all or nothing.
    pub fn write(
        &mut self,
        addr: u16,
        values: &[u16],
        now_ms: u64,
        addressing: Addressing,
    ) -> Result<Command, WriteError> {
        let n = u16::try_from(values.len()).map_err(|_| WriteError::Value)?;
        // An empty write changes nothing and must not count as a PLC write.
        if n == 0 {
            return Err(WriteError::Value);
        }
        let end = addr.checked_add(n).ok_or(WriteError::Address)?;
        // A command is written alone (FC06 or a one-register FC16), so that a
        // refused command cannot leave half a request applied.
        if n > 1 && addr <= HR_COMMAND && end > HR_COMMAND {
            return Err(WriteError::Value);
        }
        // Check every register first.
        for (i, &v) in values.iter().enumerate() {
            let a = addr + i as u16;
            self.check(a, v, now_ms)?;
            if addressing == Addressing::Broadcast && !Self::plc_register(a) {
                return Err(WriteError::Locked);
            }
        }
        let mut command = Command::None;
        for (i, &v) in values.iter().enumerate() {
            let a = addr + i as u16;
            let c = self.apply(a, v, now_ms)?;
            if c != Command::None {
                command = c;
            }
        }
        let touches = |first: u16, n: u16| addr < first + n && end > first;
        let geometry = touches(HR_POSITIONS, 2 * MAX_AXES as u16) || touches(HR_TOOL_LENGTH, 2);
        if geometry || touches(HR_SPINDLE, 1) {
            self.plc_written_ms = Some(now_ms);
        }
        if geometry {
            self.positions_written = true;
        }
        Ok(command)
    }

    /// Registers the PLC writes in normal operation (spindle speed, positions, tool length).
    fn plc_register(a: u16) -> bool {
        a == HR_SPINDLE
            || (HR_POSITIONS..HR_POSITIONS + 2 * MAX_AXES as u16).contains(&a)
            || (HR_TOOL_LENGTH..HR_TOOL_LENGTH + 2).contains(&a)
    }

    /// Writes that change what a commit in progress stores.
    fn stored(a: u16, v: u16) -> bool {
        matches!(a, HR_UNIT | HR_BAUD | HR_STAGED_LEN)
            || (a == HR_COMMAND
                && matches!(
                    v,
                    CMD_COMMIT_MODEL
                        | CMD_ROLLBACK_MODEL
                        | CMD_CLEAR_STAGING
                        | CMD_RESTORE_DEFAULTS
                        | CMD_KEEP_REFERENCE
                        | CMD_FORGET_REFERENCE
                ))
            || (HR_CLAMP..HR_RATE + MAX_DIRECTIONS as u16).contains(&a)
            || (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a)
    }

    fn protected(a: u16) -> bool {
        !(a == HR_UNLOCK || Self::plc_register(a))
    }

    fn check(&self, a: u16, v: u16, now_ms: u64) -> Result<(), WriteError> {
        let writable = matches!(
            a,
            HR_UNLOCK | HR_COMMAND | HR_UNIT | HR_BAUD | HR_SPINDLE | HR_STAGED_LEN
        ) || Self::plc_register(a)
            || (HR_CLAMP..HR_CLAMP + MAX_DIRECTIONS as u16).contains(&a)
            || (HR_RATE..HR_RATE + MAX_DIRECTIONS as u16).contains(&a)
            || (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a);
        if !writable {
            return Err(WriteError::Address);
        }
        if Self::protected(a) && !self.unlocked(now_ms) {
            return Err(WriteError::Locked);
        }
        if self.busy && Self::stored(a, v) {
            return Err(WriteError::Busy);
        }
        let ok = match a {
            // A wrong key is refused, not echoed: the master must see that the
            // board stayed locked.
            HR_UNLOCK => v == UNLOCK_CODE,
            HR_COMMAND => {
                matches!(
                    v,
                    CMD_COMMIT_MODEL
                        | CMD_REREFERENCE
                        | CMD_CLEAR_STAGING
                        | CMD_LOCK
                        | CMD_ROLLBACK_MODEL
                        | CMD_CLEAR_FAULT
                        | CMD_RESTORE_DEFAULTS
                        | CMD_KEEP_REFERENCE
                        | CMD_FORGET_REFERENCE
                ) || (cfg!(feature = "test-faults") && matches!(v, CMD_TEST_PANIC | CMD_TEST_STALL))
            }
            HR_UNIT => (1..=247).contains(&v),
            HR_BAUD => BAUD_RATES.contains(&(u32::from(v) * 100)),
            HR_STAGED_LEN => usize::from(v) <= MAX_IMAGE_BYTES,
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(WriteError::Value)
        }
    }

    fn apply(&mut self, a: u16, v: u16, now_ms: u64) -> Result<Command, WriteError> {
        match a {
            HR_UNLOCK => {
                // check() let only the unlock code through.
                self.unlocked_until_ms = Some(now_ms + UNLOCK_MS);
            }
            HR_COMMAND => return self.command(v),
            HR_UNIT => {
                self.unit = v as u8;
                return Ok(Command::LinkChanged);
            }
            HR_BAUD => {
                self.baud = u32::from(v) * 100;
                return Ok(Command::LinkChanged);
            }
            HR_SPINDLE => self.spindle_rpm = v,
            HR_STAGED_LEN => self.staged_len = v,
            a if (HR_POSITIONS..HR_POSITIONS + 2 * MAX_AXES as u16).contains(&a) => {
                let k = usize::from(a - HR_POSITIONS);
                let p = &mut self.positions[k / 2];
                let u = *p as u32;
                *p = if k % 2 == 0 {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
            }
            a if (HR_TOOL_LENGTH..HR_TOOL_LENGTH + 2).contains(&a) => {
                let u = self.tool_length_um as u32;
                self.tool_length_um = if a == HR_TOOL_LENGTH {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
            }
            a if (HR_CLAMP..HR_CLAMP + MAX_DIRECTIONS as u16).contains(&a) => {
                self.clamp[usize::from(a - HR_CLAMP)] = v;
                return Ok(Command::LimitsChanged);
            }
            a if (HR_RATE..HR_RATE + MAX_DIRECTIONS as u16).contains(&a) => {
                self.rate[usize::from(a - HR_RATE)] = v;
                return Ok(Command::LimitsChanged);
            }
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                self.staging[i..i + 2].copy_from_slice(&v.to_be_bytes());
            }
            _ => return Err(WriteError::Address),
        }
        Ok(Command::None)
    }

    fn command(&mut self, v: u16) -> Result<Command, WriteError> {
        match v {
            CMD_COMMIT_MODEL | CMD_ROLLBACK_MODEL => {
                let len = usize::from(self.staged_len);
                if len == 0 || len > MAX_IMAGE_BYTES {
                    self.result = result::BAD_LENGTH;
                    return Err(WriteError::ModelRefused);
                }
                let model = match Model::parse(&self.staging[..len]) {
                    Ok(m) => m,
                    Err(e) => {
                        self.result = result::of_image_error(&e);
                        return Err(WriteError::ModelRefused);
                    }
                };
                // An older or the same version only on purpose: a stale
                // upload must not replace a newer model by accident.
                if v == CMD_COMMIT_MODEL && model.model_version <= self.running_version {
                    self.result = result::NOT_NEWER;
                    return Err(WriteError::ModelRefused);
                }
                self.unlocked_until_ms = None;
                self.result = result::OK;
                Ok(Command::CommitModel { len })
            }
            CMD_REREFERENCE => Ok(Command::Rereference),
            CMD_CLEAR_STAGING => {
                self.staging.fill(0);
                self.staged_len = 0;
                Ok(Command::None)
            }
            CMD_CLEAR_FAULT => Ok(Command::ClearFault),
            CMD_RESTORE_DEFAULTS => Ok(Command::RestoreDefaults),
            CMD_TEST_PANIC => Ok(Command::TestPanic),
            CMD_TEST_STALL => Ok(Command::TestStall),
            CMD_KEEP_REFERENCE => Ok(Command::KeepReference),
            CMD_FORGET_REFERENCE => Ok(Command::ForgetReference),
            _ => {
                self.unlocked_until_ms = None;
                Ok(Command::None)
            }
        }
    }
}

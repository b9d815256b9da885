//! Holding registers (FC03 read, FC06/FC16 write): what the PLC writes
//! (spindle speed, axis positions), configuration and limits behind the
//! unlock code, commands, and the model staging area.
//!
//! Every write request is checked as a whole before any register changes:
//! a refused request leaves everything as it was. The addresses, codes and
//! numbers are the wire contract's (`thermocomp_protocol::holding`).

use thermocomp_core::image::{split_signed, MAX_SIGNED_BYTES};
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS};
use thermocomp_core::Model;

use super::keys::{Keys, PUBLIC_KEY_LEN};
use thermocomp_protocol::holding::Command as WireCommand;
use thermocomp_protocol::holding::*;

/// Registers of the axis positions (two per axis).
const POSITION_REGS: usize = 2 * MAX_AXES;

/// The offset of register `a` in the block of `n` registers from `base`.
fn in_block(a: u16, base: u16, n: usize) -> Option<usize> {
    a.checked_sub(base).map(usize::from).filter(|&k| k < n)
}

/// Register `k` of a block of 32-bit values (even: the high word) sets that half of `p`.
fn set_half(p: &mut i32, k: usize, v: u16) {
    let u = *p as u32;
    *p = if k.is_multiple_of(2) {
        ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
    } else {
        ((u & 0xFFFF_0000) | u32::from(v)) as i32
    };
}

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
    /// Command 12: take a probe reference after the next cycle.
    TakeProbeReference,
    /// Command 13: reset the learned reference terms.
    ResetReferenceTerms,
    /// Holding registers 40–45 changed: store them.
    ProbeSetupChanged,
    /// Commands 14–16: a key changed (in force at once): store it.
    KeysChanged,
}

/// The probe-reference registers (40–45): which direction the probe
/// measures, how it is averaged, its temperature and drift, its gauge zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeSetup {
    /// Model direction the probe measures (`None`: references refused).
    pub direction: Option<u8>,
    /// ADC samples averaged per reference, 1..=1024.
    pub samples: u16,
    /// Bus channel of the probe's DS18B20 (`None`: no drift removed).
    pub temp_channel: Option<u8>,
    /// The probe's drift, nm/K.
    pub drift_nm_per_k: i16,
    /// Probe reading at the gauge at the machine's reference state, 0.1 µm.
    pub gauge_zero: i32,
}

impl Default for ProbeSetup {
    fn default() -> Self {
        ProbeSetup {
            direction: u8::try_from(DEFAULT_PROBE_DIRECTION).ok(),
            samples: DEFAULT_REFERENCE_SAMPLES,
            temp_channel: None,
            drift_nm_per_k: 0,
            gauge_zero: 0,
        }
    }
}

/// Registers 40 and 42: a small index or 0xFFFF ("none").
fn index_register(v: Option<u8>) -> u16 {
    v.map_or(REGISTER_NONE, u16::from)
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
    /// Rotary axes A and C, 0.001° (HR_ROTARY), for the five-axis section.
    pub rotary_mdeg: [i32; 2],
    /// The PLC has written A or C since boot.
    pub rotary_written: bool,
    /// ms time of the PLC's last write of speed or positions.
    pub plc_written_ms: Option<u64>,
    pub clamp: [u16; MAX_DIRECTIONS],
    pub rate: [u16; MAX_DIRECTIONS],
    pub result: u16,
    /// Holding registers 40–45.
    pub probe: ProbeSetup,
    /// Version of the model serving now (0: none); a commit must be newer.
    pub running_version: u32,
    /// A commit is being written ([`WriteError::Busy`] for what it stores).
    pub busy: bool,
    /// The unlock key and the signing key ([`Keys`]).
    pub keys: Keys,
    unlocked_until_ms: Option<u64>,
    /// The unlock in force came from the factory code: commissioning only.
    commissioning: bool,
    /// A wrong key was written: no unlock before this time.
    unlock_refused_until_ms: u64,
    staged_len: u16,
    /// The image and its signature trailer, if any.
    staging: [u8; MAX_SIGNED_BYTES],
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
            rotary_mdeg: [0; 2],
            rotary_written: false,
            plc_written_ms: None,
            clamp: [u16::MAX; MAX_DIRECTIONS],
            rate: [u16::MAX; MAX_DIRECTIONS],
            result: result::NONE,
            probe: ProbeSetup::default(),
            running_version: 0,
            busy: false,
            keys: Keys::default(),
            unlocked_until_ms: None,
            commissioning: false,
            unlock_refused_until_ms: 0,
            staged_len: 0,
            staging: [0; MAX_SIGNED_BYTES],
        }
    }

    pub fn unlocked(&self, now_ms: u64) -> bool {
        self.unlocked_until_ms.is_some_and(|t| now_ms < t)
    }

    /// The staged image bytes.
    pub fn staged(&self) -> &[u8] {
        // A length past the buffer (refused by check()) stages all of it.
        self.staging
            .get(..usize::from(self.staged_len))
            .unwrap_or(&self.staging)
    }

    /// Scratch buffer (the staging area) for reading a stored image at boot.
    pub fn scratch(&mut self) -> &mut [u8] {
        &mut self.staging
    }

    pub fn read(&self, addr: u16, now_ms: u64) -> Option<u16> {
        let word = |values: &[i32], base: u16, a: u16| -> Option<u16> {
            let k = a.checked_sub(base)?;
            let v = *values.get(usize::from(k / 2))? as u32;
            Some(if k % 2 == 0 {
                (v >> 16) as u16
            } else {
                (v & 0xFFFF) as u16
            })
        };
        Some(match addr {
            HR_UNLOCK => u16::from(self.unlocked(now_ms)),
            HR_COMMAND => 0,
            HR_RESULT => self.result,
            HR_UNIT => u16::from(self.unit),
            // The baud rates the board accepts are below 6,553,600.
            HR_BAUD => u16::try_from(self.baud / 100).unwrap_or(u16::MAX),
            HR_SPINDLE => self.spindle_rpm,
            a if in_block(a, HR_POSITIONS, POSITION_REGS).is_some() => {
                word(&self.positions, HR_POSITIONS, a)?
            }
            a if in_block(a, HR_ROTARY, usize::from(ROTARY_REGS)).is_some() => {
                word(&self.rotary_mdeg, HR_ROTARY, a)?
            }
            HR_TOOL_LENGTH => (self.tool_length_um as u32 >> 16) as u16,
            a if a == HR_TOOL_LENGTH + 1 => (self.tool_length_um as u32 & 0xFFFF) as u16,
            a if in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some() => {
                *self.clamp.get(usize::from(a - HR_CLAMP))?
            }
            a if in_block(a, HR_RATE, MAX_DIRECTIONS).is_some() => {
                *self.rate.get(usize::from(a - HR_RATE))?
            }
            HR_STAGED_LEN => self.staged_len,
            HR_PROBE_DIRECTION => index_register(self.probe.direction),
            HR_REFERENCE_SAMPLES => self.probe.samples,
            HR_PROBE_TEMP_CHANNEL => index_register(self.probe.temp_channel),
            HR_PROBE_DRIFT => self.probe.drift_nm_per_k as u16,
            HR_GAUGE_ZERO => (self.probe.gauge_zero as u32 >> 16) as u16,
            a if a == HR_GAUGE_ZERO + 1 => (self.probe.gauge_zero as u32 & 0xFFFF) as u16,
            a if in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() => {
                let i = usize::from(a - HR_SIGNING_KEY) * 2;
                match self.keys.staged_signing.get(i..i + 2)? {
                    &[high, low] => u16::from_be_bytes([high, low]),
                    _ => return None,
                }
            }
            HR_KEY_STATE => self.key_state(now_ms),
            // The board never shows an unlock key (HR_NEW_UNLOCK_KEY included).
            a if (HR_KEY_STATE..=HR_LAST_KEYS).contains(&a) => 0,
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                match self.staging.get(i..i + 2)? {
                    &[high, low] => u16::from_be_bytes([high, low]),
                    _ => return None,
                }
            }
            a if a <= HR_LAST_PLAIN => 0, // reserved
            _ => return None,
        })
    }

    /// HR_KEY_STATE: which keys are set (never the keys themselves).
    fn key_state(&self, now_ms: u64) -> u16 {
        let mut bits = 0;
        if self.keys.unlock.is_some() {
            bits |= KEY_STATE_UNLOCK_KEY;
        }
        if self.keys.signing.is_some() {
            bits |= KEY_STATE_SIGNING_KEY;
        }
        if self.commissioning && self.unlocked(now_ms) {
            bits |= KEY_STATE_COMMISSIONING;
        }
        bits
    }

    /// Lock now (command 4, a commit, and every refused write to this unit).
    pub fn lock(&mut self) {
        self.unlocked_until_ms = None;
    }

    /// Write `values` to consecutive registers from `addr`, all or nothing.
    ///
    /// A refused write addressed to this unit locks the board: whatever went
    /// wrong (a wrong key, a value out of range, a refused model), the
    /// master must unlock again before the next protected write. The lock is
    /// the board's, not a master's: the spec has no sessions, so one refusal
    /// from any master locks it for all. Two answers do not lock: busy (06,
    /// "retransmit later", as the spec asks of the master; nothing was
    /// refused for what it is) and a refused broadcast (a broadcast never
    /// runs a command, the lock command included).
    pub fn write(
        &mut self,
        addr: u16,
        values: &[u16],
        now_ms: u64,
        addressing: Addressing,
    ) -> Result<Command, WriteError> {
        let outcome = self.write_checked(addr, values, now_ms, addressing);
        if outcome.is_err_and(|e| e != WriteError::Busy) && addressing == Addressing::Unit {
            self.lock();
            if addr == HR_UNLOCK {
                // A wrong key (or one during the hold-off): the next try
                // waits, so guessing the 16-bit key takes hours, not minutes.
                self.unlock_refused_until_ms = now_ms + UNLOCK_HOLDOFF_MS;
            }
        }
        outcome
    }

    fn write_checked(
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
        for (a, &v) in (addr..end).zip(values) {
            self.check(a, v, now_ms)?;
            if addressing == Addressing::Broadcast && !Self::plc_register(a) {
                return Err(WriteError::Locked);
            }
        }
        let mut command = Command::None;
        for (a, &v) in (addr..end).zip(values) {
            let c = self.apply(a, v, now_ms)?;
            if c != Command::None {
                command = c;
            }
        }
        let touches =
            |first: u16, n: usize| usize::from(addr) < usize::from(first) + n && end > first;
        let geometry = touches(HR_POSITIONS, POSITION_REGS) || touches(HR_TOOL_LENGTH, 2);
        let rotary = touches(HR_ROTARY, usize::from(ROTARY_REGS));
        if geometry || rotary || touches(HR_SPINDLE, 1) {
            self.plc_written_ms = Some(now_ms);
        }
        if geometry {
            self.positions_written = true;
        }
        if rotary {
            self.rotary_written = true;
        }
        Ok(command)
    }

    /// Registers the PLC writes in normal operation (spindle speed,
    /// positions, tool length, rotary axes).
    fn plc_register(a: u16) -> bool {
        a == HR_SPINDLE
            || in_block(a, HR_POSITIONS, POSITION_REGS).is_some()
            || (HR_TOOL_LENGTH..HR_TOOL_LENGTH + 2).contains(&a)
            || in_block(a, HR_ROTARY, usize::from(ROTARY_REGS)).is_some()
    }

    /// Writes that change what a commit in progress stores.
    fn stored(a: u16, v: u16) -> bool {
        matches!(a, HR_UNIT | HR_BAUD | HR_STAGED_LEN)
            || (a == HR_COMMAND
                && matches!(
                    WireCommand::from_u16(v),
                    Some(
                        WireCommand::CommitModel
                            | WireCommand::RollbackModel
                            | WireCommand::ClearStaging
                            | WireCommand::RestoreDefaults
                            | WireCommand::KeepReference
                            | WireCommand::ForgetReference
                            | WireCommand::ResetReferenceTerms
                            | WireCommand::StoreSigningKey
                            | WireCommand::SetUnlockKey
                            | WireCommand::ReplaceSigningKey
                    )
                ))
            || Self::key_register(a)
            || in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some()
            || in_block(a, HR_RATE, MAX_DIRECTIONS).is_some()
            || (HR_PROBE_DIRECTION..=HR_GAUGE_ZERO + 1).contains(&a)
            || (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a)
    }

    /// The registers the key commands read (HR_SIGNING_KEY, HR_NEW_UNLOCK_KEY).
    fn key_register(a: u16) -> bool {
        in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() || a == HR_NEW_UNLOCK_KEY
    }

    fn protected(a: u16) -> bool {
        !(a == HR_UNLOCK || Self::plc_register(a))
    }

    fn check(&self, a: u16, v: u16, now_ms: u64) -> Result<(), WriteError> {
        let writable = matches!(
            a,
            HR_UNLOCK | HR_COMMAND | HR_UNIT | HR_BAUD | HR_SPINDLE | HR_STAGED_LEN
        ) || Self::plc_register(a)
            || in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some()
            || in_block(a, HR_RATE, MAX_DIRECTIONS).is_some()
            || (HR_PROBE_DIRECTION..=HR_GAUGE_ZERO + 1).contains(&a)
            || (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a)
            || Self::key_register(a);
        if !writable {
            return Err(WriteError::Address);
        }
        if Self::protected(a) && !self.unlocked(now_ms) {
            return Err(WriteError::Locked);
        }
        // The factory code opens commissioning only: the board's own key
        // (and locking again), nothing else.
        if Self::protected(a) && self.commissioning {
            let allowed = a == HR_NEW_UNLOCK_KEY
                || (a == HR_COMMAND && matches!(v, CMD_SET_UNLOCK_KEY | CMD_LOCK));
            if !allowed {
                return Err(WriteError::Locked);
            }
        }
        if self.busy && Self::stored(a, v) {
            return Err(WriteError::Busy);
        }
        let ok = match a {
            // A wrong key is refused, not echoed: the master must see that the
            // board stayed locked.
            HR_UNLOCK => {
                now_ms >= self.unlock_refused_until_ms
                    && v == self.keys.unlock.unwrap_or(FACTORY_UNLOCK_CODE)
            }
            HR_COMMAND => WireCommand::from_u16(v)
                .is_some_and(|c| !c.test_only() || cfg!(feature = "test-faults")),
            HR_UNIT => (1..=247).contains(&v),
            HR_BAUD => BAUD_RATES.contains(&(u32::from(v) * 100)),
            HR_STAGED_LEN => usize::from(v) <= MAX_SIGNED_BYTES,
            HR_PROBE_DIRECTION => v == REGISTER_NONE || usize::from(v) < MAX_DIRECTIONS,
            HR_REFERENCE_SAMPLES => (1..=crate::acquisition::probe::MAX_OVERSAMPLE).contains(&v),
            HR_PROBE_TEMP_CHANNEL => {
                v == REGISTER_NONE || usize::from(v) < thermocomp_protocol::MAX_CHANNELS
            }
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
                // check() let only the board's key (or, on a board without
                // one, the factory code) through.
                self.unlocked_until_ms = Some(now_ms + UNLOCK_MS);
                self.commissioning = self.keys.unlock.is_none();
            }
            HR_COMMAND => return self.command(v),
            HR_UNIT => {
                // check() let only 1..=247 through.
                self.unit = u8::try_from(v).map_err(|_| WriteError::Value)?;
                return Ok(Command::LinkChanged);
            }
            HR_BAUD => {
                self.baud = u32::from(v) * 100;
                return Ok(Command::LinkChanged);
            }
            HR_SPINDLE => self.spindle_rpm = v,
            HR_STAGED_LEN => self.staged_len = v,
            a if in_block(a, HR_POSITIONS, POSITION_REGS).is_some() => {
                let k = usize::from(a - HR_POSITIONS);
                let p = self.positions.get_mut(k / 2).ok_or(WriteError::Address)?;
                set_half(p, k, v);
            }
            a if in_block(a, HR_ROTARY, usize::from(ROTARY_REGS)).is_some() => {
                let k = usize::from(a - HR_ROTARY);
                let p = self.rotary_mdeg.get_mut(k / 2).ok_or(WriteError::Address)?;
                set_half(p, k, v);
            }
            a if (HR_TOOL_LENGTH..HR_TOOL_LENGTH + 2).contains(&a) => {
                let u = self.tool_length_um as u32;
                self.tool_length_um = if a == HR_TOOL_LENGTH {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
            }
            a if in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some() => {
                let c = self.clamp.get_mut(usize::from(a - HR_CLAMP));
                *c.ok_or(WriteError::Address)? = v;
                return Ok(Command::LimitsChanged);
            }
            a if in_block(a, HR_RATE, MAX_DIRECTIONS).is_some() => {
                let r = self.rate.get_mut(usize::from(a - HR_RATE));
                *r.ok_or(WriteError::Address)? = v;
                return Ok(Command::LimitsChanged);
            }
            HR_PROBE_DIRECTION..=HR_PROBE_DRIFT => {
                let p = &mut self.probe;
                // check() bounded 40 and 42 to a small index or 0xFFFF.
                match a {
                    HR_PROBE_DIRECTION => p.direction = u8::try_from(v).ok(),
                    HR_REFERENCE_SAMPLES => p.samples = v,
                    HR_PROBE_TEMP_CHANNEL => p.temp_channel = u8::try_from(v).ok(),
                    _ => p.drift_nm_per_k = v as i16,
                }
                return Ok(Command::ProbeSetupChanged);
            }
            a if (HR_GAUGE_ZERO..HR_GAUGE_ZERO + 2).contains(&a) => {
                let u = self.probe.gauge_zero as u32;
                self.probe.gauge_zero = if a == HR_GAUGE_ZERO {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
                return Ok(Command::ProbeSetupChanged);
            }
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                let bytes = self.staging.get_mut(i..i + 2).ok_or(WriteError::Address)?;
                bytes.copy_from_slice(&v.to_be_bytes());
            }
            a if in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() => {
                let i = usize::from(a - HR_SIGNING_KEY) * 2;
                let key = &mut self.keys.staged_signing;
                let bytes = key.get_mut(i..i + 2).ok_or(WriteError::Address)?;
                bytes.copy_from_slice(&v.to_be_bytes());
            }
            HR_NEW_UNLOCK_KEY => self.keys.new_unlock = v,
            _ => return Err(WriteError::Address),
        }
        Ok(Command::None)
    }

    /// A key command: on success the key is in force and must be stored
    /// (result 23, then 0 or 22); on refusal HR_RESULT says why.
    fn key_command(
        &mut self,
        run: impl FnOnce(&mut Self) -> Result<(), u16>,
    ) -> Result<Command, WriteError> {
        match run(self) {
            Ok(()) => {
                self.result = result::OK;
                Ok(Command::KeysChanged)
            }
            Err(code) => {
                self.result = code;
                Err(WriteError::ModelRefused)
            }
        }
    }

    fn command(&mut self, v: u16) -> Result<Command, WriteError> {
        // check() let only known commands through; anything else locks.
        let Some(wire) = WireCommand::from_u16(v) else {
            self.unlocked_until_ms = None;
            return Ok(Command::None);
        };
        match wire {
            WireCommand::CommitModel | WireCommand::RollbackModel => {
                let len = usize::from(self.staged_len);
                let Some(staged) = self.staging.get(..len).filter(|s| !s.is_empty()) else {
                    self.result = result::BAD_LENGTH;
                    return Err(WriteError::ModelRefused);
                };
                // The image, then its signature trailer if it carries one.
                // Parsed in place: one model on the stack, not a second one
                // on the way out of the parser.
                let mut model = Model::empty(0, 0);
                let parsed = split_signed(staged)
                    .and_then(|signed| model.parse_into(signed.image).map(|()| signed));
                let signed = match parsed {
                    Ok(ok) => ok,
                    Err(e) => {
                        self.result = result::of_image_error(&e);
                        return Err(WriteError::ModelRefused);
                    }
                };
                // With a signing key stored, only a model it signed commits.
                if let Err(code) = self.keys.check_model(&signed) {
                    self.result = code;
                    return Err(WriteError::ModelRefused);
                }
                let len = signed.image.len();
                // An older or the same version only on purpose: a stale
                // upload must not replace a newer model by accident.
                if wire == WireCommand::CommitModel && model.model_version <= self.running_version {
                    self.result = result::NOT_NEWER;
                    return Err(WriteError::ModelRefused);
                }
                self.unlocked_until_ms = None;
                self.result = result::OK;
                Ok(Command::CommitModel { len })
            }
            WireCommand::Rereference => Ok(Command::Rereference),
            WireCommand::ClearStaging => {
                self.staging.fill(0);
                self.staged_len = 0;
                Ok(Command::None)
            }
            WireCommand::Lock => {
                self.unlocked_until_ms = None;
                Ok(Command::None)
            }
            WireCommand::ClearFault => Ok(Command::ClearFault),
            WireCommand::RestoreDefaults => Ok(Command::RestoreDefaults),
            WireCommand::TestPanic => Ok(Command::TestPanic),
            WireCommand::TestStall => Ok(Command::TestStall),
            WireCommand::KeepReference => Ok(Command::KeepReference),
            WireCommand::ForgetReference => Ok(Command::ForgetReference),
            WireCommand::TakeProbeReference => Ok(Command::TakeProbeReference),
            WireCommand::ResetReferenceTerms => Ok(Command::ResetReferenceTerms),
            WireCommand::StoreSigningKey => self.key_command(|h| h.keys.store_signing()),
            WireCommand::ReplaceSigningKey => self.key_command(|h| {
                let proof = h.staging.get(..usize::from(h.staged_len)).unwrap_or(&[]);
                h.keys.replace_signing(proof)
            }),
            WireCommand::SetUnlockKey => self.key_command(|h| {
                let k = h.keys.new_unlock;
                if k == 0 || k == FACTORY_UNLOCK_CODE {
                    return Err(result::BAD_KEY);
                }
                h.keys.unlock = Some(k);
                h.keys.new_unlock = 0;
                // Open only with the new key from now on.
                h.unlocked_until_ms = None;
                Ok(())
            }),
        }
    }
}

//! Holding registers (FC03 read, FC06/FC16 write), the codec between them
//! and the application's [`AppState`]: what the PLC writes (spindle speed,
//! axis positions), configuration and limits behind the unlock code,
//! commands (decoded into a [`Command`] the application carries out), and
//! the model staging area. The codec keeps only the unlock rule.
//!
//! Every write request is checked as a whole before any register changes:
//! a refused request leaves everything as it was. The addresses, codes and
//! numbers are the wire contract's (`thermocomp_protocol::holding`).

use thermocomp_core::image::MAX_SIGNED_BYTES;
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS};

use crate::keys::{Keys, PUBLIC_KEY_LEN};
use crate::staging::ParseCandidate;
use crate::state::AppState;
pub use crate::state::Command;
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

/// The time of a write and the model serving then (a commit must be newer).
#[derive(Clone, Copy)]
pub struct At {
    pub now_ms: u64,
    pub running_version: u32,
}

/// Registers 40 and 42: a small index or 0xFFFF ("none").
fn index_register(v: Option<u8>) -> u16 {
    v.map_or(REGISTER_NONE, u16::from)
}

/// The codec's own state: the unlock rule (the lock is the board's, not a
/// master's). Everything the registers show or set lives in the
/// application's [`AppState`]; a read encodes from it, a write decodes into
/// it and returns the [`Command`] the application then carries out.
pub struct Holding {
    unlocked_until_ms: Option<u64>,
    /// The unlock in force came from the factory code: commissioning only.
    commissioning: bool,
    /// A wrong key was written: no unlock before this time.
    unlock_refused_until_ms: u64,
}

impl Default for Holding {
    fn default() -> Self {
        Self::new()
    }
}

impl Holding {
    pub fn new() -> Self {
        Holding {
            unlocked_until_ms: None,
            commissioning: false,
            unlock_refused_until_ms: 0,
        }
    }

    pub fn unlocked(&self, now_ms: u64) -> bool {
        self.unlocked_until_ms.is_some_and(|t| now_ms < t)
    }

    /// Holding register `addr` of `st`, or `None` past the map.
    pub fn read(&self, addr: u16, now_ms: u64, st: &AppState) -> Option<u16> {
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
            HR_RESULT => st.result,
            HR_UNIT => u16::from(st.settings.unit),
            // The baud rates the board accepts are below 6,553,600.
            HR_BAUD => u16::try_from(st.settings.baud / 100).unwrap_or(u16::MAX),
            HR_SPINDLE => st.plc.spindle_rpm,
            a if in_block(a, HR_POSITIONS, POSITION_REGS).is_some() => {
                word(&st.plc.positions, HR_POSITIONS, a)?
            }
            a if in_block(a, HR_ROTARY, usize::from(ROTARY_REGS)).is_some() => {
                word(&st.plc.rotary_mdeg, HR_ROTARY, a)?
            }
            HR_TOOL_LENGTH => (st.plc.tool_length_um as u32 >> 16) as u16,
            a if a == HR_TOOL_LENGTH + 1 => (st.plc.tool_length_um as u32 & 0xFFFF) as u16,
            a if in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some() => {
                *st.settings.clamp.get(usize::from(a - HR_CLAMP))?
            }
            a if in_block(a, HR_RATE, MAX_DIRECTIONS).is_some() => {
                *st.settings.rate.get(usize::from(a - HR_RATE))?
            }
            HR_STAGED_LEN => st.staging.len(),
            HR_PROBE_DIRECTION => index_register(st.probe.direction),
            HR_REFERENCE_SAMPLES => st.probe.samples,
            HR_PROBE_TEMP_CHANNEL => index_register(st.probe.temp_channel),
            HR_PROBE_DRIFT => st.probe.drift_nm_per_k as u16,
            HR_GAUGE_ZERO => (st.probe.gauge_zero as u32 >> 16) as u16,
            a if a == HR_GAUGE_ZERO + 1 => (st.probe.gauge_zero as u32 & 0xFFFF) as u16,
            HR_ASK_SETTLE => st.ask.settle_s,
            HR_ASK_INTERVAL => st.ask.max_interval_s,
            HR_ASK_SPEED_STEP => st.ask.speed_step_rpm,
            a if in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() => {
                let i = usize::from(a - HR_SIGNING_KEY) * 2;
                match st.keys.staged_signing.get(i..i + 2)? {
                    &[high, low] => u16::from_be_bytes([high, low]),
                    _ => return None,
                }
            }
            a @ HR_RULE..=HR_LAST_RULE => rule::in_force(&st.rule, usize::from(a - HR_RULE)),
            HR_KEY_STATE => self.key_state(now_ms, &st.keys),
            // The board never shows an unlock key (HR_NEW_UNLOCK_KEY included).
            a if (HR_KEY_STATE..=HR_LAST_KEYS).contains(&a) => 0,
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                match st.staging.area().get(i..i + 2)? {
                    &[high, low] => u16::from_be_bytes([high, low]),
                    _ => return None,
                }
            }
            a if a <= HR_LAST_PLAIN => 0, // reserved
            _ => return None,
        })
    }

    /// HR_KEY_STATE: which keys are set (never the keys themselves).
    fn key_state(&self, now_ms: u64, keys: &Keys) -> u16 {
        let mut bits = 0;
        if keys.unlock.is_some() {
            bits |= KEY_STATE_UNLOCK_KEY;
        }
        if keys.signing.is_some() {
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

    /// Write `values` to consecutive registers from `addr` into `st`, all
    /// or nothing, at `at`; a commit's candidate is parsed by `parser`.
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
        at: At,
        addressing: Addressing,
        st: &mut AppState,
        parser: &mut impl ParseCandidate,
    ) -> Result<Command, WriteError> {
        let now_ms = at.now_ms;
        let outcome = self.write_checked(addr, values, at, addressing, st, parser);
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
        at: At,
        addressing: Addressing,
        st: &mut AppState,
        parser: &mut impl ParseCandidate,
    ) -> Result<Command, WriteError> {
        let now_ms = at.now_ms;
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
            self.check(a, v, now_ms, st)?;
            if addressing == Addressing::Broadcast && !Self::plc_register(a) {
                return Err(WriteError::Locked);
            }
        }
        let mut command = Command::None;
        for (a, &v) in (addr..end).zip(values) {
            let c = self.apply(a, v, at, st, parser)?;
            if c != Command::None {
                command = c;
            }
        }
        let touches =
            |first: u16, n: usize| usize::from(addr) < usize::from(first) + n && end > first;
        let geometry = touches(HR_POSITIONS, POSITION_REGS) || touches(HR_TOOL_LENGTH, 2);
        let rotary = touches(HR_ROTARY, usize::from(ROTARY_REGS));
        if geometry || rotary || touches(HR_SPINDLE, 1) {
            st.plc.written_ms = Some(now_ms);
        }
        if geometry {
            st.plc.positions_written = true;
        }
        if rotary {
            st.plc.rotary_written = true;
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
            || (HR_PROBE_DIRECTION..=HR_ASK_SPEED_STEP).contains(&a)
            || (HR_RULE..=HR_LAST_RULE).contains(&a)
            || (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a)
    }

    /// The registers the key commands read (HR_SIGNING_KEY, HR_NEW_UNLOCK_KEY).
    fn key_register(a: u16) -> bool {
        in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() || a == HR_NEW_UNLOCK_KEY
    }

    fn protected(a: u16) -> bool {
        !(a == HR_UNLOCK || Self::plc_register(a))
    }

    fn check(&self, a: u16, v: u16, now_ms: u64, st: &AppState) -> Result<(), WriteError> {
        let writable = matches!(
            a,
            HR_UNLOCK | HR_COMMAND | HR_UNIT | HR_BAUD | HR_SPINDLE | HR_STAGED_LEN
        ) || Self::plc_register(a)
            || in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some()
            || in_block(a, HR_RATE, MAX_DIRECTIONS).is_some()
            || (HR_PROBE_DIRECTION..=HR_ASK_SPEED_STEP).contains(&a)
            || (HR_RULE..=HR_LAST_RULE).contains(&a)
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
        if st.busy && Self::stored(a, v) {
            return Err(WriteError::Busy);
        }
        let ok = match a {
            // A wrong key is refused, not echoed: the master must see that the
            // board stayed locked.
            HR_UNLOCK => {
                now_ms >= self.unlock_refused_until_ms
                    && v == st.keys.unlock.unwrap_or(FACTORY_UNLOCK_CODE)
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
            a @ HR_RULE..=HR_LAST_RULE => rule::valid(usize::from(a - HR_RULE), v),
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(WriteError::Value)
        }
    }

    fn apply(
        &mut self,
        a: u16,
        v: u16,
        at: At,
        st: &mut AppState,
        parser: &mut impl ParseCandidate,
    ) -> Result<Command, WriteError> {
        match a {
            HR_UNLOCK => {
                // check() let only the board's key (or, on a board without
                // one, the factory code) through.
                self.unlocked_until_ms = Some(at.now_ms + UNLOCK_MS);
                self.commissioning = st.keys.unlock.is_none();
            }
            HR_COMMAND => return self.command(v, at.running_version, st, parser),
            HR_UNIT => {
                // check() let only 1..=247 through.
                st.settings.unit = u8::try_from(v).map_err(|_| WriteError::Value)?;
                return Ok(Command::LinkChanged);
            }
            HR_BAUD => {
                st.settings.baud = u32::from(v) * 100;
                return Ok(Command::LinkChanged);
            }
            HR_SPINDLE => st.plc.spindle_rpm = v,
            HR_STAGED_LEN => st.staging.set_len(v),
            a if in_block(a, HR_POSITIONS, POSITION_REGS).is_some() => {
                let k = usize::from(a - HR_POSITIONS);
                let p = st.plc.positions.get_mut(k / 2).ok_or(WriteError::Address)?;
                set_half(p, k, v);
            }
            a if in_block(a, HR_ROTARY, usize::from(ROTARY_REGS)).is_some() => {
                let k = usize::from(a - HR_ROTARY);
                let p = st.plc.rotary_mdeg.get_mut(k / 2);
                let p = p.ok_or(WriteError::Address)?;
                set_half(p, k, v);
            }
            a if (HR_TOOL_LENGTH..HR_TOOL_LENGTH + 2).contains(&a) => {
                let u = st.plc.tool_length_um as u32;
                st.plc.tool_length_um = if a == HR_TOOL_LENGTH {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
            }
            a if in_block(a, HR_CLAMP, MAX_DIRECTIONS).is_some() => {
                let c = st.settings.clamp.get_mut(usize::from(a - HR_CLAMP));
                *c.ok_or(WriteError::Address)? = v;
                return Ok(Command::LimitsChanged);
            }
            a if in_block(a, HR_RATE, MAX_DIRECTIONS).is_some() => {
                let r = st.settings.rate.get_mut(usize::from(a - HR_RATE));
                *r.ok_or(WriteError::Address)? = v;
                return Ok(Command::LimitsChanged);
            }
            HR_PROBE_DIRECTION..=HR_PROBE_DRIFT => {
                let p = &mut st.probe;
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
                let u = st.probe.gauge_zero as u32;
                st.probe.gauge_zero = if a == HR_GAUGE_ZERO {
                    ((u & 0xFFFF) | (u32::from(v) << 16)) as i32
                } else {
                    ((u & 0xFFFF_0000) | u32::from(v)) as i32
                };
                return Ok(Command::ProbeSetupChanged);
            }
            HR_ASK_SETTLE..=HR_ASK_SPEED_STEP => {
                let p = &mut st.ask;
                match a {
                    HR_ASK_SETTLE => p.settle_s = v,
                    HR_ASK_INTERVAL => p.max_interval_s = v,
                    _ => p.speed_step_rpm = v,
                }
                return Ok(Command::AskChanged);
            }
            a @ HR_RULE..=HR_LAST_RULE => {
                // check() let only a value in the register's range through.
                let r = st.rule.get_mut(usize::from(a - HR_RULE));
                *r.ok_or(WriteError::Address)? = v;
                return Ok(Command::RuleChanged);
            }
            a if (HR_STAGING..HR_STAGING + STAGING_REGS).contains(&a) => {
                let i = usize::from(a - HR_STAGING) * 2;
                let bytes = st.staging.scratch().get_mut(i..i + 2);
                let bytes = bytes.ok_or(WriteError::Address)?;
                bytes.copy_from_slice(&v.to_be_bytes());
            }
            a if in_block(a, HR_SIGNING_KEY, PUBLIC_KEY_LEN / 2).is_some() => {
                let i = usize::from(a - HR_SIGNING_KEY) * 2;
                let key = &mut st.keys.staged_signing;
                let bytes = key.get_mut(i..i + 2).ok_or(WriteError::Address)?;
                bytes.copy_from_slice(&v.to_be_bytes());
            }
            HR_NEW_UNLOCK_KEY => st.keys.new_unlock = v,
            _ => return Err(WriteError::Address),
        }
        Ok(Command::None)
    }

    /// A key command: on success the key is in force and must be stored
    /// (result 23, then 0 or 22); on refusal HR_RESULT says why.
    fn key_command(
        st: &mut AppState,
        run: impl FnOnce(&mut AppState) -> Result<(), u16>,
    ) -> Result<Command, WriteError> {
        match run(st) {
            Ok(()) => {
                st.result = result::OK;
                Ok(Command::KeysChanged)
            }
            Err(code) => {
                st.result = code;
                Err(WriteError::ModelRefused)
            }
        }
    }

    fn command(
        &mut self,
        v: u16,
        running_version: u32,
        st: &mut AppState,
        parser: &mut impl ParseCandidate,
    ) -> Result<Command, WriteError> {
        // check() let only known commands through; anything else locks.
        let Some(wire) = WireCommand::from_u16(v) else {
            self.unlocked_until_ms = None;
            return Ok(Command::None);
        };
        match wire {
            WireCommand::CommitModel | WireCommand::RollbackModel => {
                let newer_only = wire == WireCommand::CommitModel;
                match st
                    .staging
                    .check_commit(&st.keys, running_version, newer_only, parser)
                {
                    Ok(len) => {
                        self.unlocked_until_ms = None;
                        st.result = result::OK;
                        Ok(Command::CommitModel { len })
                    }
                    Err(code) => {
                        st.result = code;
                        Err(WriteError::ModelRefused)
                    }
                }
            }
            WireCommand::Rereference => Ok(Command::Rereference),
            WireCommand::ClearStaging => {
                st.staging.clear();
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
            WireCommand::StoreSigningKey => Self::key_command(st, |st| st.keys.store_signing()),
            WireCommand::ReplaceSigningKey => Self::key_command(st, |st| {
                let proof = st.staging.proof();
                st.keys.replace_signing(proof)
            }),
            WireCommand::SetUnlockKey => {
                let outcome = Self::key_command(st, |st| st.keys.set_unlock());
                if outcome.is_ok() {
                    // Open only with the new key from now on.
                    self.unlocked_until_ms = None;
                }
                outcome
            }
        }
    }
}

//! Faults that end in a reset, and the record of the last one that survives it.
//!
//! Every fatal path of a board — a panic, a HardFault, the watchdog's early
//! warning, an initialisation that failed — goes through [`fault`]:
//! 1. the board's outputs go to their safe state first ([`FaultBoard::safe_state`]:
//!    the RS-485 driver enable low, so a fault never jams the bus);
//! 2. a [`FaultRecord`] (kind, program counter, uptime, how many faults since
//!    the record was last cleared, a detail word) is written to a few words
//!    of RAM that the board's startup code does not initialise and that a
//!    reset keeps (`board-memory.x` of each board reserves them);
//! 3. the board resets.
//!
//! After the reset the board reads the record back ([`FaultRecord::decode`]:
//! magic and CRC-32, so power-on garbage is never taken for a record) and
//! serves it over Modbus (input registers 160–168, status bit 9) until the
//! master clears it with command 6.
//!
//! This module only formats and decides; the words themselves, the safe
//! state and the reset are the board's ([`FaultBoard`]).

use thermocomp_core::image::crc32;

/// What ended the previous run (input register 160).
pub mod kind {
    pub const NONE: u16 = 0;
    /// A Rust panic (detail: source line).
    pub const PANIC: u16 = 1;
    /// A HardFault exception (detail: the CFSR where the core has one).
    pub const HARD_FAULT: u16 = 2;
    /// The watchdog expired (detail: bit 0 measurement loop stalled, bit 1
    /// Modbus task stalled, as the feeder last saw them).
    pub const WATCHDOG: u16 = 3;
    /// Initialisation failed (detail: [`super::init_step`] code).
    pub const INIT_FAILED: u16 = 4;
    /// The stack overflowed its region (with flip-link, into the bottom of
    /// RAM: a fault instead of corrupting `.bss`; detail: the stack pointer
    /// at the fault; no PC, since the exception frame could not be pushed).
    pub const STACK_OVERFLOW: u16 = 5;

    /// Name as in the register map (docs/register-map.md).
    pub fn name(k: u16) -> &'static str {
        match k {
            NONE => "none",
            PANIC => "panic",
            HARD_FAULT => "hard fault",
            WATCHDOG => "watchdog",
            INIT_FAILED => "init failed",
            STACK_OVERFLOW => "stack overflow",
            _ => "unknown",
        }
    }
}

/// Which initialisation step failed (detail of [`kind::INIT_FAILED`]).
pub mod init_step {
    /// The core peripherals were already taken.
    pub const CORE_PERIPHERALS: u32 = 1;
    /// The Modbus UART refused its configuration.
    pub const UART: u32 = 2;
    /// A task could not be spawned.
    pub const SPAWN: u32 = 3;
    /// The flash for the model slots / settings could not be taken.
    pub const FLASH: u32 = 4;
    /// A static buffer was already taken.
    pub const BUFFER: u32 = 5;
}

/// Words of RAM the record takes.
pub const WORDS: usize = 8;
const MAGIC: u32 = 0x5443_4652; // "TCFR"

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultRecord {
    pub kind: u16,
    /// Program counter at the fault (0 where the board cannot know it, e.g.
    /// the STM32's IWDG, which resets without an interrupt first).
    pub pc: u32,
    /// Uptime at the fault, ms.
    pub uptime_ms: u64,
    /// Faults since the record was last cleared (this one included).
    pub count: u32,
    /// Kind-specific detail (see [`kind`]).
    pub detail: u32,
}

impl FaultRecord {
    /// The RAM words: magic, kind, pc, uptime low, uptime high, count,
    /// detail, CRC-32 of the seven words before it (little-endian bytes).
    pub fn encode(&self) -> [u32; WORDS] {
        let mut w = [
            MAGIC,
            u32::from(self.kind),
            self.pc,
            (self.uptime_ms & 0xFFFF_FFFF) as u32,
            (self.uptime_ms >> 32) as u32,
            self.count,
            self.detail,
            0,
        ];
        w[WORDS - 1] = checksum(&w);
        w
    }

    /// A record when the words hold one (magic and checksum right); `None`
    /// for power-on contents or a cleared record.
    pub fn decode(w: &[u32; WORDS]) -> Option<FaultRecord> {
        if w[0] != MAGIC || w[WORDS - 1] != checksum(w) || w[1] > u32::from(u16::MAX) {
            return None;
        }
        Some(FaultRecord {
            kind: u16::try_from(w[1]).ok()?,
            pc: w[2],
            uptime_ms: u64::from(w[3]) | (u64::from(w[4]) << 32),
            count: w[5],
            detail: w[6],
        })
    }

    /// The record after one more fault: `previous` (if any) counts on.
    pub fn next(
        previous: Option<&FaultRecord>,
        kind: u16,
        pc: u32,
        uptime_ms: u64,
        detail: u32,
    ) -> Self {
        FaultRecord {
            kind,
            pc,
            uptime_ms,
            count: previous.map_or(0, |r| r.count).saturating_add(1),
            detail,
        }
    }
}

fn checksum(w: &[u32; WORDS]) -> u32 {
    let mut bytes = [0u8; 4 * (WORDS - 1)];
    for (chunk, word) in bytes.chunks_exact_mut(4).zip(w.iter()) {
        chunk.copy_from_slice(&word.to_le_bytes());
    }
    crc32(&bytes)
}

/// What a board provides for the fault path. Every function must work from
/// any context — a panic inside a critical section, a HardFault, an NMI —
/// so none may take a lock or wait on an interrupt.
pub trait FaultBoard {
    /// Outputs to their safe state: the RS-485 driver enable low (the bus
    /// released), whatever the task that owned the pin was doing.
    fn safe_state();
    /// Milliseconds since boot (best effort; 0 when unknown).
    fn uptime_ms() -> u64;
    /// The record's RAM words as they are.
    fn load() -> [u32; WORDS];
    /// Write the record's RAM words.
    fn store(words: &[u32; WORDS]);
    /// Reset the chip (system reset request).
    fn reset() -> !;
}

/// The one fatal path: safe state, record, reset.
pub fn fault<B: FaultBoard>(kind: u16, pc: u32, detail: u32) -> ! {
    B::safe_state();
    record::<B>(kind, pc, detail);
    B::reset()
}

/// Write the record of a fault (counting on from the one held) without
/// resetting: for a fault found after the fact, e.g. a watchdog reset flag.
pub fn record<B: FaultBoard>(kind: u16, pc: u32, detail: u32) -> FaultRecord {
    let previous = FaultRecord::decode(&B::load());
    let record = FaultRecord::next(previous.as_ref(), kind, pc, B::uptime_ms(), detail);
    B::store(&record.encode());
    record
}

/// Read the record at boot (it stays in RAM until [`clear`]).
pub fn recorded<B: FaultBoard>() -> Option<FaultRecord> {
    FaultRecord::decode(&B::load())
}

/// Forget the record (command 6): the next fault counts from 1 again.
pub fn clear<B: FaultBoard>() {
    B::store(&[0; WORDS]);
}

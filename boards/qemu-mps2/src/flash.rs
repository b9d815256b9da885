//! The model slots and the settings store on the bench board: the
//! MODEL_SLOTS region of memory.x (slots first, the store's 48 KiB after)
//! (SSRAM on mps2-an386, so it keeps its contents only while QEMU runs),
//! behind the same NorFlash trait as the real board's flash, with NOR rules:
//! erase sets 0xFF, programming only clears bits, aligned writes.
//!
//! Erase time: the background erase a commit uses ([`BackgroundErase`])
//! takes the real time of the NUCLEO's slot erase — one 128 KiB sector of
//! the F446, 1 s typical (datasheet t_ERASE128KB) — during which the region
//! refuses writes as a busy NOR would. (The blocking `erase` of the boot-time
//! programming path is instantaneous.)

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

extern "C" {
    static mut __model_slots_start: u8;
}

pub const SLOTS_BYTES: usize = 128 * 1024;
pub const SLOT_SIZE: u32 = (SLOTS_BYTES / 2) as u32;
/// The settings store's area, right after the slots (on the NUCLEO it is
/// sectors 1–3, three 16 KiB sectors of its own).
const SETTINGS_AT: usize = SLOTS_BYTES;
const TOTAL_BYTES: usize = SETTINGS_AT + thermocomp::settings_store::AREA_BYTES as usize;

#[derive(Debug, Clone, Copy)]
pub enum RamNorError {
    NotAligned,
    OutOfBounds,
    /// A background erase is still running.
    Busy,
}

impl NorFlashError for RamNorError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamNorError::NotAligned => NorFlashErrorKind::NotAligned,
            RamNorError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            RamNorError::Busy => NorFlashErrorKind::Other,
        }
    }
}

/// Real erase time of one slot (a 128 KiB sector on the F446, typical).
pub const SLOT_ERASE_MS: u64 = 1_000;

pub struct RamNor {
    mem: &'static mut [u8],
    /// A background erase runs until then.
    busy_until: Option<embassy_time::Instant>,
}

impl RamNor {
    /// Take the region; call once.
    pub fn take() -> Option<RamNor> {
        static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
        if TAKEN.swap(true, core::sync::atomic::Ordering::AcqRel) {
            return None;
        }
        // SAFETY: the linker reserves MODEL_SLOTS for this alone, and TAKEN
        // hands it out once.
        let mem = unsafe {
            core::slice::from_raw_parts_mut(
                core::ptr::addr_of_mut!(__model_slots_start),
                TOTAL_BYTES,
            )
        };
        Some(RamNor {
            mem,
            busy_until: None,
        })
    }
}

impl ErrorType for RamNor {
    type Error = RamNorError;
}

impl ReadNorFlash for RamNor {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamNorError> {
        let o = offset as usize;
        let src = self
            .mem
            .get(o..o + bytes.len())
            .ok_or(RamNorError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }
    fn capacity(&self) -> usize {
        TOTAL_BYTES
    }
}

impl NorFlash for RamNor {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = 4096;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), RamNorError> {
        let (from, to) = (from as usize, to as usize);
        if from % Self::ERASE_SIZE != 0 || to % Self::ERASE_SIZE != 0 {
            return Err(RamNorError::NotAligned);
        }
        self.mem
            .get_mut(from..to)
            .ok_or(RamNorError::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamNorError> {
        if !thermocomp::hal::flash::BackgroundErase::erase_done(self) {
            return Err(RamNorError::Busy);
        }
        let o = offset as usize;
        if !o.is_multiple_of(Self::WRITE_SIZE) || !bytes.len().is_multiple_of(Self::WRITE_SIZE) {
            return Err(RamNorError::NotAligned);
        }
        let dst = self
            .mem
            .get_mut(o..o + bytes.len())
            .ok_or(RamNorError::OutOfBounds)?;
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d &= *s;
        }
        Ok(())
    }
}

impl thermocomp::hal::flash::BackgroundErase for RamNor {
    #[allow(clippy::cast_possible_truncation, reason = "TOTAL_BYTES < 4 GiB")]
    fn settings_area(&self) -> core::ops::Range<u32> {
        SETTINGS_AT as u32..TOTAL_BYTES as u32
    }

    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]> {
        let from = usize::try_from(from).ok()?;
        self.mem
            .get(from..from.checked_add(usize::try_from(len).ok()?)?)
    }

    fn start_erase(&mut self, from: u32, to: u32) -> Result<(), RamNorError> {
        self.erase(from, to)?;
        let ms = SLOT_ERASE_MS * u64::from(to - from) / u64::from(SLOT_SIZE);
        self.busy_until =
            Some(embassy_time::Instant::now() + embassy_time::Duration::from_millis(ms));
        Ok(())
    }

    fn erase_done(&mut self) -> bool {
        match self.busy_until {
            Some(t) if embassy_time::Instant::now() < t => false,
            _ => {
                self.busy_until = None;
                true
            }
        }
    }
}

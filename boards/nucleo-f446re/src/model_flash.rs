//! The application's flash in the STM32F446RE: the model slots in sectors
//! 6 and 7 (128 KiB each, 0x0804_0000 and 0x0806_0000) and the settings
//! store in sectors 1–3 (16 KiB each, 0x0800_4000–0x0800_FFFF);
//! `board-memory.x` keeps the vector table in sector 0 and the program in
//! sectors 4–5 (`_stext`). embassy-stm32's blocking `Flash` implements
//! `NorFlash` over the whole array; this adapter maps the application's
//! offsets: [0, 256 KiB) → sectors 6–7, [256 KiB, 304 KiB) → sectors 1–3.
//! Its erase size is the smallest sector (16 KiB); every erase the
//! application asks for falls on the sectors' own boundaries (a slot: one
//! 128 KiB sector; a store page: one 16 KiB sector), which embassy checks.
//! Erasing a 128 KiB sector takes 1–2 s with the bus stalled; the
//! application answers the commit first (HR_RESULT 23) and erases after.

use embassy_stm32::flash::{Blocking, Error, Flash};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

/// Offset of sector 6 from the start of flash.
const SLOTS_OFFSET: u32 = 0x4_0000;
pub const SLOT_SIZE: u32 = 0x2_0000;
/// Where the application sees the settings store (after both slots).
const SETTINGS_AT: u32 = 2 * SLOT_SIZE;
/// Offset of sector 1 from the start of flash.
const SETTINGS_OFFSET: u32 = 0x4000;
const SETTINGS_END: u32 = SETTINGS_AT + thermocomp::settings_store::AREA_BYTES;
const _: () = assert!(SETTINGS_OFFSET + thermocomp::settings_store::AREA_BYTES <= 0x1_0000);

/// The flash address of an application offset (`None`: outside both areas).
fn address(offset: u32, len: usize) -> Option<u32> {
    let end = offset.checked_add(u32::try_from(len).ok()?)?;
    if end <= SETTINGS_AT {
        Some(SLOTS_OFFSET + offset)
    } else if offset >= SETTINGS_AT && end <= SETTINGS_END {
        Some(SETTINGS_OFFSET + (offset - SETTINGS_AT))
    } else {
        None
    }
}

pub struct SlotFlash {
    flash: Flash<'static, Blocking>,
}

impl SlotFlash {
    pub fn new(flash: Flash<'static, Blocking>) -> Self {
        SlotFlash { flash }
    }
}

impl ErrorType for SlotFlash {
    type Error = Error;
}

impl ReadNorFlash for SlotFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Error> {
        let at = address(offset, bytes.len()).ok_or(Error::Size)?;
        self.flash.blocking_read(at, bytes)
    }
    fn capacity(&self) -> usize {
        SETTINGS_END as usize
    }
}

impl NorFlash for SlotFlash {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = 16 * 1024;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Error> {
        let len = usize::try_from(to.saturating_sub(from)).map_err(|_| Error::Size)?;
        let at = address(from, len).ok_or(Error::Size)?;
        self.flash.blocking_erase(at, at + (to - from))
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Error> {
        let at = address(offset, bytes.len()).ok_or(Error::Size)?;
        self.flash.blocking_write(at, bytes)
    }
}

/// Blocking erase (the default): the F446 has one flash bank, and every
/// flash read — every instruction fetch — stalls while a sector erases, so
/// a background erase would stall the CPU all the same. The application
/// starts it after the commit's reply is out (HR_RESULT 23 until done), and
/// only once the RS-485 line is quiet: not while the port transmits (the
/// driver enable would stay high through the erase: the bus jammed for
/// 1–4 s) nor while a request is coming in (its reply would wait out the
/// erase).
impl thermocomp::hal::flash::BackgroundErase for SlotFlash {
    fn settings_area(&self) -> core::ops::Range<u32> {
        SETTINGS_AT..SETTINGS_END
    }
    /// The F446's flash is memory-mapped (read-only) at `FLASH_BASE`, as
    /// embassy-stm32's own `blocking_read` reads it.
    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]> {
        let len = usize::try_from(len).ok()?;
        let at = address(from, len)?;
        let start = embassy_stm32::flash::FLASH_BASE.checked_add(usize::try_from(at).ok()?)?;
        // SAFETY: `address` keeps `[at, at + len)` inside the slots or the
        // store's sectors, which are mapped flash for the program's whole
        // life. The slice borrows `self`, so no erase or program through
        // this adapter (`&mut self`) can change those bytes while it lives.
        Some(unsafe { core::slice::from_raw_parts(start as *const u8, len) })
    }
    fn ready_to_erase(&mut self) -> bool {
        crate::rtu_port::line_quiet()
    }
}

//! The model slots in the STM32F446RE's internal flash: sectors 6 and 7
//! (128 KiB each, 0x0804_0000 and 0x0806_0000; `board-memory.x` keeps the
//! program below them). embassy-stm32's blocking `Flash` implements
//! `NorFlash` over the whole array; this adapter shifts offsets so the
//! application's slot A is sector 6 and slot B sector 7.
//! Erasing a 128 KiB sector takes 1–2 s with the bus stalled; the
//! application answers the commit first (HR_RESULT 23) and erases after.

use embassy_stm32::flash::{Blocking, Error, Flash};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

/// Offset of sector 6 from the start of flash.
const SLOTS_OFFSET: u32 = 0x4_0000;
pub const SLOT_SIZE: u32 = 0x2_0000;

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
        self.flash.blocking_read(SLOTS_OFFSET + offset, bytes)
    }
    fn capacity(&self) -> usize {
        2 * SLOT_SIZE as usize
    }
}

impl NorFlash for SlotFlash {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = SLOT_SIZE as usize;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Error> {
        self.flash
            .blocking_erase(SLOTS_OFFSET + from, SLOTS_OFFSET + to)
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Error> {
        self.flash.blocking_write(SLOTS_OFFSET + offset, bytes)
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
    fn ready_to_erase(&mut self) -> bool {
        crate::rtu_port::line_quiet()
    }
}

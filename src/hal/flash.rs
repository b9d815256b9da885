//! The board's flash: the model slots ([`crate::model_store`]), whose erase
//! may run in the background, and the settings store's own small sectors
//! ([`crate::settings_store`]). A commit starts the erase of the inactive slot,
//! the application goes on (Modbus answers, the measurement loop keeps its
//! period), and programming follows once [`BackgroundErase::erase_done`].
//!
//! The defaults are a blocking erase (done when `start_erase` returns): the
//! host mock and the NUCLEO, whose single-bank F446 stalls every flash read
//! — so every instruction fetch — while a sector erases anyway.

use embedded_storage::nor_flash::NorFlash;

pub trait BackgroundErase: NorFlash {
    /// Where the settings store lives in this flash
    /// ([`crate::settings_store`]): [`crate::settings_store::AREA_BYTES`]
    /// on [`crate::settings_store::PAGE`] boundaries, sectors of its own,
    /// apart from the model slots at `[0, 2 · slot size)`.
    fn settings_area(&self) -> core::ops::Range<u32>;

    /// `len` bytes at `from` as the CPU reads them where the flash is
    /// memory-mapped (`None`: the range is outside this flash). The commit
    /// check lends the compensator's model to the candidate image and puts
    /// the model in force back by parsing its slot's image from here, so
    /// that neither a second model nor a second image buffer is needed
    /// ([`crate::model_store::ModelStore::reparse_active`]).
    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]>;

    /// Start erasing `[from, to)`; may return before the erase is done.
    fn start_erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.erase(from, to)
    }

    /// True once the erase started last has finished.
    fn erase_done(&mut self) -> bool {
        true
    }

    /// Whether an erase may start now. A board whose erase stalls the CPU
    /// (the NUCLEO) says no while its RS-485 port transmits or receives, so
    /// that the erase never holds the bus or delays a reply; the commit then
    /// waits for the next look (the feeder's, every 100 ms).
    fn ready_to_erase(&mut self) -> bool {
        true
    }
}

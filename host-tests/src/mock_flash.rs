//! NOR flash double with power-cut injection: erase sets bytes to 0xFF,
//! programming can only clear bits (as real NOR), writes must be aligned to
//! `WRITE_SIZE`, and after `budget` word programs or sector erases the power
//! "fails": that operation stops half way and every later one errors, until
//! `power_on` (a reboot, flash contents kept).

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

pub const WRITE_SIZE: usize = 4;
pub const ERASE_SIZE: usize = 1024;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MockError {
    PowerLost,
    NotAligned,
    OutOfBounds,
}

impl NorFlashError for MockError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            MockError::NotAligned => NorFlashErrorKind::NotAligned,
            MockError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            MockError::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

#[derive(Clone)]
pub struct MockFlash {
    pub bytes: Vec<u8>,
    /// Erases per `ERASE_SIZE` sector since creation (the wear bench).
    pub erase_counts: Vec<u64>,
    /// Operations (word programs, sector erases) left before the power fails.
    pub budget: Option<u64>,
    pub powered: bool,
    pub operations: u64,
}

impl MockFlash {
    /// `size` bytes for the model slots, then the settings store's area.
    pub fn new(size: usize) -> Self {
        let page = thermocomp::settings_store::PAGE as usize;
        let settings_at = size.div_ceil(page) * page;
        let total = settings_at + thermocomp::settings_store::AREA_BYTES as usize;
        MockFlash {
            bytes: vec![0xFF; total],
            erase_counts: vec![0; total / ERASE_SIZE],
            budget: None,
            powered: true,
            operations: 0,
        }
    }

    /// Where the settings store's area starts: the last
    /// [`thermocomp::settings_store::AREA_BYTES`] of the mock (after the
    /// `size` bytes [`MockFlash::new`] was asked for, rounded up to a store
    /// page), so a mock whose `bytes` are replaced by another's keeps it.
    pub fn settings_at(&self) -> u32 {
        let len = u32::try_from(self.bytes.len()).expect("mock flash under 4 GiB");
        len.saturating_sub(thermocomp::settings_store::AREA_BYTES)
    }

    pub fn power_on(&mut self) {
        self.powered = true;
        self.budget = None;
    }

    fn spend(&mut self) -> Result<(), MockError> {
        if !self.powered {
            return Err(MockError::PowerLost);
        }
        self.operations += 1;
        if let Some(b) = self.budget.as_mut() {
            if *b == 0 {
                self.powered = false;
                return Err(MockError::PowerLost);
            }
            *b -= 1;
        }
        Ok(())
    }
}

impl ErrorType for MockFlash {
    type Error = MockError;
}

impl ReadNorFlash for MockFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MockError> {
        let o = offset as usize;
        let src = self
            .bytes
            .get(o..o + bytes.len())
            .ok_or(MockError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for MockFlash {
    const WRITE_SIZE: usize = WRITE_SIZE;
    const ERASE_SIZE: usize = ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), MockError> {
        let (from, to) = (from as usize, to as usize);
        if from % ERASE_SIZE != 0 || to % ERASE_SIZE != 0 {
            return Err(MockError::NotAligned);
        }
        if to > self.bytes.len() || from > to {
            return Err(MockError::OutOfBounds);
        }
        for sector in (from..to).step_by(ERASE_SIZE) {
            if let Err(e) = self.spend() {
                // Power lost mid-erase: the first half of the sector is erased.
                if e == MockError::PowerLost {
                    self.bytes[sector..sector + ERASE_SIZE / 2].fill(0xFF);
                }
                return Err(e);
            }
            self.bytes[sector..sector + ERASE_SIZE].fill(0xFF);
            // (`bytes` may have been replaced by a longer copy.)
            let n = self.bytes.len() / ERASE_SIZE;
            if self.erase_counts.len() < n {
                self.erase_counts.resize(n, 0);
            }
            self.erase_counts[sector / ERASE_SIZE] += 1;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), MockError> {
        let o = offset as usize;
        if !o.is_multiple_of(WRITE_SIZE) || !bytes.len().is_multiple_of(WRITE_SIZE) {
            return Err(MockError::NotAligned);
        }
        if o + bytes.len() > self.bytes.len() {
            return Err(MockError::OutOfBounds);
        }
        for (i, word) in bytes.chunks(WRITE_SIZE).enumerate() {
            let at = o + i * WRITE_SIZE;
            if let Err(e) = self.spend() {
                if e == MockError::PowerLost {
                    // Half a word programmed.
                    self.bytes[at] &= word[0];
                    self.bytes[at + 1] &= word[1];
                }
                return Err(e);
            }
            for (d, s) in self.bytes[at..at + WRITE_SIZE].iter_mut().zip(word) {
                *d &= *s; // NOR: programming only clears bits
            }
        }
        Ok(())
    }
}

/// Erases at once (the default blocking erase): the application's
/// background commit runs start → done → program in one `poll_flash`.
impl thermocomp::hal::flash::BackgroundErase for MockFlash {
    fn settings_area(&self) -> std::ops::Range<u32> {
        self.settings_at()..self.settings_at() + thermocomp::settings_store::AREA_BYTES
    }

    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]> {
        let from = usize::try_from(from).ok()?;
        self.bytes
            .get(from..from.checked_add(usize::try_from(len).ok()?)?)
    }
}

//! Two model slots in flash (A/B) so that a power loss at any moment leaves
//! the old model or the new one, never a broken one.
//!
//! Slot layout: a 16-byte header — magic "TCSL", generation u32, image length
//! u32, CRC-32 of the image — then the image. A commit erases the inactive
//! slot, programs the image, then the header's last three words, and the
//! magic last of all: until the magic is there, the slot is not a candidate.
//! At boot the valid slot (magic, length, CRC and a model that parses) with
//! the newer generation wins.

use embedded_storage::nor_flash::NorFlash;
use thermocomp_core::image::crc32;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;

const MAGIC: [u8; 4] = *b"TCSL";
const HEADER: u32 = 16;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash refused an erase or write (or power was lost).
    Flash,
    /// The image does not fit a slot.
    TooLarge,
}

pub struct ModelStore<F: NorFlash> {
    flash: F,
    /// Offsets of slot A and B inside `flash`; each `slot_size` bytes.
    slots: [u32; 2],
    slot_size: u32,
    active: Option<(usize, u32)>,
}

#[derive(Debug, Clone, Copy)]
struct Header {
    generation: u32,
    len: u32,
    crc: u32,
}

impl<F: NorFlash> ModelStore<F> {
    /// `slot_size` must be a multiple of the erase size; slots at 0 and `slot_size`.
    pub fn new(flash: F, slot_size: u32) -> Self {
        ModelStore {
            flash,
            slots: [0, slot_size],
            slot_size,
            active: None,
        }
    }

    pub fn flash(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Find the newest valid slot and parse its model; `buf` is scratch.
    pub fn load(&mut self, buf: &mut [u8; MAX_IMAGE_BYTES]) -> Option<Model> {
        self.active = None;
        let mut best: Option<(usize, u32)> = None;
        for s in 0..2 {
            if let Some(h) = self.valid_header(s, buf) {
                let newer = match best {
                    None => true,
                    // Wrapping comparison: generation g+1 is newer than g.
                    Some((_, g)) => (h.generation.wrapping_sub(g) as i32) > 0,
                };
                if newer {
                    best = Some((s, h.generation));
                }
            }
        }
        let (s, g) = best?;
        let h = self.valid_header(s, buf)?;
        let model = Model::parse(&buf[..h.len as usize]).ok()?;
        self.active = Some((s, g));
        Some(model)
    }

    /// Slot index and generation of the model that `load` or `commit` made active.
    pub fn active(&self) -> Option<(usize, u32)> {
        self.active
    }

    /// Reads slot `s`'s image into `buf` and returns its header when the slot
    /// holds a complete, CRC-correct image that parses.
    fn valid_header(&mut self, s: usize, buf: &mut [u8; MAX_IMAGE_BYTES]) -> Option<Header> {
        let base = self.slots[s];
        let mut h = [0u8; HEADER as usize];
        self.flash.read(base, &mut h).ok()?;
        if h[0..4] != MAGIC {
            return None;
        }
        let word = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let header = Header {
            generation: word(4),
            len: word(8),
            crc: word(12),
        };
        let len = header.len as usize;
        if len == 0 || len > MAX_IMAGE_BYTES || header.len + HEADER > self.slot_size {
            return None;
        }
        self.flash.read(base + HEADER, &mut buf[..len]).ok()?;
        if crc32(&buf[..len]) != header.crc || Model::parse(&buf[..len]).is_err() {
            return None;
        }
        Some(header)
    }

    /// Write `image` to the inactive slot and make it the active one.
    pub fn commit(&mut self, image: &[u8]) -> Result<(), StoreError> {
        let len = image.len() as u32;
        if image.is_empty() || image.len() > MAX_IMAGE_BYTES || len + HEADER > self.slot_size {
            return Err(StoreError::TooLarge);
        }
        let (target, generation) = match self.active {
            Some((s, g)) => (1 - s, g.wrapping_add(1)),
            None => (0, 1),
        };
        let base = self.slots[target];
        self.flash
            .erase(base, base + self.slot_size)
            .map_err(|_| StoreError::Flash)?;
        // Program the image in write-size-aligned chunks (the tail padded with 0xFF).
        let ws = F::WRITE_SIZE.max(1);
        let mut chunk = [0xFFu8; 64];
        let step = (chunk.len() / ws) * ws;
        let mut off = 0usize;
        while off < image.len() {
            let n = (image.len() - off).min(step);
            let padded = n.div_ceil(ws) * ws;
            chunk[..padded].fill(0xFF);
            chunk[..n].copy_from_slice(&image[off..off + n]);
            self.flash
                .write(base + HEADER + off as u32, &chunk[..padded])
                .map_err(|_| StoreError::Flash)?;
            off += n;
        }
        let mut h = [0u8; HEADER as usize];
        h[0..4].copy_from_slice(&MAGIC);
        h[4..8].copy_from_slice(&generation.to_le_bytes());
        h[8..12].copy_from_slice(&len.to_le_bytes());
        h[12..16].copy_from_slice(&crc32(image).to_le_bytes());
        // The magic goes last (write sizes up to 4 bytes; larger ones write the header at once).
        if ws <= 4 {
            self.flash
                .write(base + 4, &h[4..])
                .map_err(|_| StoreError::Flash)?;
            self.flash
                .write(base, &h[..4])
                .map_err(|_| StoreError::Flash)?;
        } else {
            self.flash
                .write(base, &h[..ws.min(16)])
                .map_err(|_| StoreError::Flash)?;
        }
        self.active = Some((target, generation));
        Ok(())
    }
}

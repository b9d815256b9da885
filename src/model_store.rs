//! Two slots in flash (A/B) holding the model and the board's settings, so
//! that a power loss at any moment leaves the old model and settings or the
//! new ones, never a broken one.
//!
//! Slot layout: a 16-byte header — magic "TCSL", generation u32, image length
//! u32, CRC-32 of the image — then the image (length 0: no model, settings
//! only), then at the next 4-byte boundary a settings block — magic "TCSE",
//! length u32, CRC-32 of the payload, the payload ([`crate::settings`]).
//! A commit (of a model or of settings) erases the inactive slot, programs
//! the image, the settings block, then the header's last three words, and
//! the magic last of all: until the magic is there, the slot is not a
//! candidate. At boot the valid slot (magic, length, CRC and a model that
//! parses) with the newer generation wins; its settings block counts when
//! its own magic and CRC are right (a slot written before settings existed
//! has none: defaults).

use embedded_storage::nor_flash::NorFlash;

use crate::hal::flash::BackgroundErase;
use thermocomp_core::image::crc32;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;

const MAGIC: [u8; 4] = *b"TCSL";
const HEADER: u32 = 16;
const SETTINGS_MAGIC: [u8; 4] = *b"TCSE";
/// Largest settings payload a slot carries.
pub const MAX_SETTINGS_BYTES: usize = 640;

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
    /// Image length and CRC of the active slot (0, 0: no model).
    active_image: (u32, u32),
    /// The settings payload of the active slot (empty: none stored).
    settings: heapless::Vec<u8, MAX_SETTINGS_BYTES>,
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
            active_image: (0, 0),
            settings: heapless::Vec::new(),
        }
    }

    /// The stored settings payload (`None`: none stored yet).
    pub fn settings(&self) -> Option<&[u8]> {
        (!self.settings.is_empty()).then_some(&self.settings[..])
    }

    /// CRC-32 of the active slot's image (0: no model).
    pub fn active_crc(&self) -> u32 {
        self.active_image.1
    }

    pub fn flash(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Find the newest valid slot and parse its model; `buf` is scratch
    /// (at least `MAX_IMAGE_BYTES`: a longer image is no valid slot).
    pub fn load(&mut self, buf: &mut [u8]) -> Option<Model> {
        let mut m = Model::empty(0, 0);
        self.load_into(buf, &mut m).then_some(m)
    }

    /// As [`ModelStore::load`], parsed into `model` in place (each slot's
    /// image is checked by parsing it there; a board passes its
    /// compensator's model, so no model sits on its stack). `false`: no
    /// model (`model` then holds no valid model).
    pub fn load_into(&mut self, buf: &mut [u8], model: &mut Model) -> bool {
        // The chosen slot was parsed into `model` last, when it was checked.
        self.load_header(buf, model).is_some()
    }

    /// The newest valid slot made the active one, its settings read and its
    /// image in `buf`: the image's length (`None`: no model).
    fn load_header(&mut self, buf: &mut [u8], model: &mut Model) -> Option<usize> {
        self.active = None;
        let mut best: Option<(usize, u32)> = None;
        for s in 0..2 {
            if let Some(h) = self.valid_header(s, buf, model) {
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
        let h = self.valid_header(s, buf, model)?;
        self.active = Some((s, g));
        self.active_image = (h.len, h.crc);
        self.settings = self.read_settings(s, h.len);
        (h.len != 0).then_some(h.len as usize)
    }

    /// Offset of slot `s` (0 or 1; any other index reads as slot 1).
    fn slot_base(&self, s: usize) -> u32 {
        if s == 0 {
            self.slots[0]
        } else {
            self.slots[1]
        }
    }

    /// Offset of slot `s`'s settings block after an image of `len` bytes.
    fn settings_offset(&self, s: usize, len: u32) -> u32 {
        self.slot_base(s) + HEADER + len.div_ceil(4) * 4
    }

    fn read_settings(&mut self, s: usize, len: u32) -> heapless::Vec<u8, MAX_SETTINGS_BYTES> {
        let mut out = heapless::Vec::new();
        let at = self.settings_offset(s, len);
        let mut h = [0u8; 12];
        if at + 12 > self.slot_base(s) + self.slot_size || self.flash.read(at, &mut h).is_err() {
            return out;
        }
        let (words, _) = h.as_chunks::<4>();
        let &[magic, n, crc] = words else {
            return out;
        };
        let n = u32::from_le_bytes(n);
        let mut payload = [0u8; MAX_SETTINGS_BYTES];
        let Some(payload) = payload.get_mut(..n as usize) else {
            return out;
        };
        if magic != SETTINGS_MAGIC
            || n == 0
            || at + 12 + n > self.slot_base(s) + self.slot_size
            || self.flash.read(at + 12, payload).is_err()
            || crc32(payload) != u32::from_le_bytes(crc)
        {
            return out;
        }
        let _ = out.extend_from_slice(payload);
        out
    }

    /// Slot index and generation of the model that `load` or `commit` made active.
    pub fn active(&self) -> Option<(usize, u32)> {
        self.active
    }

    /// Reads slot `s`'s image into `buf` and returns its header when the slot
    /// holds a complete, CRC-correct image that parses (into `scratch`).
    fn valid_header(&mut self, s: usize, buf: &mut [u8], scratch: &mut Model) -> Option<Header> {
        let base = self.slot_base(s);
        let mut h = [0u8; HEADER as usize];
        self.flash.read(base, &mut h).ok()?;
        let (words, _) = h.as_chunks::<4>();
        let &[magic, generation, len, crc] = words else {
            return None;
        };
        if magic != MAGIC {
            return None;
        }
        let header = Header {
            generation: u32::from_le_bytes(generation),
            len: u32::from_le_bytes(len),
            crc: u32::from_le_bytes(crc),
        };
        let len = header.len as usize;
        if len > MAX_IMAGE_BYTES || header.len + HEADER > self.slot_size {
            return None;
        }
        if len == 0 {
            // Settings only, no model.
            return (header.crc == crc32(&[])).then_some(header);
        }
        let image = buf.get_mut(..len)?;
        self.flash.read(base + HEADER, image).ok()?;
        if crc32(image) != header.crc || scratch.parse_into(image).is_err() {
            return None;
        }
        Some(header)
    }

    /// Write `image` to the inactive slot (with the settings held now) and
    /// make it the active one.
    pub fn commit(&mut self, image: &[u8]) -> Result<(), StoreError> {
        if image.is_empty() || image.len() > MAX_IMAGE_BYTES {
            return Err(StoreError::TooLarge);
        }
        let settings = self.settings.clone();
        self.write_slot(Source::Bytes(image), &settings, true)?;
        Ok(())
    }

    /// As [`ModelStore::commit`], with a new settings payload in the same slot.
    pub fn commit_with(&mut self, image: &[u8], settings: &[u8]) -> Result<(), StoreError> {
        if image.is_empty() || image.len() > MAX_IMAGE_BYTES || settings.len() > MAX_SETTINGS_BYTES
        {
            return Err(StoreError::TooLarge);
        }
        let mut payload = heapless::Vec::new();
        let _ = payload.extend_from_slice(settings);
        self.write_slot(Source::Bytes(image), &payload, true)
    }

    /// Store a new settings payload with the model held now (copied from the
    /// active slot) and make that slot the active one.
    pub fn commit_settings(&mut self, payload: &[u8]) -> Result<(), StoreError> {
        if payload.is_empty() || payload.len() > MAX_SETTINGS_BYTES {
            return Err(StoreError::TooLarge);
        }
        let mut settings = heapless::Vec::new();
        let _ = settings.extend_from_slice(payload);
        match self.active {
            Some((s, _)) if self.active_image.0 > 0 => {
                let (len, crc) = self.active_image;
                self.write_slot(Source::Slot { s, len, crc }, &settings, true)
            }
            _ => self.write_slot(Source::Bytes(&[]), &settings, true),
        }
    }

    /// Offsets of the inactive slot (the one the next commit writes).
    fn inactive_range(&self) -> (u32, u32) {
        let target = self.active.map_or(0, |(s, _)| 1 - s);
        (
            self.slot_base(target),
            self.slot_base(target) + self.slot_size,
        )
    }

    /// Second half of a commit after [`ModelStore::begin`] erased the
    /// inactive slot: program `image` (`None`: keep the model held now) and
    /// the `settings` payload, header and magic last; then it is the active slot.
    pub fn finish(&mut self, image: Option<&[u8]>, settings: &[u8]) -> Result<(), StoreError> {
        if settings.len() > MAX_SETTINGS_BYTES {
            return Err(StoreError::TooLarge);
        }
        let mut payload = heapless::Vec::new();
        let _ = payload.extend_from_slice(settings);
        let source = match (image, self.active) {
            (Some(b), _) if b.is_empty() || b.len() > MAX_IMAGE_BYTES => {
                return Err(StoreError::TooLarge)
            }
            (Some(b), _) => Source::Bytes(b),
            (None, Some((s, _))) if self.active_image.0 > 0 => {
                let (len, crc) = self.active_image;
                Source::Slot { s, len, crc }
            }
            (None, _) => Source::Bytes(&[]),
        };
        self.write_slot(source, &payload, false)
    }

    fn write_slot(
        &mut self,
        image: Source,
        settings: &heapless::Vec<u8, MAX_SETTINGS_BYTES>,
        erase: bool,
    ) -> Result<(), StoreError> {
        let (len, crc) = match image {
            Source::Bytes(b) => {
                let len = u32::try_from(b.len()).map_err(|_| StoreError::TooLarge)?;
                (len, crc32(b))
            }
            Source::Slot { len, crc, .. } => (len, crc),
        };
        let settings_len = u32::try_from(settings.len()).map_err(|_| StoreError::TooLarge)?;
        let settings_end = HEADER + len.div_ceil(4) * 4 + 12 + settings_len;
        if settings_end > self.slot_size {
            return Err(StoreError::TooLarge);
        }
        let (target, generation) = match self.active {
            Some((s, g)) => (1 - s, g.wrapping_add(1)),
            None => (0, 1),
        };
        let base = self.slot_base(target);
        if erase {
            self.flash
                .erase(base, base + self.slot_size)
                .map_err(|_| StoreError::Flash)?;
        }
        // Program the image in write-size-aligned chunks (the tail padded with 0xFF).
        let ws = F::WRITE_SIZE.max(1);
        let mut chunk = [0xFFu8; 64];
        let step = (chunk.len() / ws) * ws;
        let mut off = 0u32;
        while off < len {
            let n = ((len - off) as usize).min(step);
            let padded = chunk
                .get_mut(..n.div_ceil(ws) * ws)
                .ok_or(StoreError::TooLarge)?;
            padded.fill(0xFF);
            let data = padded.get_mut(..n).ok_or(StoreError::TooLarge)?;
            match image {
                Source::Bytes(b) => {
                    let start = off as usize;
                    let bytes = b.get(start..start + n).ok_or(StoreError::TooLarge)?;
                    data.copy_from_slice(bytes);
                }
                Source::Slot { s, .. } => self
                    .flash
                    .read(self.slot_base(s) + HEADER + off, data)
                    .map_err(|_| StoreError::Flash)?,
            }
            self.flash
                .write(base + HEADER + off, padded)
                .map_err(|_| StoreError::Flash)?;
            #[allow(clippy::cast_possible_truncation, reason = "n <= step <= 64")]
            let n = n as u32;
            off += n;
        }
        // The settings block, before the header.
        if !settings.is_empty() {
            let mut block = [0xFFu8; 12 + MAX_SETTINGS_BYTES + 8];
            let (n, crc) = (settings_len.to_le_bytes(), crc32(settings).to_le_bytes());
            let content = SETTINGS_MAGIC.iter().chain(&n).chain(&crc).chain(settings);
            for (b, &v) in block.iter_mut().zip(content) {
                *b = v;
            }
            let total = (12 + settings.len()).div_ceil(ws) * ws;
            let at = self.settings_offset(target, len);
            self.flash
                .write(at, block.get(..total).unwrap_or(&block))
                .map_err(|_| StoreError::Flash)?;
        }
        let mut h = [0u8; HEADER as usize];
        h[0..4].copy_from_slice(&MAGIC);
        h[4..8].copy_from_slice(&generation.to_le_bytes());
        h[8..12].copy_from_slice(&len.to_le_bytes());
        h[12..16].copy_from_slice(&crc.to_le_bytes());
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
                .write(base, h.get(..ws).unwrap_or(&h))
                .map_err(|_| StoreError::Flash)?;
        }
        self.active = Some((target, generation));
        self.active_image = (len, crc);
        self.settings = settings.clone();
        Ok(())
    }
}

impl<F: BackgroundErase> ModelStore<F> {
    /// Parse the active slot's image, read where the flash maps it, into
    /// `model`: `true` when it is the image the slot's header names (its
    /// CRC-32) and parses. No scratch buffer: the commit check uses this to
    /// put the model in force back after lending its storage to a
    /// candidate ([`thermocomp_core::compensator::Compensator::check_with`]).
    pub fn reparse_active(&self, model: &mut Model) -> bool {
        let (len, crc) = self.active_image;
        let Some((s, _)) = self.active.filter(|_| len != 0) else {
            return false;
        };
        let Some(image) = self.flash.mapped(self.slot_base(s) + HEADER, len) else {
            return false;
        };
        crc32(image) == crc && model.parse_into(image).is_ok()
    }

    /// First half of a commit: start erasing the inactive slot (the active
    /// one keeps serving; a power cut now leaves it as it was).
    pub fn begin(&mut self) -> Result<(), StoreError> {
        let (from, to) = self.inactive_range();
        self.flash
            .start_erase(from, to)
            .map_err(|_| StoreError::Flash)
    }

    /// Whether [`ModelStore::begin`] may start the erase now
    /// ([`BackgroundErase::ready_to_erase`]).
    pub fn ready_to_erase(&mut self) -> bool {
        self.flash.ready_to_erase()
    }

    /// True once the erase [`ModelStore::begin`] started is done.
    pub fn erase_done(&mut self) -> bool {
        self.flash.erase_done()
    }
}

/// Where a slot's image comes from: new bytes, or the active slot (a
/// settings commit keeps the model).
#[derive(Clone, Copy)]
enum Source<'a> {
    Bytes(&'a [u8]),
    Slot { s: usize, len: u32, crc: u32 },
}

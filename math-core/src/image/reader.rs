//! A cursor over image bytes: every read is bounds-checked and a short
//! read is [`ImageError::LengthMismatch`], so the parser cannot panic on
//! any input.

use super::error::ImageError;

pub(super) struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// A reader of `bytes` from offset `at`.
    pub(super) fn new(bytes: &'a [u8], at: usize) -> Self {
        Reader { bytes, at }
    }

    /// Every byte has been read.
    pub(super) fn is_at_end(&self) -> bool {
        self.at == self.bytes.len()
    }

    /// A reader of the next `len` bytes (a section's payload), which this
    /// one skips; `None` when fewer remain.
    pub(super) fn take(&mut self, len: usize) -> Option<Reader<'a>> {
        let end = self.at.checked_add(len)?;
        let part = self.bytes.get(self.at..end)?;
        self.at = end;
        Some(Reader::new(part, 0))
    }

    pub(super) fn array<const N: usize>(&mut self) -> Result<[u8; N], ImageError> {
        let end = self.at.checked_add(N).ok_or(ImageError::LengthMismatch)?;
        let part = self
            .bytes
            .get(self.at..end)
            .ok_or(ImageError::LengthMismatch)?;
        let a = <[u8; N]>::try_from(part).map_err(|_| ImageError::LengthMismatch)?;
        self.at = end;
        Ok(a)
    }

    pub(super) fn u8(&mut self) -> Result<u8, ImageError> {
        let [b] = self.array()?;
        Ok(b)
    }

    pub(super) fn u16(&mut self) -> Result<u16, ImageError> {
        Ok(u16::from_le_bytes(self.array()?))
    }

    pub(super) fn i16(&mut self) -> Result<i16, ImageError> {
        Ok(i16::from_le_bytes(self.array()?))
    }

    pub(super) fn u32(&mut self) -> Result<u32, ImageError> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    pub(super) fn i32(&mut self) -> Result<i32, ImageError> {
        Ok(i32::from_le_bytes(self.array()?))
    }

    /// Fill `dst` with i32s. Out of line: inlined, the weight loops (bounded
    /// by the array sizes) are unrolled into the caller, and parsing is not
    /// hot while flash is scarce. One slice type for every caller, so the
    /// board carries it once (not once per iterator type).
    #[inline(never)]
    pub(super) fn i32s(&mut self, dst: &mut [i32]) -> Result<(), ImageError> {
        for v in dst {
            *v = self.i32()?;
        }
        Ok(())
    }

    /// Fill the first `n` of `dst` (all of it if shorter) with i32s.
    pub(super) fn first_i32s(&mut self, dst: &mut [i32], n: usize) -> Result<(), ImageError> {
        let n = n.min(dst.len());
        self.i32s(dst.get_mut(..n).unwrap_or_default())
    }

    /// A one-byte count, refused above `max`.
    pub(super) fn count(&mut self, what: &'static str, max: usize) -> Result<u8, ImageError> {
        let n = self.u8()?;
        if usize::from(n) > max {
            return Err(ImageError::TooMany {
                what,
                count: usize::from(n),
                max,
            });
        }
        Ok(n)
    }
}

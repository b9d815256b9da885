//! Which sensor feeds which channel. Kept across power cycles: a replaced
//! sensor goes to a free channel, never silently into another's place.
//!
//! Persisted form ([`ChannelMap::to_bytes`]): `b"TCM"`, format version 1,
//! then [`MAX_CHANNELS`] × 8 bytes of ROM code in channel order (eight zero
//! bytes = channel unused), then a CRC-8 over everything before it:
//! [`CHANNEL_MAP_BYTES`] = 165 bytes.

use super::rom::RomCode;
use thermocomp_core::crc::crc8_maxim;
use thermocomp_protocol::MAX_CHANNELS;

/// Size of the persisted form.
pub const CHANNEL_MAP_BYTES: usize = 4 + 8 * MAX_CHANNELS + 1;
const MAGIC: [u8; 4] = [b'T', b'C', b'M', 1];

/// Channel map errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum MapError {
    /// Channel index ≥ [`MAX_CHANNELS`].
    NoSuchChannel,
    /// The ROM code is already mapped to another channel.
    Duplicate,
    /// The ROM code fails its CRC or is all zero.
    InvalidRom,
    /// No free channel for a new sensor.
    Full,
    /// Persisted block: wrong length, magic or version.
    BadFormat,
    /// Persisted block: CRC mismatch.
    BadCrc,
}

/// ROM code → channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChannelMap {
    roms: [Option<RomCode>; MAX_CHANNELS],
}

impl Default for ChannelMap {
    fn default() -> Self {
        Self::new()
    }
}

impl ChannelMap {
    /// Empty map.
    pub const fn new() -> ChannelMap {
        ChannelMap {
            roms: [None; MAX_CHANNELS],
        }
    }

    /// The sensor on `channel`.
    pub fn get(&self, channel: usize) -> Option<RomCode> {
        self.roms.get(channel).copied().flatten()
    }

    /// The channel of `rom`.
    pub fn channel_of(&self, rom: &RomCode) -> Option<usize> {
        self.roms.iter().position(|r| r.as_ref() == Some(rom))
    }

    /// Number of mapped channels.
    pub fn len(&self) -> usize {
        self.roms.iter().filter(|r| r.is_some()).count()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Maps `rom` to `channel` (`None` frees it).
    pub fn set(&mut self, channel: usize, rom: Option<RomCode>) -> Result<(), MapError> {
        if channel >= MAX_CHANNELS {
            return Err(MapError::NoSuchChannel);
        }
        if let Some(r) = &rom {
            if !r.is_valid() {
                return Err(MapError::InvalidRom);
            }
            if let Some(c) = self.channel_of(r) {
                if c != channel {
                    return Err(MapError::Duplicate);
                }
            }
        }
        if let Some(slot) = self.roms.get_mut(channel) {
            *slot = rom;
        }
        Ok(())
    }

    /// Puts every ROM code of `found` that is not mapped yet into the lowest
    /// free channel, in the order given. Returns how many were added; stops
    /// with [`MapError::Full`] when no channel is free.
    pub fn assign_new(&mut self, found: &[RomCode]) -> Result<usize, MapError> {
        let mut added = 0;
        for rom in found {
            if self.channel_of(rom).is_some() {
                continue;
            }
            if !rom.is_valid() {
                return Err(MapError::InvalidRom);
            }
            let free = self
                .roms
                .iter()
                .position(|r| r.is_none())
                .ok_or(MapError::Full)?;
            self.set(free, Some(*rom))?;
            added += 1;
        }
        Ok(added)
    }

    /// Mapped channels, `(channel, rom)`.
    pub fn iter(&self) -> impl Iterator<Item = (usize, RomCode)> + '_ {
        self.roms
            .iter()
            .enumerate()
            .filter_map(|(c, r)| r.map(|r| (c, r)))
    }

    /// The persisted form.
    pub fn to_bytes(&self) -> [u8; CHANNEL_MAP_BYTES] {
        let mut out = [0u8; CHANNEL_MAP_BYTES];
        out[..4].copy_from_slice(&MAGIC);
        for (chunk, rom) in out[4..4 + 8 * MAX_CHANNELS]
            .chunks_exact_mut(8)
            .zip(self.roms.iter())
        {
            if let Some(r) = rom {
                chunk.copy_from_slice(&r.0);
            }
        }
        out[CHANNEL_MAP_BYTES - 1] = crc8_maxim(&out[..CHANNEL_MAP_BYTES - 1]);
        out
    }

    /// Reads the persisted form; rejects anything that does not check.
    pub fn from_bytes(bytes: &[u8]) -> Result<ChannelMap, MapError> {
        if bytes.len() != CHANNEL_MAP_BYTES || bytes.get(..4) != Some(&MAGIC[..]) {
            return Err(MapError::BadFormat);
        }
        if crc8_maxim(bytes) != 0 {
            return Err(MapError::BadCrc);
        }
        let mut map = ChannelMap::new();
        let body = bytes
            .get(4..4 + 8 * MAX_CHANNELS)
            .ok_or(MapError::BadFormat)?;
        for (channel, chunk) in body.chunks_exact(8).enumerate() {
            let mut rom = [0u8; 8];
            rom.copy_from_slice(chunk);
            if rom != [0; 8] {
                map.set(channel, Some(RomCode(rom)))?;
            }
        }
        Ok(map)
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation
)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_corruption() {
        let mut m = ChannelMap::new();
        let a = RomCode::from_serial(0x28, [1, 0, 0, 0, 0, 0]);
        let b = RomCode::from_serial(0x28, [2, 0, 0, 0, 0, 0]);
        m.set(5, Some(a)).unwrap();
        assert_eq!(m.assign_new(&[a, b]), Ok(1));
        assert_eq!(m.get(0), Some(b));
        assert_eq!(m.set(7, Some(a)), Err(MapError::Duplicate));
        let bytes = m.to_bytes();
        assert_eq!(ChannelMap::from_bytes(&bytes), Ok(m));
        let mut bad = bytes;
        bad[10] ^= 4;
        assert_eq!(ChannelMap::from_bytes(&bad), Err(MapError::BadCrc));
        assert_eq!(
            ChannelMap::from_bytes(&bytes[1..]),
            Err(MapError::BadFormat)
        );
    }
}

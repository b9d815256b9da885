//! The settings store: settings, channel map, kept reference, keys, probe
//! setup and the probe-reference terms as key–value records in a
//! wear-levelled, power-fail-safe map ([`sequential_storage::map`]) on
//! small sectors of their own, apart from the model slots
//! ([`crate::model_store`]). A record is appended when it changes; a page is
//! erased only when the map needs a fresh one (one 16 KiB sector on the
//! F446, ≈ 0.25–0.5 s), and the model slots only by a model commit.
//!
//! Wear: one probe reference writes one direction's terms (an item of
//! 8 + 1 + 4 + 58 bytes, 72 with padding). At one reference per minute for
//! a year that is ≈ 38 MB through a 48 KiB area: ≈ 770 erases per sector
//! per year (`scripts/bench-flash-wear.sh` measures it on the mock flash).
//!
//! The map runs on the blocking flash through [`Window`] (an adapter that
//! declares the store's page size and forwards to the board's blocking
//! flash; embassy-embedded-hal's `BlockingAsync` keeps the flash's own
//! erase size, which on the F446 is the 128 KiB of the model sectors), and
//! its futures are driven to completion with `embassy_futures::block_on`:
//! every flash call returns at once, so each future is ready on its first
//! poll.

use core::ops::Range;

use embedded_storage::nor_flash::NorFlash;
use sequential_storage::cache::Cache;
use sequential_storage::map::{MapConfig, MapStorage};

/// The store's page: one 16 KiB sector of the F446 (sectors 1–3).
pub const PAGE: u32 = 16 * 1024;
/// Pages in the store (sequential-storage needs at least two).
pub const PAGES: u32 = 3;
/// Bytes of flash the store occupies.
pub const AREA_BYTES: u32 = PAGE * PAGES;
/// Largest record value (the channel map, 165 bytes, is the longest).
pub const MAX_VALUE: usize = 192;
/// The map's working buffer: key + value, rounded to the flash word.
const BUF: usize = MAX_VALUE + 8;

/// The record keys. Stable: a key's meaning never changes (a new record
/// takes a new key; an older firmware ignores keys it does not know).
pub mod key {
    pub const SETTINGS: u8 = 1;
    pub const CHANNEL_MAP: u8 = 2;
    /// The kept reference sample; a one-byte value `[0]`: none kept.
    pub const KEPT: u8 = 3;
    /// The board's keys; `[0]`: none stored.
    pub const KEYS: u8 = 4;
    /// The probe setup (holding registers 40–45).
    pub const PROBE_SETUP: u8 = 5;
    /// The old slots' settings were copied here (migration done): `[1]`.
    pub const MIGRATED: u8 = 6;
    /// When to ask for a probe reference: holding registers 46–48 (u16 LE
    /// each), then the rule's state (`thermocomp_core::ask`, 16 bytes).
    pub const ASK: u8 = 7;
    /// The probe-reference rule's parameters: holding registers 90–99 as
    /// written (u16 LE each, 0xFFFF: the firmware's default).
    pub const RULE: u8 = 8;
    /// Probe-reference terms of direction `d`: `TERMS + d`, 6 keys.
    pub const TERMS: u8 = 16;
}

/// Records the application keeps: the terms of each direction, when to ask
/// for a reference, the rule's parameters, the probe setup, the keys, the
/// kept reference, the channel map and the settings.
pub const RECORDS: usize = thermocomp_core::limits::MAX_DIRECTIONS + 7;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingsStoreError {
    /// The flash refused a read, write or erase (or power was lost).
    Flash,
    /// The map found its pages inconsistent beyond repair, or full.
    Corrupted,
    /// A value longer than [`MAX_VALUE`].
    TooLarge,
}

/// The store's place in the board's flash and its erase count.
#[derive(Debug, Clone)]
pub struct SettingsStore {
    area: Range<u32>,
    /// Page erases done by this store since boot (the wear bench reads it).
    erases: u32,
}

impl SettingsStore {
    /// `area`: offsets in the board's flash, [`AREA_BYTES`] long, on
    /// [`PAGE`] boundaries (checked by [`SettingsStore::valid`]).
    pub const fn new(area: Range<u32>) -> Self {
        SettingsStore { area, erases: 0 }
    }

    /// Whether the area is one the map can run on: page-aligned, at least
    /// two pages, and the flash's own erase size divides the page.
    pub fn valid<F: NorFlash>(&self) -> bool {
        let Range { start, end } = self.area;
        start.is_multiple_of(PAGE)
            && end.is_multiple_of(PAGE)
            && end >= start + 2 * PAGE
            && F::ERASE_SIZE > 0
            && PAGE.is_multiple_of(u32::try_from(F::ERASE_SIZE).unwrap_or(u32::MAX))
    }

    /// Page erases this store started since boot.
    pub fn erases(&self) -> u32 {
        self.erases
    }

    /// The last value stored under `key`, copied into `out`; `Ok(None)`: none.
    pub fn fetch<F: NorFlash>(
        &mut self,
        flash: &mut F,
        key: u8,
        out: &mut [u8; MAX_VALUE],
    ) -> Result<Option<usize>, SettingsStoreError> {
        if !self.valid::<F>() {
            return Err(SettingsStoreError::Corrupted);
        }
        let mut buf = [0u8; BUF];
        let mut window = Window::new(flash, &mut self.erases);
        let Ok(config) = MapConfig::try_new(self.area.clone()) else {
            return Err(SettingsStoreError::Corrupted);
        };
        let mut map = MapStorage::<u8, _, _>::new(&mut window, config, Cache::new_uncached());
        let got = embassy_futures::block_on(map.fetch_item::<&[u8]>(&mut buf, &key));
        match got {
            Ok(Some(v)) => {
                let n = v.len();
                let dst = out.get_mut(..n).ok_or(SettingsStoreError::TooLarge)?;
                dst.copy_from_slice(v);
                Ok(Some(n))
            }
            Ok(None) => Ok(None),
            Err(e) => Err(map_error(e)),
        }
    }

    /// Erase the whole area (a store found unreadable: an area that held
    /// something else before, e.g. program code on a board updated from
    /// the old layout). Every record is lost.
    pub fn format<F: NorFlash>(&mut self, flash: &mut F) -> Result<(), SettingsStoreError> {
        if !self.valid::<F>() {
            return Err(SettingsStoreError::Corrupted);
        }
        self.erases = self.erases.saturating_add(PAGES);
        flash
            .erase(self.area.start, self.area.end)
            .map_err(|_| SettingsStoreError::Flash)
    }

    /// Store `value` under `key` (it replaces the last one). At most one
    /// page erase, and only when the page in use is full.
    pub fn store<F: NorFlash>(
        &mut self,
        flash: &mut F,
        key: u8,
        value: &[u8],
    ) -> Result<(), SettingsStoreError> {
        if value.len() > MAX_VALUE {
            return Err(SettingsStoreError::TooLarge);
        }
        if !self.valid::<F>() {
            return Err(SettingsStoreError::Corrupted);
        }
        let mut buf = [0u8; BUF];
        let mut window = Window::new(flash, &mut self.erases);
        let Ok(config) = MapConfig::try_new(self.area.clone()) else {
            return Err(SettingsStoreError::Corrupted);
        };
        let mut map = MapStorage::<u8, _, _>::new(&mut window, config, Cache::new_uncached());
        embassy_futures::block_on(map.store_item(&mut buf, &key, &value)).map_err(map_error)
    }
}

fn map_error<E>(e: sequential_storage::Error<E>) -> SettingsStoreError {
    match e {
        sequential_storage::Error::Storage { .. } => SettingsStoreError::Flash,
        sequential_storage::Error::BufferTooBig | sequential_storage::Error::BufferTooSmall(_) => {
            SettingsStoreError::TooLarge
        }
        _ => SettingsStoreError::Corrupted,
    }
}

/// The board's blocking flash seen by the map: pages of [`PAGE`] bytes,
/// every call forwarded at once (so the map's futures are ready on their
/// first poll), erases counted.
pub struct Window<'a, F: NorFlash> {
    flash: &'a mut F,
    erases: &'a mut u32,
}

impl<'a, F: NorFlash> Window<'a, F> {
    fn new(flash: &'a mut F, erases: &'a mut u32) -> Self {
        Window { flash, erases }
    }
}

impl<F: NorFlash> embedded_storage_async::nor_flash::ErrorType for Window<'_, F> {
    type Error = F::Error;
}

impl<F: NorFlash> embedded_storage_async::nor_flash::ReadNorFlash for Window<'_, F> {
    const READ_SIZE: usize = F::READ_SIZE;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), F::Error> {
        self.flash.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> embedded_storage_async::nor_flash::NorFlash for Window<'_, F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = PAGE as usize;
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), F::Error> {
        *self.erases = self.erases.saturating_add(to.saturating_sub(from) / PAGE);
        self.flash.erase(from, to)
    }
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), F::Error> {
        self.flash.write(offset, bytes)
    }
}

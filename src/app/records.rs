//! What the app keeps besides the model, as records of the settings store
//! ([`crate::settings_store`]): one record per thing that changes on its
//! own, so that a probe reference writes one direction's terms (72 bytes)
//! and nothing else. Each record is replaced whole (old or new after a
//! power cut, never neither); the settings record is written last, and its
//! presence makes the store the board's settings (before it, a board
//! updated from the old layout reads its old slot's settings block once and
//! copies it here: [`App::migrate`]).

use thermocomp_core::ask::{AskParams, ASK_STATE_BYTES};
use thermocomp_core::image::crc32;
use thermocomp_core::limits::MAX_DIRECTIONS;
use thermocomp_core::reference::{ReferenceState, STATE_BYTES};

use super::App;
use crate::acquisition::channel_map::{ChannelMap, CHANNEL_MAP_BYTES};
use crate::hal::flash::BackgroundErase;
use crate::probe_reference::{decode_setup, encode_setup};
use crate::settings::{KeptReference, Settings, StoredKeys, ENCODED_LEN as SETTINGS_LEN};
use crate::settings_store::{key, SettingsStoreError, MAX_VALUE, RECORDS};
use thermocomp_protocol::holding::rule;

/// Records in write order: the terms of each direction, when to ask for a
/// reference, the rule's parameters, the probe setup, the keys, the kept
/// reference, the channel map, and the settings last.
const COUNT: usize = RECORDS;
/// A terms record: the CRC-32 of the model image they were learned on,
/// then the core's state bytes.
const TERMS_LEN: usize = 4 + STATE_BYTES;
/// "None" for the optional records (kept reference, keys).
const NONE: [u8; 1] = [0];

/// The ask record: holding registers 46–48, then the rule's state.
const ASK_LEN: usize = 6 + ASK_STATE_BYTES;

const _: () = assert!(TERMS_LEN <= MAX_VALUE && CHANNEL_MAP_BYTES <= MAX_VALUE);

/// The store key of record `i` (in write order).
fn key_of(i: usize) -> u8 {
    match i {
        // i < MAX_DIRECTIONS = 6 (the match arm's guard).
        #[allow(clippy::cast_possible_truncation, reason = "i < MAX_DIRECTIONS")]
        i if i < MAX_DIRECTIONS => key::TERMS + i as u8,
        i => match i - MAX_DIRECTIONS {
            0 => key::ASK,
            1 => key::RULE,
            2 => key::PROBE_SETUP,
            3 => key::KEYS,
            4 => key::KEPT,
            5 => key::CHANNEL_MAP,
            _ => key::SETTINGS,
        },
    }
}

impl<F: BackgroundErase> App<F> {
    /// Record `i`'s value as it stands now, in `out`: its length.
    fn record(&self, i: usize, out: &mut [u8; MAX_VALUE]) -> usize {
        let mut put = |bytes: &[u8]| {
            let n = bytes.len().min(MAX_VALUE);
            if let (Some(dst), Some(src)) = (out.get_mut(..n), bytes.get(..n)) {
                dst.copy_from_slice(src);
            }
            n
        };
        if i < MAX_DIRECTIONS {
            let mut v = [0u8; TERMS_LEN];
            let (crc, state) = v.split_at_mut(4);
            crc.copy_from_slice(&self.store.active_crc().to_le_bytes());
            if let Some(b) = self.references.state_bytes(i) {
                state.copy_from_slice(&b);
            }
            return put(&v);
        }
        let h = &self.state;
        match key_of(i) {
            key::ASK => {
                let mut v = [0u8; ASK_LEN];
                let (params, state) = v.split_at_mut(6);
                let p = h.ask;
                for (c, w) in
                    params
                        .chunks_exact_mut(2)
                        .zip([p.settle_s, p.max_interval_s, p.speed_step_rpm])
                {
                    c.copy_from_slice(&w.to_le_bytes());
                }
                state.copy_from_slice(self.references.ask_saved());
                put(&v)
            }
            key::RULE => {
                let mut v = [0u8; 2 * rule::N];
                for (c, w) in v.chunks_exact_mut(2).zip(h.rule) {
                    c.copy_from_slice(&w.to_le_bytes());
                }
                put(&v)
            }
            key::PROBE_SETUP => put(&encode_setup(&h.probe)),
            key::KEYS => {
                let keys = StoredKeys {
                    unlock: h.keys.unlock,
                    signing: h.keys.signing,
                };
                if keys.is_empty() {
                    put(&NONE)
                } else {
                    put(&keys.encode())
                }
            }
            key::KEPT => match &self.kept {
                Some(k) => put(&k.encode()),
                None => put(&NONE),
            },
            key::CHANNEL_MAP => put(&self.map.to_bytes()),
            _ => put(&self.settings().encode()),
        }
    }

    /// CRC-32 of record `i` as it stands now.
    fn record_crc(&self, i: usize) -> u32 {
        let mut v = [0u8; MAX_VALUE];
        let n = self.record(i, &mut v);
        crc32(v.get(..n).unwrap_or(&v))
    }

    /// Whether any record differs from what the store holds.
    pub(super) fn records_dirty(&self) -> bool {
        (0..COUNT).any(|i| self.written.get(i).copied().flatten() != Some(self.record_crc(i)))
    }

    /// Write every record that changed, in order (the settings last). A
    /// store the map finds corrupted (an area that held something else) is
    /// formatted and written once more, whole.
    pub(super) fn store_records(&mut self) -> Result<(), SettingsStoreError> {
        match self.store_changed() {
            Err(SettingsStoreError::Corrupted) => {
                self.settings_store.format(self.store.flash())?;
                self.written = [None; COUNT];
                self.store_changed()
            }
            other => other,
        }
    }

    fn store_changed(&mut self) -> Result<(), SettingsStoreError> {
        for i in 0..COUNT {
            let mut v = [0u8; MAX_VALUE];
            let n = self.record(i, &mut v);
            let value = v.get(..n).unwrap_or(&v);
            let crc = crc32(value);
            if self.written.get(i).copied().flatten() == Some(crc) {
                continue;
            }
            self.settings_store
                .store(self.store.flash(), key_of(i), value)?;
            if let Some(w) = self.written.get_mut(i) {
                *w = Some(crc);
            }
        }
        Ok(())
    }

    /// The records from the store into the app; the settings (`None`: the
    /// store holds no settings record — a fresh board, or one updated from
    /// the old slot layout — and nothing was read).
    pub(super) fn load_records(&mut self) -> Option<Settings> {
        let mut v = [0u8; MAX_VALUE];
        let settings_i = COUNT - 1;
        let n = self.fetch_record(settings_i, &mut v)?;
        let settings = v.get(..n).and_then(Settings::decode);
        if let Some(map) = self
            .fetch_record(COUNT - 2, &mut v)
            .and_then(|n| ChannelMap::from_bytes(v.get(..n)?).ok())
        {
            self.map = map;
        }
        self.kept = self
            .fetch_record(COUNT - 3, &mut v)
            .and_then(|n| KeptReference::decode(v.get(..n)?));
        let keys = self
            .fetch_record(COUNT - 4, &mut v)
            .and_then(|n| StoredKeys::decode(v.get(..n)?))
            .unwrap_or_default();
        self.state.keys = crate::keys::Keys::stored(keys.unlock, keys.signing);
        if let Some(setup) = self
            .fetch_record(COUNT - 5, &mut v)
            .and_then(|n| decode_setup(v.get(..n)?))
        {
            self.state.probe = setup;
        }
        if let Some(n) = self.fetch_record(MAX_DIRECTIONS, &mut v) {
            self.load_ask(v.get(..n).unwrap_or(&[]));
        }
        // The terms count only with the model they were learned on, and
        // only all together.
        let model = self.store.active_crc().to_le_bytes();
        let mut states = [ReferenceState::default(); MAX_DIRECTIONS];
        let mut all = true;
        for (d, st) in states.iter_mut().enumerate() {
            let loaded = self.fetch_record(d, &mut v).and_then(|n| {
                let (crc, state) = v.get(..n)?.split_at_checked(4)?;
                (crc == model).then_some(())?;
                ReferenceState::from_bytes(state).ok()
            });
            match loaded {
                Some(s) => *st = s,
                None => all = false,
            }
        }
        if all {
            self.references.load_states(states);
        }
        if let Some(n) = self.fetch_record(MAX_DIRECTIONS + 1, &mut v) {
            self.load_rule(v.get(..n).unwrap_or(&[]));
        }
        settings.or(Some(self.defaults))
    }

    /// Record `i` from the store into `v` (its length), remembering its CRC.
    fn fetch_record(&mut self, i: usize, v: &mut [u8; MAX_VALUE]) -> Option<usize> {
        let got = self
            .settings_store
            .fetch(self.store.flash(), key_of(i), v)
            .ok()
            .flatten();
        if let (Some(n), Some(w)) = (got, self.written.get_mut(i)) {
            *w = v.get(..n).map(crc32);
        }
        got
    }

    /// The old slot layout's settings block (before issue 47), if the
    /// active slot has one: the settings, channel map, kept reference,
    /// keys, probe setup and terms, in force.
    pub(super) fn load_slot_settings(&mut self) -> Option<Settings> {
        let blob = self.store.settings()?;
        let stored = blob.get(..SETTINGS_LEN).and_then(Settings::decode);
        if let Some(map) = blob
            .get(SETTINGS_LEN..SETTINGS_LEN + CHANNEL_MAP_BYTES)
            .and_then(|b| ChannelMap::from_bytes(b).ok())
        {
            self.map = map;
        }
        // After the map: the kept reference (tag 'R'), the probe references
        // (tag 'Q') and the keys (tag 'K'), each optional, read by their tag.
        let mut copy = heapless::Vec::<u8, { crate::model_store::MAX_SETTINGS_BYTES }>::new();
        let _ = copy.extend_from_slice(blob.get(SETTINGS_LEN + CHANNEL_MAP_BYTES..)?);
        let tail = crate::settings::tail_records(&copy);
        self.kept = tail.kept;
        let keys = tail.keys.unwrap_or_default();
        self.state.keys = crate::keys::Keys::stored(keys.unlock, keys.signing);
        if let Some(setup) = tail.references.and_then(|r| self.references.decode(r)) {
            self.state.probe = setup;
        }
        stored
    }

    /// Copy the settings in force (read from the old slot layout) into the
    /// settings store, at boot. Its area may hold anything (on a board
    /// updated from the old layout, sectors 1–3 held program code): a store
    /// that fails is formatted and written once more.
    pub(super) fn migrate(&mut self) {
        self.written = [None; COUNT];
        if self.store_records().is_err() {
            let _ = self.settings_store.format(self.store.flash());
            self.written = [None; COUNT];
            let _ = self.store_records();
        }
    }
}

impl<F: BackgroundErase> App<F> {
    /// The rule record back: holding registers 90–99, in force. Another
    /// length or a value out of a register's range: nothing changes.
    fn load_rule(&mut self, b: &[u8]) {
        let mut regs = [rule::DEFAULT; rule::N];
        let (words, rest) = b.as_chunks::<2>();
        if words.len() != rule::N || !rest.is_empty() {
            return;
        }
        for (i, (r, w)) in regs.iter_mut().zip(words).enumerate() {
            *r = u16::from_le_bytes(*w);
            if !rule::valid(i, *r) {
                return;
            }
        }
        self.state.rule = regs;
        self.rule_in_force();
    }

    /// The ask record back: holding registers 46–48 and the rule's state
    /// (taken up at the first cycle). Another length: nothing changes.
    fn load_ask(&mut self, b: &[u8]) {
        let Some((params, state)) = b.split_first_chunk::<6>() else {
            return;
        };
        if state.len() != ASK_STATE_BYTES || !self.references.load_ask(state) {
            return;
        }
        let [s0, s1, i0, i1, r0, r1] = *params;
        self.state.ask = AskParams {
            settle_s: u16::from_le_bytes([s0, s1]),
            max_interval_s: u16::from_le_bytes([i0, i1]),
            speed_step_rpm: u16::from_le_bytes([r0, r1]),
        };
    }
}

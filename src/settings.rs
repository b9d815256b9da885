//! Settings that survive a reboot: unit address, baud rate, clamp and rate
//! overrides. They are stored with the model in the same A/B flash slots
//! ([`crate::model_store`]: a settings block after the image, written
//! before the slot's magic), so a power cut at any moment leaves the old
//! settings or the new ones, and are applied at boot. Command 7 restores
//! the defaults (and stores them). The slots also keep the channel map and
//! the kept reference sample ([`KeptReference`]) after these settings.

use thermocomp_core::limits::MAX_DIRECTIONS;

use thermocomp_protocol::holding::BAUD_RATES;
use thermocomp_protocol::MAX_CHANNELS;

/// Encoded size (bytes): version, unit, baud/100, clamp × 6, rate × 6.
pub const ENCODED_LEN: usize = 1 + 1 + 2 + 2 * MAX_DIRECTIONS * 2;
const VERSION: u8 = 1;
/// Unit address and baud rate of a board with default settings.
pub const DEFAULT_UNIT: u8 = 1;
pub const DEFAULT_BAUD: u32 = 115_200;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// Modbus unit address, 1–247.
    pub unit: u8,
    /// One of [`BAUD_RATES`].
    pub baud: u32,
    /// Per-direction clamp override, 0.1 µm (0xFFFF: none, the model's).
    pub clamp: [u16; MAX_DIRECTIONS],
    /// Per-direction rate-limit override, 0.1 µm/s (0xFFFF: none).
    pub rate: [u16; MAX_DIRECTIONS],
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            unit: DEFAULT_UNIT,
            baud: DEFAULT_BAUD,
            clamp: [u16::MAX; MAX_DIRECTIONS],
            rate: [u16::MAX; MAX_DIRECTIONS],
        }
    }
}

impl Settings {
    pub fn encode(&self) -> [u8; ENCODED_LEN] {
        let mut b = [0u8; ENCODED_LEN];
        // The baud rates the board accepts are below 6,553,600.
        let baud = u16::try_from(self.baud / 100).unwrap_or(u16::MAX);
        let words = [baud].into_iter().chain(self.clamp).chain(self.rate);
        let content = [VERSION, self.unit]
            .into_iter()
            .chain(words.flat_map(u16::to_le_bytes));
        for (byte, v) in b.iter_mut().zip(content) {
            *byte = v;
        }
        b
    }

    /// Settings from stored bytes; `None` for another version or a value
    /// outside its range (the board then keeps its defaults).
    pub fn decode(b: &[u8]) -> Option<Settings> {
        let (&[version, unit, baud_low, baud_high], limits) = b.split_first_chunk::<4>()?;
        if b.len() != ENCODED_LEN || version != VERSION {
            return None;
        }
        let baud = u32::from(u16::from_le_bytes([baud_low, baud_high])) * 100;
        if !(1..=247).contains(&unit) || !BAUD_RATES.contains(&baud) {
            return None;
        }
        let mut s = Settings {
            unit,
            baud,
            ..Settings::default()
        };
        // Clamps then rates, one little-endian word each.
        let (words, _) = limits.as_chunks::<2>();
        for (limit, &w) in s.clamp.iter_mut().chain(s.rate.iter_mut()).zip(words) {
            *limit = u16::from_le_bytes(w);
        }
        Some(s)
    }
}

/// Encoded size of a kept reference: tag, version, channel mask u32,
/// [`MAX_CHANNELS`] × i16 (1/16 °C).
pub const REFERENCE_LEN: usize = 2 + 4 + 2 * MAX_CHANNELS;
const REFERENCE_TAG: u8 = b'R';
const REFERENCE_VERSION: u8 = 1;

/// The reference sample a machine with a fixed reference keeps across
/// reboots (commands 10 and 11; command 7 drops it): per bus channel the
/// reading taken when it was kept (1/16 °C), so it serves any model that
/// reads these channels. Stored after the channel map in the slots'
/// settings block (same power-cut-safe commit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeptReference {
    /// 1/16 °C per channel; `None`: no reading when it was kept.
    pub temps: [Option<i16>; MAX_CHANNELS],
}

impl KeptReference {
    pub fn encode(&self) -> [u8; REFERENCE_LEN] {
        let mut b = [0u8; REFERENCE_LEN];
        let mask = (0..MAX_CHANNELS)
            .zip(self.temps)
            .filter(|(_, t)| t.is_some())
            .fold(0u32, |m, (c, _)| m | (1 << c));
        // A channel without a reading stores 0 under a clear mask bit.
        let temps = self
            .temps
            .into_iter()
            .flat_map(|t| t.unwrap_or(0).to_le_bytes());
        let content = [REFERENCE_TAG, REFERENCE_VERSION]
            .into_iter()
            .chain(mask.to_le_bytes())
            .chain(temps);
        for (byte, v) in b.iter_mut().zip(content) {
            *byte = v;
        }
        b
    }

    /// A kept reference from stored bytes; `None` for another length, tag
    /// or version, a channel bit beyond [`MAX_CHANNELS`], or a reading
    /// outside the DS18B20's range (−55…125 °C): the board then has none.
    pub fn decode(b: &[u8]) -> Option<KeptReference> {
        let (&[tag, version, m0, m1, m2, m3], readings) = b.split_first_chunk::<6>()?;
        if b.len() != REFERENCE_LEN || tag != REFERENCE_TAG || version != REFERENCE_VERSION {
            return None;
        }
        let mask = u32::from_le_bytes([m0, m1, m2, m3]);
        if mask >> MAX_CHANNELS != 0 {
            return None;
        }
        let mut temps = [None; MAX_CHANNELS];
        let (readings, _) = readings.as_chunks::<2>();
        for (c, (t, &reading)) in temps.iter_mut().zip(readings).enumerate() {
            if mask & (1 << c) != 0 {
                let v = i16::from_le_bytes(reading);
                if !(-55 * 16..=125 * 16).contains(&v) {
                    return None;
                }
                *t = Some(v);
            }
        }
        Some(KeptReference { temps })
    }
}

// ---------------------------------------------------------------------------
// Issue 30 (signed models, per-board unlock key): the board's keys, one
// tagged record after the channel map, beside the kept reference ('R').
// Records after the channel map are read by their tag ([`tail_records`]),
// so a slot written before a record existed still reads, and a record
// added later goes after these without moving them.
// ---------------------------------------------------------------------------

/// Encoded size of the keys record: tag, version, flags, unlock key u16,
/// signing public key (32 bytes).
pub const KEYS_LEN: usize = 3 + 2 + 32;
const KEYS_TAG: u8 = b'K';
const KEYS_VERSION: u8 = 1;
const KEYS_HAS_UNLOCK: u8 = 1 << 0;
const KEYS_HAS_SIGNING: u8 = 1 << 1;

/// The keys set at commissioning (holding registers 50–67, commands
/// 14–16). The unlock key is kept only here and in RAM: no register and
/// no log shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StoredKeys {
    /// The board's own unlock key (`None`: not commissioned).
    pub unlock: Option<u16>,
    /// The Ed25519 public key models must be signed with.
    pub signing: Option<[u8; 32]>,
}

impl StoredKeys {
    /// Nothing to store: no record is written.
    pub fn is_empty(&self) -> bool {
        self.unlock.is_none() && self.signing.is_none()
    }

    pub fn encode(&self) -> [u8; KEYS_LEN] {
        let mut b = [0u8; KEYS_LEN];
        let flags = if self.unlock.is_some() {
            KEYS_HAS_UNLOCK
        } else {
            0
        } | if self.signing.is_some() {
            KEYS_HAS_SIGNING
        } else {
            0
        };
        let content = [KEYS_TAG, KEYS_VERSION, flags]
            .into_iter()
            .chain(self.unlock.unwrap_or(0).to_le_bytes())
            .chain(self.signing.unwrap_or([0; 32]));
        for (byte, v) in b.iter_mut().zip(content) {
            *byte = v;
        }
        b
    }

    /// Keys from a stored record; `None` for another length, tag, version
    /// or unknown flag bits, or an unlock key of 0.
    pub fn decode(b: &[u8]) -> Option<StoredKeys> {
        let (&[tag, version, flags, k0, k1], signing) = b.split_first_chunk::<5>()?;
        if b.len() != KEYS_LEN || tag != KEYS_TAG || version != KEYS_VERSION {
            return None;
        }
        if flags & !(KEYS_HAS_UNLOCK | KEYS_HAS_SIGNING) != 0 {
            return None;
        }
        let unlock = u16::from_le_bytes([k0, k1]);
        let signing = <[u8; 32]>::try_from(signing).ok()?;
        Some(StoredKeys {
            unlock: if flags & KEYS_HAS_UNLOCK != 0 {
                Some(unlock).filter(|&k| k != 0)
            } else {
                None
            },
            signing: (flags & KEYS_HAS_SIGNING != 0).then_some(signing),
        })
    }
}

/// The tagged records after the channel map.
#[derive(Default)]
pub struct TailRecords<'a> {
    pub kept: Option<KeptReference>,
    pub keys: Option<StoredKeys>,
    /// The probe references' block (tag 'Q', decoded by
    /// `probe_reference::References::decode`).
    pub references: Option<&'a [u8]>,
}

/// The tagged records after the channel map: the kept reference, the probe
/// references and the keys, each at most once, in any order; reading stops
/// at an unknown tag.
pub fn tail_records(mut b: &[u8]) -> TailRecords<'_> {
    let mut out = TailRecords::default();
    while let Some(&tag) = b.first() {
        let len = match tag {
            REFERENCE_TAG => REFERENCE_LEN,
            KEYS_TAG => KEYS_LEN,
            crate::probe_reference::TAG => crate::probe_reference::BLOCK_LEN,
            _ => break,
        };
        let Some((record, rest)) = b.split_at_checked(len) else {
            break;
        };
        match tag {
            REFERENCE_TAG => out.kept = KeptReference::decode(record),
            KEYS_TAG => out.keys = StoredKeys::decode(record),
            _ => out.references = Some(record),
        }
        b = rest;
    }
    out
}

//! Holding registers (FC03 read, FC06/FC16 write): what the PLC writes
//! (spindle speed, axis positions), configuration and limits behind the
//! unlock code, commands, and the model staging area.
//!
//! Commands and result codes are enums ([`Command`], [`ResultCode`]); the
//! register holds their number. `CMD_*` and [`result`]'s constants are the
//! same numbers as plain register words, for code that writes or matches
//! raw words (a master's requests, tests).

use thermocomp_core::image::MAX_SIGNED_BYTES;
use thermocomp_core::ImageError;

pub const HR_UNLOCK: u16 = 0;
pub const HR_COMMAND: u16 = 1;
pub const HR_RESULT: u16 = 2;
pub const HR_UNIT: u16 = 3;
pub const HR_BAUD: u16 = 4;
pub const HR_SPINDLE: u16 = 5;
/// Axis positions, int32 µm (or 0.001°), high word first, 2 registers each.
pub const HR_POSITIONS: u16 = 6;
/// Per-direction clamp override, 0.1 µm (0xFFFF: none, the image's limit).
pub const HR_CLAMP: u16 = 20;
/// Per-direction rate-limit override, 0.1 µm/s (0xFFFF: none).
pub const HR_RATE: u16 = 26;
/// Length in bytes of the staged model image.
pub const HR_STAGED_LEN: u16 = 32;
/// Tool length for the volumetric correction, int32 µm, high word first
/// (written by the PLC like the positions).
pub const HR_TOOL_LENGTH: u16 = 34;
/// Rotary axes A (36–37) and C (38–39) for the five-axis part of the
/// volumetric correction (image section kind 4), int32 0.001°, high word
/// first, written by the PLC like the positions (no unlock; broadcast allowed).
pub const HR_ROTARY: u16 = 36;
/// Registers of the rotary block (A and C, two each).
pub const ROTARY_REGS: u16 = 4;
/// Probe references (issue 28; unlock; stored with the settings): the
/// model direction the probe measures at the gauge (0–5; 0xFFFF: none).
pub const HR_PROBE_DIRECTION: u16 = 40;
/// Probe ADC samples averaged for one reference (1–1024).
pub const HR_REFERENCE_SAMPLES: u16 = 41;
/// Bus channel of the DS18B20 beside the probe (0–19; 0xFFFF: none).
pub const HR_PROBE_TEMP_CHANNEL: u16 = 42;
/// The probe's own temperature drift, int16 nm/K (0.001 µm/K), removed
/// from a reading before it is used: reading − k·(T − 20 °C).
pub const HR_PROBE_DRIFT: u16 = 43;
/// Probe reading at the gauge with the machine at its reference state,
/// int32 0.1 µm, high word first (44–45): a reference uses reading − this.
pub const HR_GAUGE_ZERO: u16 = 44;
/// Defaults of the probe-reference registers.
pub const DEFAULT_PROBE_DIRECTION: u16 = REGISTER_NONE;
pub const DEFAULT_REFERENCE_SAMPLES: u16 = 256;
/// "None" for holding registers 40 and 42.
pub const REGISTER_NONE: u16 = 0xFFFF;
/// When the board asks for a probe reference (issue 51; unlock; stored
/// with the settings; 0 switches a part off, all three 0: the board never
/// asks, as before these registers existed): ask this many seconds after a
/// spindle-speed change (46), when this many seconds have passed since the
/// last accepted reference (47); a speed change is a move of at least this
/// many rpm of holding register 5 (48). Input register 23 says what is
/// wanted (`thermocomp_core::ask`).
pub const HR_ASK_SETTLE: u16 = 46;
pub const HR_ASK_INTERVAL: u16 = 47;
pub const HR_ASK_SPEED_STEP: u16 = 48;
/// Last register of the plain block (33 and 49 reserved, read 0).
pub const HR_LAST_PLAIN: u16 = 49;
/// Model staging area: 2 bytes per register (first byte in the high half).
/// It holds the largest image and its signature trailer
/// (`thermocomp_core::image::signed`).
pub const HR_STAGING: u16 = 1000;
// The staging area must fit the address space above HR_STAGING.
const _: () = assert!(MAX_SIGNED_BYTES / 2 <= (u16::MAX - HR_STAGING) as usize);
const _: () = assert!(MAX_SIGNED_BYTES.is_multiple_of(2));
#[allow(clippy::cast_possible_truncation)] // checked by the assertion above
pub const STAGING_REGS: u16 = (MAX_SIGNED_BYTES / 2) as u16;

// --- Keys (issue 30: signed models, per-board unlock key), registers 50–89.
/// The model-signing public key (Ed25519, 32 bytes, 16 registers, first
/// byte in the high half): written before [`CMD_STORE_SIGNING_KEY`] or
/// [`CMD_REPLACE_SIGNING_KEY`] (unlock); reads back what was written, or
/// the stored key after a boot (all zero: none). A public key is no secret.
pub const HR_SIGNING_KEY: u16 = 50;
/// Registers of the signing key.
pub const SIGNING_KEY_REGS: u16 = 16;
/// Key state (read only): see the `KEY_STATE_*` bits.
pub const HR_KEY_STATE: u16 = 66;
/// Bit of HR_KEY_STATE: the board has its own unlock key (commissioned).
pub const KEY_STATE_UNLOCK_KEY: u16 = 1 << 0;
/// Bit of HR_KEY_STATE: a signing key is stored: only signed models commit.
pub const KEY_STATE_SIGNING_KEY: u16 = 1 << 1;
/// Bit of HR_KEY_STATE: unlocked with the factory code (commissioning
/// only: HR_NEW_UNLOCK_KEY, commands 15 and 4).
pub const KEY_STATE_COMMISSIONING: u16 = 1 << 2;
/// The board's new unlock key, written before [`CMD_SET_UNLOCK_KEY`]
/// (unlock); always reads 0: the board never shows a key.
pub const HR_NEW_UNLOCK_KEY: u16 = 67;
/// Last register of the key block (68–89 reserved, read 0).
pub const HR_LAST_KEYS: u16 = 89;

// --- The probe-reference rule's parameters (issue 51 item 5), registers 90–99.
/// The parameters of the probe-reference rule
/// (`thermocomp_core::reference::ReferenceParams`, one register per field
/// in its order, in the units of [`rule::UNIT`]; unlock; stored):
/// σ_r, σ_b (0.01 µm), τ_b (min), σ_s (0.01 µm/h), τ_s (min), gate k (0.1),
/// gate |ν| (0.01 µm), largest step (0.01 µm), bias bound (0.01 µm), rate
/// bound (0.01 µm/h). [`rule::DEFAULT`] written: the firmware's default;
/// a read gives the value in force.
pub const HR_RULE: u16 = 90;
/// Registers of the rule block.
#[allow(clippy::cast_possible_truncation, reason = "10 parameters")]
pub const RULE_REGS: u16 = rule::N as u16;
/// Last register below the staging area.
pub const HR_LAST_RULE: u16 = HR_RULE + RULE_REGS - 1;

/// The probe-reference rule's registers (90–99) and the core's parameters.
pub mod rule {
    use thermocomp_core::reference::{ReferenceParams, MAX_SIGMA_NM, MAX_TAU_S, MAX_TERM_NM};

    /// Parameters (registers), in `ReferenceParams`' field order.
    pub const N: usize = 10;
    /// Written to a register: the firmware's default for that parameter.
    pub const DEFAULT: u16 = 0xFFFF;
    /// One register unit in the core's unit: nm (σ_r, σ_b, gate, step,
    /// bias bound), nm/h (σ_s, rate bound), s (τ_b, τ_s), tenths (gate k).
    pub const UNIT: [u32; N] = [10, 10, 60, 10, 60, 1, 10, 10, 10, 10];
    /// Smallest value a register takes (a time constant of 0 is refused).
    pub const MIN: [u16; N] = [0, 0, 1, 0, 1, 0, 0, 0, 0, 0];
    /// Largest value a register takes (gate k: 6000, as `tcomp replay
    /// --reference-param gate_k` allows); beyond, exception 03.
    pub const MAX: [u16; N] = [
        65534, 65534, 65534, 65534, 65534, 60000, 65534, 65534, 65534, 65534,
    ];

    /// The core's fields as numbers, in register order.
    pub const fn fields(p: &ReferenceParams) -> [u32; N] {
        [
            p.sigma_ref_nm,
            p.sigma_bias_nm,
            p.tau_bias_s,
            p.sigma_rate_nm_h,
            p.tau_rate_s,
            p.gate_k_x10 as u32,
            p.gate_abs_nm,
            p.max_step_nm,
            p.max_bias_nm,
            p.max_rate_nm_h,
        ]
    }

    /// The registers' values of the firmware's defaults.
    #[allow(
        clippy::cast_possible_truncation,
        clippy::indexing_slicing,
        reason = "checked below; const evaluation: an index out of range fails the build"
    )]
    pub const DEFAULTS: [u16; N] = {
        let f = fields(&ReferenceParams::DEFAULT);
        let mut out = [0u16; N];
        let mut i = 0;
        while i < N {
            // Each default is a whole number of register units, in range.
            assert!(f[i].is_multiple_of(UNIT[i]) && f[i] / UNIT[i] <= MAX[i] as u32);
            assert!(f[i] / UNIT[i] >= MIN[i] as u32);
            out[i] = (f[i] / UNIT[i]) as u16;
            i += 1;
        }
        out
    };

    // Every value a register takes is inside the core's own bounds
    // (`ReferenceParams::sanitised` changes nothing): no silent clamping.
    #[allow(
        clippy::indexing_slicing,
        reason = "const evaluation: an index out of range fails the build"
    )]
    const _: () = {
        let top = fields(&ReferenceParams {
            sigma_ref_nm: MAX_SIGMA_NM,
            sigma_bias_nm: MAX_SIGMA_NM,
            tau_bias_s: MAX_TAU_S,
            sigma_rate_nm_h: MAX_SIGMA_NM,
            tau_rate_s: MAX_TAU_S,
            gate_k_x10: u16::MAX,
            gate_abs_nm: MAX_TERM_NM as u32,
            max_step_nm: MAX_TERM_NM as u32,
            max_bias_nm: MAX_TERM_NM as u32,
            max_rate_nm_h: MAX_TERM_NM as u32,
        });
        let mut i = 0;
        while i < N {
            // The core's lower bound: 1 s for the time constants, else 0.
            let low = if i == 2 || i == 4 { 1 } else { 0 };
            assert!(MAX[i] as u32 * UNIT[i] <= top[i] && MIN[i] as u32 * UNIT[i] >= low);
            i += 1;
        }
    };

    /// Whether register `i` of the block takes `v`.
    pub fn valid(i: usize, v: u16) -> bool {
        v == DEFAULT
            || matches!((MIN.get(i), MAX.get(i)), (Some(&lo), Some(&hi)) if lo <= v && v <= hi)
    }

    /// Register `i`'s value in force (what a read gives): the value
    /// written, or the default's for [`DEFAULT`] (or a value out of range).
    pub fn in_force(regs: &[u16; N], i: usize) -> u16 {
        match regs.get(i) {
            Some(&v) if v != DEFAULT && valid(i, v) => v,
            _ => DEFAULTS.get(i).copied().unwrap_or(0),
        }
    }

    /// The core's parameters from the registers as written.
    pub fn decode(regs: &[u16; N]) -> ReferenceParams {
        let f: [u32; N] = core::array::from_fn(|i| {
            u32::from(in_force(regs, i)) * UNIT.get(i).copied().unwrap_or(1)
        });
        let [sigma_ref_nm, sigma_bias_nm, tau_bias_s, sigma_rate_nm_h, tau_rate_s, k, gate_abs_nm, max_step_nm, max_bias_nm, max_rate_nm_h] =
            f;
        ReferenceParams {
            sigma_ref_nm,
            sigma_bias_nm,
            tau_bias_s,
            sigma_rate_nm_h,
            tau_rate_s,
            gate_k_x10: u16::try_from(k).unwrap_or(u16::MAX),
            gate_abs_nm,
            max_step_nm,
            max_bias_nm,
            max_rate_nm_h,
        }
    }
}

/// The factory unlock code: on a board without its own unlock key it opens
/// commissioning (setting that key) and nothing else; once the board has
/// its key it opens nothing (docs/register-map.md, "Keys and commissioning").
pub const FACTORY_UNLOCK_CODE: u16 = 0xA5C3;
/// An unlock (the board's own key in HR_UNLOCK) allows configuration and
/// model writes for this long.
pub const UNLOCK_MS: u64 = 60_000;
/// After a refused unlock, every unlock is refused for this long (a 16-bit
/// key then takes 9 h on average to guess over the bus, 18 h at most).
pub const UNLOCK_HOLDOFF_MS: u64 = 1_000;

/// Baud rates the board accepts (HR_BAUD holds baud / 100).
pub const BAUD_RATES: [u32; 6] = [9_600, 19_200, 38_400, 57_600, 115_200, 230_400];

/// A `#[repr(u16)]` enum of wire codes, its conversions, and each code as
/// a plain `u16` constant (one list, so the two cannot drift apart).
macro_rules! wire_codes {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $code:literal => $konst:ident, )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        #[repr(u16)]
        pub enum $name {
            $( $(#[$vmeta])* $variant = $code, )*
        }

        impl $name {
            /// The number the register holds.
            pub const fn code(self) -> u16 {
                self as u16
            }

            /// The code with this number, `None` for a number the map does not define.
            pub const fn from_u16(code: u16) -> Option<Self> {
                match code {
                    $( $code => Some($name::$variant), )*
                    _ => None,
                }
            }

            /// The code's name as docs/register-map.md spells it.
            pub const fn name(self) -> &'static str {
                match self {
                    $( $name::$variant => stringify!($konst), )*
                }
            }
        }

        $( $(#[$vmeta])* pub const $konst: u16 = $code; )*
    };
}

wire_codes! {
    /// Commands (written to HR_COMMAND, alone: FC06 or a one-register FC16).
    pub enum Command {
        CommitModel = 1 => CMD_COMMIT_MODEL,
        Rereference = 2 => CMD_REREFERENCE,
        ClearStaging = 3 => CMD_CLEAR_STAGING,
        Lock = 4 => CMD_LOCK,
        /// Commit the staged model even when its version is not newer than the
        /// running one (going back to an older model on purpose); every other check
        /// of [`CMD_COMMIT_MODEL`] still applies.
        RollbackModel = 5 => CMD_ROLLBACK_MODEL,
        /// Forget the fault record (input registers 160–168, status bit 9).
        ClearFault = 6 => CMD_CLEAR_FAULT,
        /// Restore the default settings (unit 1, 115200 baud, no clamp or rate
        /// override, no fixed reference) and store them; link changes apply after the reply.
        RestoreDefaults = 7 => CMD_RESTORE_DEFAULTS,
        /// Test builds only (feature `test-faults`, the QEMU bench board): panic
        /// after the reply, to show the fault path end to end.
        TestPanic = 8 => CMD_TEST_PANIC,
        /// Test builds only (feature `test-faults`): the measurement loop stops
        /// making progress, so the watchdog must trip.
        TestStall = 9 => CMD_TEST_STALL,
        /// Keep a reference sample across reboots (a machine with a fixed
        /// reference): the next cycle at which every model sensor reads fresh is
        /// the new reference sample (per channel), used from then on and at every
        /// boot, and stored with the settings (HR_RESULT 50, then 23, then 0 or 22).
        /// While a reference is kept (or the image has a fixed reference),
        /// [`CMD_REREFERENCE`] does the same.
        KeepReference = 10 => CMD_KEEP_REFERENCE,
        /// Forget the kept reference (stored); the reference in use stays until
        /// the next boot or command 2.
        ForgetReference = 11 => CMD_FORGET_REFERENCE,
        /// Take a probe reference now (the spindle sits at the gauge): after
        /// the next cycle the probe is averaged over holding register 41's
        /// samples and compared with the model for the direction of register
        /// 40 (`thermocomp_core::reference`); HR_RESULT 60 until taken, then
        /// 23 (stored) and 0 (accepted) or 61 (refused: counted, nothing else
        /// changed), or 62–64 (not taken).
        TakeProbeReference = 12 => CMD_TAKE_PROBE_REFERENCE,
        /// Reset the learned reference terms and re-zero offsets of every
        /// direction (stored; a new model does the same).
        ResetReferenceTerms = 13 => CMD_RESET_REFERENCE_TERMS,
        /// Store the signing public key written to HR_SIGNING_KEY; from then
        /// on only models signed with its private key commit. Refused (result
        /// 72) when a key is stored: a stored key is replaced only by
        /// [`CMD_REPLACE_SIGNING_KEY`].
        StoreSigningKey = 14 => CMD_STORE_SIGNING_KEY,
        /// Set the board's own unlock key from HR_NEW_UNLOCK_KEY (stored; the
        /// board locks: unlock again with the new key). The only command a
        /// board unlocked with the factory code takes.
        SetUnlockKey = 15 => CMD_SET_UNLOCK_KEY,
        /// Replace the stored signing key by the one in HR_SIGNING_KEY: the
        /// staging area holds (staged length 64) a signature by the stored
        /// key over "thermocomp signing key v1" followed by the new key.
        ReplaceSigningKey = 16 => CMD_REPLACE_SIGNING_KEY,
    }
}

impl Command {
    /// Commands only a `test-faults` build accepts.
    pub const fn test_only(self) -> bool {
        matches!(self, Command::TestPanic | Command::TestStall)
    }
}

pub use result::ResultCode;

/// Command results (HR_RESULT): one code per reason a commit is refused.
pub mod result {
    use super::ImageError;

    wire_codes! {
        /// What HR_RESULT says about the last command or commit.
        pub enum ResultCode {
            Ok = 0 => OK,
            None = 1 => NONE,
            /// Staged length outside 1..=MAX_IMAGE_BYTES.
            BadLength = 2 => BAD_LENGTH,
            /// The image's CRC-32 does not match (corrupted in transfer).
            BadCrc = 3 => BAD_CRC,
            /// Writing the model to flash failed; the previous model still serves.
            StoreFailed = 4 => STORE_FAILED,
            /// Shorter than its header or than its own total length.
            TooShort = 5 => TOO_SHORT,
            /// Total length above the staging area.
            TooLong = 6 => TOO_LONG,
            /// Not a model image (magic).
            BadMagic = 7 => BAD_MAGIC,
            /// Image format version this firmware does not read.
            UnsupportedFormat = 8 => UNSUPPORTED_FORMAT,
            /// Units code this firmware does not read.
            UnsupportedUnits = 9 => UNSUPPORTED_UNITS,
            /// A count above its fixed maximum (sensors, inputs, nets, terms …).
            TooMany = 10 => TOO_MANY,
            /// A reference to a sensor, input, direction or axis that does not exist.
            BadIndex = 11 => BAD_INDEX,
            /// An envelope or axis range whose minimum is not below its maximum.
            BadRange = 12 => BAD_RANGE,
            /// Another field outside its domain (flags, step, lag, power …).
            BadValue = 13 => BAD_VALUE,
            /// The sections do not fill the image's length exactly.
            LengthMismatch = 14 => LENGTH_MISMATCH,
            /// Bytes after the sealed image (staged length longer than the image).
            TrailingBytes = 15 => TRAILING_BYTES,
            /// A sensor channel the board does not have.
            SensorChannel = 16 => SENSOR_CHANNEL,
            /// Model version 0.
            ZeroModelVersion = 17 => ZERO_MODEL_VERSION,
            /// A direction's max correction outside 1..=MAX_CORRECTION.
            MaxCorrection = 18 => MAX_CORRECTION,
            /// A direction's max rate outside 1..=MAX_RATE (0 would freeze the correction).
            MaxRate = 19 => MAX_RATE,
            /// Table coefficients whose sums could overflow the evaluation.
            TableSumTooLarge = 20 => TABLE_SUM_TOO_LARGE,
            /// Version not newer than the running model's (CMD_ROLLBACK_MODEL commits it).
            NotNewer = 21 => NOT_NEWER,
            /// A settings change (unit, baud, clamp, rate, command 7) is in force
            /// but could not be stored in flash: it is lost at the next reboot.
            SettingsNotStored = 22 => SETTINGS_NOT_STORED,
            /// A commit (model or settings) is being written to flash in the
            /// background; poll until another code (0 OK, 4, 22).
            CommitInProgress = 23 => COMMIT_IN_PROGRESS,
            /// An image section (format v2) of a kind this firmware does not read.
            UnknownSection = 30 => UNKNOWN_SECTION,
            /// An image section whose contents do not match its declared length.
            SectionLength = 31 => SECTION_LENGTH,
            /// The same image section kind twice.
            DuplicateSection = 32 => DUPLICATE_SECTION,
            /// A fallback model reads a sensor it is meant to do without.
            FallbackUsesExcluded = 33 => FALLBACK_USES_EXCLUDED,
            /// Volumetric section: a position slot, stroke or tool-length scale out of range.
            VolumetricRange = 40 => VOLUMETRIC_RANGE,
            /// Volumetric section: a sensor's reference or envelope outside −55 … 125 °C.
            VolumetricTemperature = 41 => VOLUMETRIC_TEMPERATURE,
            /// Volumetric section: a max correction outside 1..=MAX_CORRECTION.
            VolumetricMaxCorrection = 42 => VOLUMETRIC_MAX_CORRECTION,
            /// Five-axis section (kind 4) without a volumetric section (kind 3).
            FiveAxisNoVolumetric = 80 => FIVE_AXIS_NO_VOLUMETRIC,
            /// Five-axis section: more temperature columns than the volumetric section has sensors.
            FiveAxisSensors = 81 => FIVE_AXIS_SENSORS,
            /// Five-axis section: a Fourier order above 4.
            FiveAxisOrder = 82 => FIVE_AXIS_ORDER,
            /// Five-axis section: pivot or offset beyond ±2^27 µm, or the
            /// volumetric section's positions beyond ±2^28 µm.
            FiveAxisGeometry = 83 => FIVE_AXIS_GEOMETRY,
            /// Five-axis section: an A or C range not increasing or beyond ±720°.
            FiveAxisAngleRange = 84 => FIVE_AXIS_ANGLE_RANGE,
            /// Five-axis section: a max correction outside 1..=MAX_CORRECTION.
            FiveAxisMaxCorrection = 85 => FIVE_AXIS_MAX_CORRECTION,
            /// Five-axis section: an error that can exceed 1 mm / 1 mrad.
            FiveAxisErrorTooLarge = 86 => FIVE_AXIS_ERROR_TOO_LARGE,
            /// Five-axis section: flag bits this firmware does not read.
            FiveAxisFlags = 87 => FIVE_AXIS_FLAGS,
            /// Command 10 (or 2 with a kept reference) accepted: the reference is
            /// taken at the next cycle with every model sensor fresh, then stored.
            ReferencePending = 50 => REFERENCE_PENDING,
            /// The image names a sensor by a ROM code that fails its CRC-8.
            SensorRom = 51 => SENSOR_ROM,
            /// The image names two sensors by the same ROM code.
            DuplicateSensorRom = 52 => DUPLICATE_SENSOR_ROM,
            /// Command 12 accepted: the probe reference is taken after the next cycle.
            ProbeReferencePending = 60 => PROBE_REFERENCE_PENDING,
            /// The probe reference disagreed with the model beyond the gate
            /// (a chip on the gauge, the probe out of place): refused and
            /// counted (input register 305), nothing else changed.
            ReferenceRefused = 61 => REFERENCE_REFUSED,
            /// No probe reference taken: the probe's reading is not OK (none,
            /// out of range, saturated, ADC error).
            ProbeNotReady = 62 => PROBE_NOT_READY,
            /// No probe reference taken: no model, or holding register 40
            /// names no direction of it.
            NoProbeDirection = 63 => NO_PROBE_DIRECTION,
            /// No probe reference taken: holding register 42 names a channel
            /// without a fresh reading.
            ProbeTemperatureMissing = 64 => PROBE_TEMPERATURE_MISSING,
            /// A signing key is stored and the staged image carries no signature.
            Unsigned = 70 => UNSIGNED,
            /// The staged image's signature is not one by the stored signing key
            /// (or its trailer is malformed); for command 16, the replacement's.
            BadSignature = 71 => BAD_SIGNATURE,
            /// Command 14 while a signing key is stored (command 16 replaces it).
            SigningKeySet = 72 => SIGNING_KEY_SET,
            /// Command 14 or 16: HR_SIGNING_KEY is not an Ed25519 public key;
            /// command 15: the new unlock key is 0 or the factory code.
            BadKey = 73 => BAD_KEY,
            /// A direction (or fallback) can predict beyond ±10 mm over the
            /// image's own input envelope (bounded analytically).
            PredictionBound = 74 => PREDICTION_BOUND,
            /// A network weight or bias beyond what the quantizer produces (±256.0).
            CoefficientRange = 75 => COEFFICIENT_RANGE,
            /// A warm-up longer than 24 h.
            WarmupTooLong = 76 => WARMUP_TOO_LONG,
            /// A lag time constant of 0 or longer than 7 days.
            LagTooLong = 77 => LAG_TOO_LONG,
        }
    }

    impl ResultCode {
        /// The result code of an image refusal.
        pub fn of_image_error(e: &ImageError) -> ResultCode {
            match e {
                ImageError::TooShort { .. } => ResultCode::TooShort,
                ImageError::TooLong { .. } => ResultCode::TooLong,
                ImageError::BadMagic => ResultCode::BadMagic,
                ImageError::UnsupportedVersion(_) => ResultCode::UnsupportedFormat,
                ImageError::UnsupportedUnits(_) => ResultCode::UnsupportedUnits,
                ImageError::BadCrc { .. } => ResultCode::BadCrc,
                ImageError::TooMany { .. } => ResultCode::TooMany,
                ImageError::BadIndex { .. } => ResultCode::BadIndex,
                ImageError::NonMonotoneRange { .. } => ResultCode::BadRange,
                ImageError::BadValue { .. } => ResultCode::BadValue,
                ImageError::LengthMismatch => ResultCode::LengthMismatch,
                ImageError::TrailingBytes { .. } => ResultCode::TrailingBytes,
                ImageError::SensorChannelOutOfRange { .. } => ResultCode::SensorChannel,
                ImageError::ZeroModelVersion => ResultCode::ZeroModelVersion,
                ImageError::MaxCorrectionOutOfRange { .. } => ResultCode::MaxCorrection,
                ImageError::MaxRateOutOfRange { .. } => ResultCode::MaxRate,
                ImageError::TableSumTooLarge { .. } => ResultCode::TableSumTooLarge,
                ImageError::UnknownSection { .. } => ResultCode::UnknownSection,
                ImageError::SectionLength { .. } => ResultCode::SectionLength,
                ImageError::DuplicateSection { .. } => ResultCode::DuplicateSection,
                ImageError::FallbackUsesExcluded { .. } => ResultCode::FallbackUsesExcluded,
                ImageError::BadSensorRom { .. } => ResultCode::SensorRom,
                ImageError::DuplicateSensorRom { .. } => ResultCode::DuplicateSensorRom,
                ImageError::VolumetricAxisSlot { .. }
                | ImageError::VolumetricStroke { .. }
                | ImageError::VolumetricTool { .. } => ResultCode::VolumetricRange,
                ImageError::VolumetricTemperature { .. } => ResultCode::VolumetricTemperature,
                ImageError::VolumetricMaxCorrection { .. } => ResultCode::VolumetricMaxCorrection,
                ImageError::FiveAxisWithoutVolumetric => ResultCode::FiveAxisNoVolumetric,
                ImageError::FiveAxisSensors { .. } => ResultCode::FiveAxisSensors,
                ImageError::FiveAxisOrder { .. } => ResultCode::FiveAxisOrder,
                ImageError::FiveAxisGeometry => ResultCode::FiveAxisGeometry,
                ImageError::FiveAxisAngleRange { .. } => ResultCode::FiveAxisAngleRange,
                ImageError::FiveAxisMaxCorrection { .. } => ResultCode::FiveAxisMaxCorrection,
                ImageError::FiveAxisErrorTooLarge { .. } => ResultCode::FiveAxisErrorTooLarge,
                ImageError::FiveAxisFlags { .. } => ResultCode::FiveAxisFlags,
                ImageError::BadSignatureTrailer => ResultCode::BadSignature,
                ImageError::PredictionBound { .. } => ResultCode::PredictionBound,
                ImageError::CoefficientRange { .. } => ResultCode::CoefficientRange,
                ImageError::WarmupTooLong { .. } => ResultCode::WarmupTooLong,
                ImageError::LagTooLong { .. } => ResultCode::LagTooLong,
            }
        }
    }

    /// The name of a result code (as docs/register-map.md spells it), for messages;
    /// "unknown" for a number the map does not define.
    pub fn name(code: u16) -> &'static str {
        ResultCode::from_u16(code).map_or("unknown", ResultCode::name)
    }

    /// The result code of an image refusal, as the register holds it.
    pub fn of_image_error(e: &ImageError) -> u16 {
        ResultCode::of_image_error(e).code()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_keep_their_numbers() {
        for v in 0..=u16::from(u8::MAX) {
            if let Some(c) = Command::from_u16(v) {
                assert_eq!(c.code(), v);
            }
            if let Some(r) = ResultCode::from_u16(v) {
                assert_eq!(r.code(), v);
                assert_eq!(result::name(v), r.name());
            }
        }
        assert_eq!(Command::from_u16(0), None);
        assert_eq!(Command::from_u16(12), Some(Command::TakeProbeReference));
        assert_eq!(Command::from_u16(17), None);
        assert_eq!(ResultCode::ReferenceRefused.code(), 61);
        assert_eq!(Command::ReplaceSigningKey.code(), 16);
        assert_eq!(Command::KeepReference.code(), CMD_KEEP_REFERENCE);
        assert_eq!(ResultCode::CommitInProgress.code(), 23);
        assert_eq!(
            ResultCode::DuplicateSensorRom.name(),
            "DUPLICATE_SENSOR_ROM"
        );
        assert_eq!(result::name(24), "unknown");
        assert_eq!(
            result::of_image_error(&ImageError::BadMagic),
            result::BAD_MAGIC
        );
    }

    #[test]
    fn rule_registers_round_trip_and_stay_inside_the_core_bounds() {
        use thermocomp_core::reference::ReferenceParams;
        let defaults = [rule::DEFAULT; rule::N];
        assert_eq!(rule::decode(&defaults), ReferenceParams::DEFAULT);
        assert_eq!(
            rule::DEFAULTS,
            [30, 300, 240, 200, 120, 40, 3000, 2000, 5000, 2000]
        );
        let set = [50, 250, 90, 0, 30, 35, 0, 1500, 4000, 65534];
        let p = rule::decode(&set);
        assert_eq!(
            p,
            ReferenceParams {
                sigma_ref_nm: 500,
                sigma_bias_nm: 2_500,
                tau_bias_s: 5_400,
                sigma_rate_nm_h: 0,
                tau_rate_s: 1_800,
                gate_k_x10: 35,
                gate_abs_nm: 0,
                max_step_nm: 15_000,
                max_bias_nm: 40_000,
                max_rate_nm_h: 655_340,
            }
        );
        for (i, (&v, &d)) in set.iter().zip(&rule::DEFAULTS).enumerate() {
            assert_eq!(rule::in_force(&set, i), v);
            assert_eq!(rule::in_force(&defaults, i), d);
        }
        // The extremes a register takes are what the core uses, unclamped.
        for regs in [rule::MIN, rule::MAX] {
            assert!(regs.iter().enumerate().all(|(i, &v)| rule::valid(i, v)));
            assert_eq!(rule::decode(&regs).sanitised(), rule::decode(&regs));
        }
        assert!(
            !rule::valid(2, 0) && !rule::valid(4, 0),
            "a time constant of 0"
        );
        assert!(!rule::valid(5, 60_001) && rule::valid(5, rule::DEFAULT));
        assert!(!rule::valid(rule::N, 1));
    }
}

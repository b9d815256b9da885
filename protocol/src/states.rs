//! State codes as the registers carry them: per temperature channel (input
//! registers 130–149) and of the probe (input register 22).

/// Why a channel's value can or cannot be used. A named state per channel, not
/// a number: the register map exposes [`ChannelState::code`], the logs the name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ChannelState {
    /// No sensor mapped to this channel.
    Unused,
    /// Not read yet since boot.
    Pending,
    /// Last reading good.
    Ok,
    /// No presence pulse after reset: bus open or no device.
    NoPresence,
    /// Scratchpad CRC-8 mismatch.
    CrcError,
    /// Nine zero bytes (they pass the CRC; a shorted or stuck-low line).
    AllZero,
    /// 85.0 °C power-on value: the conversion did not run (power glitch).
    PowerOnValue,
    /// All ones (0xFF...): the device stopped answering mid-read.
    Disconnected,
    /// Outside the configured plausible range.
    OutOfRange,
    /// A step between two readings no real machine can make.
    ImplausibleStep,
    /// Identical raw value for longer than the configured stuck time while
    /// other channels moved.
    Stuck,
    /// The scratchpad's configuration (resolution, reset marker) was back at
    /// its power-up contents or changed: the sensor was reset (brownout,
    /// reconnection). Rewritten; the reading of that cycle is not used.
    ConfigLost,
    /// The sensor was off the bus (no presence, all ones) in this cycle or
    /// its previous one: it may have missed the Convert T and hold an old
    /// conversion, so a reading that passes every check is still not used.
    Intermittent,
}

impl ChannelState {
    /// Stable numeric code for the register map (documented in docs/register-map.md).
    pub const fn code(self) -> u16 {
        match self {
            ChannelState::Unused => 0,
            ChannelState::Pending => 1,
            ChannelState::Ok => 2,
            ChannelState::NoPresence => 3,
            ChannelState::CrcError => 4,
            ChannelState::AllZero => 5,
            ChannelState::PowerOnValue => 6,
            ChannelState::Disconnected => 7,
            ChannelState::OutOfRange => 8,
            ChannelState::ImplausibleStep => 9,
            ChannelState::Stuck => 10,
            ChannelState::ConfigLost => 11,
            ChannelState::Intermittent => 12,
        }
    }

    /// True for states that mean the value is a fault (not merely absent).
    pub const fn is_fault(self) -> bool {
        !matches!(
            self,
            ChannelState::Unused | ChannelState::Pending | ChannelState::Ok
        )
    }
}

/// The probe's state, a named value like the temperature channels'.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ProbeState {
    /// Reading good.
    Ok,
    /// At least one sample at the ADC's rail: target out of the probe's
    /// range or probe disconnected.
    Saturated,
    /// Calibrated value outside the configured measuring range.
    OutOfRange,
    /// Calibrated value does not fit i32 (bad calibration).
    CalibrationOverflow,
    /// Oversample count outside 1..=MAX_OVERSAMPLE.
    BadConfig,
    /// The ADC failed.
    AdcError,
}

impl ProbeState {
    /// Stable code for the register map.
    pub const fn code(self) -> u16 {
        match self {
            ProbeState::Ok => 2,
            ProbeState::Saturated => 11,
            ProbeState::OutOfRange => 8,
            ProbeState::CalibrationOverflow => 12,
            ProbeState::BadConfig => 13,
            ProbeState::AdcError => 14,
        }
    }
}

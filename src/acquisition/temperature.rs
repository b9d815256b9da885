//! The temperature acquisition cycle and the per-channel fault logic.
//!
//! One [`TemperatureAcquisition::cycle`]:
//! 1. reset + Skip ROM + Convert T: every sensor converts at once;
//! 2. the conversion is awaited on an async delay (the executor keeps
//!    running): externally powered sensors are polled with read slots
//!    (a DS18B20 answers 0 while converting) every `poll_ms`; parasite-powered
//!    sensors get the strong pull-up for the datasheet conversion time;
//! 3. per mapped channel: reset + Match ROM + Read Scratchpad (9 bytes),
//!    decoded by [`super::ds18b20::decode`]; CRC, all-zero and disconnected
//!    reads are retried up to `read_retries` times;
//! 4. plausibility: range, step against the last good value (scaled by the
//!    time since), stuck value while other channels move.
//!
//! A faulty channel keeps its last good value for `hold_ms`
//! ([`Validity::Held`]), then is [`Validity::Invalid`] and compensation must
//! not use it. A good reading recovers the channel at once; a step rejected as
//! implausible is accepted when `step_confirm` consecutive readings agree with
//! it (a real jump after a long outage is not rejected forever).
//!
//! # 85.0 °C: power-on value or temperature
//! The temperature register powers up at 85.0 °C, a temperature a machine
//! tool can reach. A power-on reset also reloads TH, TL and the configuration
//! from EEPROM, so [`TemperatureAcquisition::configure`] writes a marker into
//! the (unused) alarm bytes ([`MARKER_TH`], [`MARKER_TL`], never copied to
//! EEPROM) with the resolution. A scratchpad without the marker or with
//! another resolution comes from a sensor that was reset (brownout,
//! reconnection) or never configured: its configuration is rewritten at once
//! (Match ROM + Write Scratchpad) and its reading is not used that cycle
//! (85.0 °C: [`ChannelState::PowerOnValue`]; other values:
//! [`ChannelState::ConfigLost`], or `Pending` for a sensor never configured).
//! With the marker intact, 85.0 °C is the power-on value only on the first
//! reading after the configuration was written (a Convert T the sensor missed
//! while still busy); from the second conversion on it is a temperature.
//!
//! # Intermittent contact
//! Convert T goes to every sensor at once (Skip ROM; acknowledging it per
//! sensor would cost 20 × 6 ms of Match ROM and break the 1 s cycle), so
//! nothing tells which sensors heard it. A sensor whose data contact was open
//! at that moment keeps its last conversion, however old, with a valid CRC
//! and the marker intact: after an outage of minutes it would serve a
//! minutes-old value. A sensor that was off the bus (no presence or all ones)
//! at any attempt in this cycle or its previous one is therefore
//! [`ChannelState::Intermittent`]: its reading is not used until it has
//! answered a whole cycle before. What remains, a contact that opens exactly
//! at Convert T and at no read, gives the previous cycle's conversion.
//! (A contact that also carries the supply resets the sensor: the marker
//! tells.)

use super::channel_map::ChannelMap;
use super::ds18b20::{self, Resolution, Scratchpad};
use super::rom;
use crate::hal::onewire::{BusError, OneWireBus};
use embedded_hal_async::delay::DelayNs;
use thermocomp_protocol::states::ChannelState;
use thermocomp_protocol::MAX_CHANNELS;

/// How the sensors are powered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PowerMode {
    /// V_DD wired: completion is polled with read slots.
    External,
    /// Parasite power: strong pull-up for the full conversion time.
    Parasite,
}

/// Written to TH and TL with the resolution: a scratchpad still carrying
/// them has not been reset since. Factory EEPROM holds 0x4B, 0x46; the
/// firmware never issues Copy Scratchpad, so EEPROM never holds the marker.
pub const MARKER_TH: u8 = 0x5A;
pub const MARKER_TL: u8 = 0xA5;

/// ROM searches [`TemperatureAcquisition::discover`] makes before it gives
/// up on a bus that answers with noise.
pub const SEARCH_ATTEMPTS: usize = 3;

/// Acquisition parameters. All bounds explicit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AcquisitionConfig {
    pub resolution: Resolution,
    pub power: PowerMode,
    /// Extra read attempts after a CRC/all-zero/disconnected/no-presence read.
    pub read_retries: u8,
    /// Poll period while waiting for the conversion (external power), ms.
    pub poll_ms: u32,
    /// Plausible range, 1/16 °C, inclusive.
    pub min_raw: i16,
    pub max_raw: i16,
    /// Largest step accepted between readings: `max_step_raw` plus
    /// `max_slope_raw_per_min` per minute since the last good value.
    pub max_step_raw: i32,
    pub max_slope_raw_per_min: i32,
    /// Consecutive agreeing readings that confirm a large step.
    pub step_confirm: u8,
    /// A value identical for this long while another channel changed is stuck.
    pub stuck_ms: u64,
    /// How long a faulty channel's last good value may still be used.
    pub hold_ms: u64,
}

impl Default for AcquisitionConfig {
    fn default() -> Self {
        AcquisitionConfig {
            resolution: Resolution::Bits12,
            power: PowerMode::External,
            read_retries: 2,
            poll_ms: 2,
            // −40 °C .. +100 °C: a machine tool's structure never leaves it.
            min_raw: -40 * 16,
            max_raw: 100 * 16,
            // 2 °C + 4 °C/min: coolant shocks stay below it, glitches do not.
            max_step_raw: 32,
            max_slope_raw_per_min: 64,
            step_confirm: 3,
            // The measured FL_THERMAL spindle run (shared/data) holds a sensor
            // constant to 1/16 °C for up to 44 min while others move; 30 min
            // flagged healthy sensors there (host-tests acquisition_replay).
            stuck_ms: 2 * 60 * 60 * 1000,
            hold_ms: 60 * 1000,
        }
    }
}

/// Whether compensation may use a channel's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Validity {
    /// Read good this cycle.
    Fresh,
    /// The channel is faulty; the value is the last good one, younger than
    /// `hold_ms`.
    Held,
    /// No usable value: compensation must mark its output invalid.
    Invalid,
}

/// One channel as seen by compensation and the Modbus server.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelValue {
    pub state: ChannelState,
    pub validity: Validity,
    /// 1/16 °C; meaningful unless `validity` is `Invalid`.
    pub raw: i16,
}

impl ChannelValue {
    /// The value compensation may use.
    pub fn usable(&self) -> Option<i16> {
        match self.validity {
            Validity::Invalid => None,
            _ => Some(self.raw),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Channel {
    state: ChannelState,
    /// Last good value and when it was read.
    good: Option<(i16, u64)>,
    /// When the good value last changed.
    changed_ms: u64,
    /// A rejected step and how many readings agreed with it.
    candidate: Option<(i16, u8)>,
    /// The sensor's scratchpad has carried the marker: a later scratchpad
    /// without it means the sensor was reset.
    marked: bool,
    /// A scratchpad with the marker was read since the configuration was
    /// last written: the register holds conversions, 85.0 °C included.
    confirmed: bool,
    /// The sensor was off the bus (no presence, all ones) at some attempt
    /// in its last cycle.
    absent: bool,
}

const EMPTY: Channel = Channel {
    state: ChannelState::Unused,
    good: None,
    changed_ms: 0,
    candidate: None,
    marked: false,
    confirmed: false,
    absent: false,
};

/// Counters of one cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CycleReport {
    /// Channels read good.
    pub ok: u8,
    /// Channels in a fault state after the cycle.
    pub faulty: u8,
    /// Read attempts beyond the first.
    pub retries: u16,
    /// Time from Convert T to the conversion being reported done, µs
    /// (as measured by the delays awaited).
    pub conversion_wait_us: u32,
    /// The conversion did not report done within 1.25 × t_CONV.
    pub conversion_timeout: bool,
    /// Sensors whose configuration was found lost (reset) and rewritten.
    pub reconfigured: u8,
}

/// The DS18B20 acquisition state of up to [`MAX_CHANNELS`] sensors.
pub struct TemperatureAcquisition {
    config: AcquisitionConfig,
    map: ChannelMap,
    channels: [Channel; MAX_CHANNELS],
}

impl TemperatureAcquisition {
    pub fn new(config: AcquisitionConfig, map: ChannelMap) -> Self {
        let mut s = TemperatureAcquisition {
            config,
            map,
            channels: [EMPTY; MAX_CHANNELS],
        };
        s.set_map(map);
        s
    }

    pub fn config(&self) -> &AcquisitionConfig {
        &self.config
    }

    pub fn map(&self) -> &ChannelMap {
        &self.map
    }

    /// Replaces the channel map; channels whose sensor changed restart Pending.
    pub fn set_map(&mut self, map: ChannelMap) {
        for (c, ch) in self.channels.iter_mut().enumerate() {
            let before = self.map.get(c);
            let after = map.get(c);
            if after.is_none() {
                *ch = EMPTY;
            } else if before != after || ch.state == ChannelState::Unused {
                *ch = Channel {
                    state: ChannelState::Pending,
                    ..EMPTY
                };
            }
        }
        self.map = map;
    }

    /// Searches the bus and maps new sensors to free channels. Returns the
    /// number of sensors found. With more than [`MAX_CHANNELS`] sensors on
    /// the bus the first ones found are still mapped and the result is
    /// `Err(SearchError::TooMany)`; a full map keeps its sensors. A search
    /// broken by noise (a code failing its CRC, devices vanishing mid-search)
    /// is repeated up to [`SEARCH_ATTEMPTS`] times; if it still fails, the
    /// sensors found before the failure (each code CRC-checked) are mapped
    /// and the error returned.
    pub async fn discover<B: OneWireBus>(
        &mut self,
        bus: &mut B,
    ) -> Result<usize, super::rom::SearchError> {
        use rom::SearchError;
        let mut found: heapless::Vec<rom::RomCode, MAX_CHANNELS> = heapless::Vec::new();
        let mut result = Err(SearchError::NoPresence);
        for _ in 0..SEARCH_ATTEMPTS {
            result = rom::search(bus, &mut found).await;
            if !matches!(result, Err(SearchError::Crc | SearchError::NoResponse)) {
                break;
            }
        }
        if matches!(
            result,
            Ok(_) | Err(SearchError::TooMany | SearchError::Crc | SearchError::NoResponse)
        ) {
            let mut map = self.map;
            // Full map: the sensors already mapped keep working.
            let _ = map.assign_new(&found);
            self.set_map(map);
        }
        result
    }

    /// Writes the configured resolution and the reset marker to every
    /// sensor (Skip ROM + Write Scratchpad; the alarms are unused).
    pub async fn configure<B: OneWireBus>(&mut self, bus: &mut B) -> Result<bool, BusError> {
        if !rom::select_all(bus).await? {
            return Ok(false);
        }
        self.write_configuration(bus).await?;
        for ch in self.channels.iter_mut() {
            ch.confirmed = false;
        }
        Ok(true)
    }

    /// Match ROM + Write Scratchpad of one sensor that lost its configuration.
    async fn configure_sensor<B: OneWireBus>(
        &mut self,
        bus: &mut B,
        rom: &rom::RomCode,
    ) -> Result<bool, BusError> {
        if !rom::select(bus, rom).await? {
            return Ok(false);
        }
        self.write_configuration(bus).await?;
        Ok(true)
    }

    async fn write_configuration<B: OneWireBus>(&self, bus: &mut B) -> Result<(), BusError> {
        bus.write_byte(ds18b20::WRITE_SCRATCHPAD).await?;
        bus.write_byte(MARKER_TH).await?;
        bus.write_byte(MARKER_TL).await?;
        bus.write_byte(self.config.resolution.config_byte()).await
    }

    /// One acquisition cycle; `now_ms` is the time of the readings.
    pub async fn cycle<B: OneWireBus, D: DelayNs>(
        &mut self,
        bus: &mut B,
        delay: &mut D,
        now_ms: u64,
    ) -> CycleReport {
        let mut report = CycleReport::default();
        match self.convert_all(bus, delay, &mut report).await {
            Ok(true) => {}
            Ok(false) => {
                self.fail_all(ChannelState::NoPresence, now_ms);
                return self.finish(report);
            }
            Err(_) => {
                // A shorted line reads all zeros.
                self.fail_all(ChannelState::AllZero, now_ms);
                return self.finish(report);
            }
        }
        for channel in 0..MAX_CHANNELS {
            let Some(rom) = self.map.get(channel) else {
                continue;
            };
            let mut result = Err(ChannelState::Pending);
            let mut absent = false;
            for attempt in 0..=self.config.read_retries {
                if attempt > 0 {
                    report.retries = report.retries.saturating_add(1);
                }
                result = read_scratchpad(bus, &rom).await;
                absent |= matches!(
                    result,
                    Err(ChannelState::Disconnected | ChannelState::NoPresence)
                );
                let retry = matches!(
                    result,
                    Err(ChannelState::CrcError
                        | ChannelState::AllZero
                        | ChannelState::Disconnected
                        | ChannelState::NoPresence)
                );
                if !retry {
                    break;
                }
            }
            let (mut value, rewrite) = match result {
                Ok(scratchpad) => self.judge(channel, &scratchpad),
                Err(state) => (Err(state), false),
            };
            if let Some(ch) = self.channels.get_mut(channel) {
                // Off the bus in this cycle or the last: it may have missed
                // a Convert T and still hold an old conversion.
                if value.is_ok() && (absent || ch.absent) {
                    value = Err(ChannelState::Intermittent);
                }
                ch.absent = absent;
            }
            if rewrite && matches!(self.configure_sensor(bus, &rom).await, Ok(true)) {
                report.reconfigured = report.reconfigured.saturating_add(1);
            }
            self.apply(channel, value, now_ms);
        }
        self.finish(report)
    }

    fn finish(&self, mut report: CycleReport) -> CycleReport {
        for ch in &self.channels {
            if ch.state == ChannelState::Ok {
                report.ok += 1;
            } else if ch.state.is_fault() {
                report.faulty += 1;
            }
        }
        report
    }

    async fn convert_all<B: OneWireBus, D: DelayNs>(
        &mut self,
        bus: &mut B,
        delay: &mut D,
        report: &mut CycleReport,
    ) -> Result<bool, BusError> {
        if !rom::select_all(bus).await? {
            return Ok(false);
        }
        let t_conv = self.config.resolution.conversion_time_us();
        match self.config.power {
            PowerMode::Parasite => {
                bus.write_byte_then_strong_pullup(ds18b20::CONVERT_T)
                    .await?;
                delay.delay_us(t_conv).await;
                bus.set_strong_pullup(false).await?;
                report.conversion_wait_us = t_conv;
            }
            PowerMode::External => {
                bus.write_byte(ds18b20::CONVERT_T).await?;
                let poll_us = self.config.poll_ms.clamp(1, 100) * 1000;
                let limit = t_conv + t_conv / 4;
                let mut waited = 0u32;
                loop {
                    delay.delay_us(poll_us).await;
                    waited = waited.saturating_add(poll_us);
                    if bus.read_bit().await? {
                        break;
                    }
                    if waited >= limit {
                        report.conversion_timeout = true;
                        break;
                    }
                }
                report.conversion_wait_us = waited;
            }
        }
        Ok(true)
    }

    /// Tells a CRC-valid scratchpad's temperature from the power-on value and
    /// a reset sensor (module doc). Returns the reading for [`Self::apply`]
    /// and whether the sensor's configuration must be rewritten.
    fn judge(&mut self, channel: usize, sp: &Scratchpad) -> (Result<i16, ChannelState>, bool) {
        let resolution = self.config.resolution;
        let Some(ch) = self.channels.get_mut(channel) else {
            return (Err(ChannelState::Pending), false);
        };
        let intact = sp.th == MARKER_TH && sp.tl == MARKER_TL && sp.resolution == resolution;
        if !intact {
            ch.confirmed = false;
            let state = if sp.reads_power_on_value() {
                ChannelState::PowerOnValue
            } else if ch.marked {
                ChannelState::ConfigLost
            } else {
                ChannelState::Pending
            };
            return (Err(state), true);
        }
        ch.marked = true;
        let first_since_configured = !ch.confirmed;
        ch.confirmed = true;
        if sp.reads_power_on_value() && first_since_configured {
            return (Err(ChannelState::PowerOnValue), false);
        }
        (Ok(sp.raw), false)
    }

    fn fail_all(&mut self, state: ChannelState, now_ms: u64) {
        for c in 0..MAX_CHANNELS {
            if self.map.get(c).is_some() {
                if let Some(ch) = self.channels.get_mut(c) {
                    ch.absent = state == ChannelState::NoPresence;
                }
                self.apply(c, Err(state), now_ms);
            }
        }
    }

    /// Applies one reading (or its fault) to a channel.
    fn apply(&mut self, channel: usize, result: Result<i16, ChannelState>, now_ms: u64) {
        let cfg = self.config;
        // "Other channels moved": one changed after this one last did.
        let mine = self.channels.get(channel).map_or(0, |c| c.changed_ms);
        let others_moved = self
            .channels
            .iter()
            .enumerate()
            .any(|(c, ch)| c != channel && ch.good.is_some() && ch.changed_ms > mine);
        let Some(ch) = self.channels.get_mut(channel) else {
            return;
        };
        let raw = match result {
            Err(state) => {
                ch.state = state;
                return;
            }
            Ok(raw) => raw,
        };
        if raw < cfg.min_raw || raw > cfg.max_raw {
            ch.state = ChannelState::OutOfRange;
            return;
        }
        if let Some((last, at)) = ch.good {
            let dt_ms = now_ms.saturating_sub(at);
            // dt is capped at ~12 days: the allowance saturates, never wraps.
            let dt = i64::try_from(dt_ms.min(1 << 30)).unwrap_or(1 << 30);
            let allowed = i64::from(cfg.max_step_raw)
                .saturating_add(i64::from(cfg.max_slope_raw_per_min).saturating_mul(dt) / 60_000);
            let step = (i64::from(raw) - i64::from(last)).abs();
            if step > allowed {
                let agreeing = match ch.candidate {
                    Some((c, n))
                        if (i64::from(c) - i64::from(raw)).abs() <= i64::from(cfg.max_step_raw) =>
                    {
                        n.saturating_add(1)
                    }
                    _ => 1,
                };
                if agreeing < cfg.step_confirm {
                    ch.candidate = Some((raw, agreeing));
                    ch.state = ChannelState::ImplausibleStep;
                    return;
                }
            }
            if raw == last {
                if now_ms.saturating_sub(ch.changed_ms) >= cfg.stuck_ms && others_moved {
                    ch.state = ChannelState::Stuck;
                    return;
                }
            } else {
                ch.changed_ms = now_ms;
            }
        } else {
            ch.changed_ms = now_ms;
        }
        ch.candidate = None;
        ch.good = Some((raw, now_ms));
        ch.state = ChannelState::Ok;
    }

    /// The state of a channel.
    pub fn state(&self, channel: usize) -> ChannelState {
        self.channels
            .get(channel)
            .map_or(ChannelState::Unused, |c| c.state)
    }

    /// What compensation may use of `channel` at `now_ms`.
    pub fn value(&self, channel: usize, now_ms: u64) -> ChannelValue {
        let Some(ch) = self.channels.get(channel) else {
            return ChannelValue {
                state: ChannelState::Unused,
                validity: Validity::Invalid,
                raw: 0,
            };
        };
        let (validity, raw) = match (ch.state, ch.good) {
            (ChannelState::Ok, Some((raw, _))) => (Validity::Fresh, raw),
            (s, Some((raw, at)))
                if s.is_fault() && now_ms.saturating_sub(at) <= self.config.hold_ms =>
            {
                (Validity::Held, raw)
            }
            _ => (Validity::Invalid, 0),
        };
        ChannelValue {
            state: ch.state,
            validity,
            raw,
        }
    }
}

/// Reset + Match ROM + Read Scratchpad of one sensor, decoded.
pub async fn read_scratchpad<B: OneWireBus>(
    bus: &mut B,
    rom: &rom::RomCode,
) -> Result<ds18b20::Scratchpad, ChannelState> {
    match rom::select(bus, rom).await {
        Ok(true) => {}
        Ok(false) => return Err(ChannelState::NoPresence),
        Err(_) => return Err(ChannelState::AllZero),
    }
    let mut bytes = [0u8; 9];
    if bus.write_byte(ds18b20::READ_SCRATCHPAD).await.is_err() {
        return Err(ChannelState::AllZero);
    }
    for b in bytes.iter_mut() {
        match bus.read_byte().await {
            Ok(v) => *b = v,
            Err(_) => return Err(ChannelState::AllZero),
        }
    }
    ds18b20::decode(&bytes)
}

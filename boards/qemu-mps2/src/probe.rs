//! The bench board's emulated eddy-current probe (issue 28): a 16-bit ADC
//! whose code follows the trace's `dprobe_um` column (±1000 µm over the
//! range), with a small deterministic dither of ±3 codes that averages out
//! over every even number of samples, read by the application's own
//! oversampling and calibration (`thermocomp::acquisition::probe`).

use thermocomp::acquisition::probe::{self, Calibration, ProbeConfig, ProbeReading};
use thermocomp::hal::adc::{AdcError, ProbeAdc};

/// Full scale of the emulated converter.
const FULL_SCALE: u16 = u16::MAX;
/// −1000 µm at code 0, +1000 µm at 65,536 codes.
const OFFSET_TENTH_UM: i32 = -10_000;
const SPAN_TENTH_UM: i32 = 20_000;
const CODES: i32 = 65_536;
/// Samples per reading outside references.
const OVERSAMPLE: u16 = 16;

/// The probe as the trace row gives it.
pub struct EmulatedProbe {
    /// Code for the row's reading; `None`: the row has no probe value (the
    /// converter times out).
    code: Option<u16>,
    taken: u32,
}

impl EmulatedProbe {
    /// The converter's code for a reading of `tenth_um` (0.1 µm), rounded.
    pub fn at(tenth_um: Option<i32>) -> EmulatedProbe {
        let code = tenth_um.map(|v| {
            let num = (i64::from(v) - i64::from(OFFSET_TENTH_UM)) * i64::from(CODES);
            let span = i64::from(SPAN_TENTH_UM);
            let c = (num + span / 2).div_euclid(span);
            u16::try_from(c.clamp(0, i64::from(FULL_SCALE))).unwrap_or(FULL_SCALE)
        });
        EmulatedProbe { code, taken: 0 }
    }

    /// One reading of the row's probe: `oversample` samples (the board's
    /// usual count when `None`), calibrated by the application.
    pub async fn read(tenth_um: Option<i32>, oversample: Option<u16>) -> Option<ProbeReading> {
        let calibration = Calibration::linear(OFFSET_TENTH_UM, SPAN_TENTH_UM, CODES)?;
        let config = ProbeConfig {
            oversample: oversample.unwrap_or(OVERSAMPLE),
            saturation_margin: 8,
            calibration,
            min_tenth_um: OFFSET_TENTH_UM + 100,
            max_tenth_um: OFFSET_TENTH_UM + SPAN_TENTH_UM - 100,
        };
        let mut adc = EmulatedProbe::at(tenth_um);
        Some(probe::measure(&mut adc, &config).await)
    }
}

impl ProbeAdc for EmulatedProbe {
    fn full_scale(&self) -> u16 {
        FULL_SCALE
    }

    async fn sample(&mut self) -> Result<u16, AdcError> {
        let code = self.code.ok_or(AdcError::Timeout)?;
        // +3, −3, +1, −1: zero mean over each pair.
        let dither: i32 = match self.taken % 4 {
            0 => 3,
            1 => -3,
            2 => 1,
            _ => -1,
        };
        self.taken = self.taken.wrapping_add(1);
        let v = (i32::from(code) + dither).clamp(0, i32::from(FULL_SCALE));
        Ok(u16::try_from(v).unwrap_or(FULL_SCALE))
    }
}

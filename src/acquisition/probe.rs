//! The eddy-current displacement probe: oversampling and averaging, saturation
//! and range detection, calibration to 0.1 µm.
//!
//! Calibration is a polynomial in the averaged reading `x` (ADC codes × 16,
//! i.e. 1/16 LSB): `y = (c0 + c1·x + c2·x² + c3·x³) / 2³²` in 0.1 µm,
//! evaluated in i128 with checked arithmetic. A result outside i32 is an
//! error ([`ProbeState::CalibrationOverflow`]), never clamped.

use thermocomp_protocol::states::ProbeState;

use crate::hal::adc::ProbeAdc;

/// Most samples averaged per reading.
pub const MAX_OVERSAMPLE: u16 = 1024;

/// Calibration polynomial, Q32 coefficients (see module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibration {
    pub coeffs: [i64; 4],
}

impl Calibration {
    /// `y = offset + gain · counts`: offset in 0.1 µm, gain in 0.1 µm per ADC
    /// code as a ratio `gain_num / gain_den` (e.g. 2000 µm over 4096 codes
    /// = 20000 / 4096 tenths per code). `None` if `gain_den` is 0 or it
    /// overflows.
    pub fn linear(offset_tenth_um: i32, gain_num: i32, gain_den: i32) -> Option<Calibration> {
        if gain_den == 0 {
            return None;
        }
        let c0 = i64::from(offset_tenth_um).checked_mul(1 << 32)?;
        // x is counts × 16: divide the per-code gain by 16.
        let c1 = (i64::from(gain_num) << 28).checked_div(i64::from(gain_den))?;
        Some(Calibration {
            coeffs: [c0, c1, 0, 0],
        })
    }

    /// Evaluates at `x` (1/16 ADC code); `None` if the result is outside i32.
    pub fn apply(&self, x: u32) -> Option<i32> {
        let x = i128::from(x);
        let mut acc: i128 = 0;
        for c in self.coeffs.iter().rev() {
            acc = acc.checked_mul(x)?.checked_add(i128::from(*c))?;
        }
        // Round half away from zero.
        let half: i128 = 1 << 31;
        let y = if acc >= 0 {
            acc.checked_add(half)? >> 32
        } else {
            -(acc.checked_neg()?.checked_add(half)? >> 32)
        };
        i32::try_from(y).ok()
    }
}

/// Probe parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProbeConfig {
    /// Samples per reading, 1..=[`MAX_OVERSAMPLE`].
    pub oversample: u16,
    /// A sample within this many codes of 0 or full scale is saturated.
    pub saturation_margin: u16,
    pub calibration: Calibration,
    /// Measuring range of the probe, 0.1 µm, inclusive.
    pub min_tenth_um: i32,
    pub max_tenth_um: i32,
}

/// One probe reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProbeReading {
    pub state: ProbeState,
    /// Calibrated displacement, 0.1 µm (present unless the calibration
    /// overflowed or sampling failed; also given when out of range).
    pub tenth_um: Option<i32>,
    /// Mean of the samples, 1/16 ADC code.
    pub mean_x16: u32,
    pub min_code: u16,
    pub max_code: u16,
}

/// Takes `oversample` samples, averages and calibrates them.
pub async fn measure<A: ProbeAdc>(adc: &mut A, config: &ProbeConfig) -> ProbeReading {
    let mut reading = ProbeReading {
        state: ProbeState::Ok,
        tenth_um: None,
        mean_x16: 0,
        min_code: u16::MAX,
        max_code: 0,
    };
    let n = config.oversample;
    if n == 0 || n > MAX_OVERSAMPLE {
        reading.state = ProbeState::BadConfig;
        return reading;
    }
    let full = adc.full_scale();
    let mut sum: u32 = 0;
    for i in 0..n {
        if i % 16 == 15 {
            // A conversion is ~25 µs blocking: let other tasks in now and then.
            super::bitbang::yield_now().await;
        }
        match adc.sample().await {
            Ok(code) => {
                let code = code.min(full);
                sum += u32::from(code);
                reading.min_code = reading.min_code.min(code);
                reading.max_code = reading.max_code.max(code);
            }
            Err(_) => {
                reading.state = ProbeState::AdcError;
                return reading;
            }
        }
    }
    // sum ≤ 1024 · 65535 < 2^27, × 16 < 2^31.
    let n32 = u32::from(n);
    reading.mean_x16 = (sum * 16 + n32 / 2) / n32;
    let margin = config.saturation_margin;
    let saturated = reading.min_code <= margin || reading.max_code >= full.saturating_sub(margin);
    reading.tenth_um = config.calibration.apply(reading.mean_x16);
    reading.state = match reading.tenth_um {
        _ if saturated => ProbeState::Saturated,
        None => ProbeState::CalibrationOverflow,
        Some(y) if y < config.min_tenth_um || y > config.max_tenth_um => ProbeState::OutOfRange,
        Some(_) => ProbeState::Ok,
    };
    reading
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
    fn linear_calibration() {
        // 0 µm at code 0, 2000 µm (20000 tenths) at code 4096.
        let c = Calibration::linear(-10_000, 20_000, 4096).unwrap();
        assert_eq!(c.apply(2048 * 16), Some(0));
        assert_eq!(c.apply(4096 * 16), Some(10_000));
        assert_eq!(c.apply(0), Some(-10_000));
        // quadratic term: + x² · 2^-32 ... overflow is reported, not clamped
        let big = Calibration {
            coeffs: [0, 0, 0, i64::MAX],
        };
        assert_eq!(big.apply(65_520), None);
    }
}

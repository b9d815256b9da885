//! The eddy-current probe's analog output on PA0 (A0, ADC1_IN0): 0–10 V probe
//! output through a 1:3.3 divider and RC filter, 12-bit conversions.
//! Oversampling, saturation detection and calibration to 0.1 µm are in
//! `thermocomp::acquisition::probe`; this only hands out raw codes.
//!
//! Construction (in `main`, after `embassy_stm32::init`):
//! ```ignore
//! let mut probe = probe_adc::ProbeInput::new(p.ADC1, p.PA0);
//! let cfg = ProbeConfig {
//!     oversample: 64,
//!     saturation_margin: 8,
//!     calibration: Calibration::linear(offset_tenth_um, gain_num, gain_den).unwrap(),
//!     min_tenth_um: -10_000,
//!     max_tenth_um: 10_000,
//! };
//! let reading = thermocomp::acquisition::probe::measure(&mut probe, &cfg).await;
//! ```

use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::peripherals::{ADC1, PA0};
use embassy_stm32::Peri;
use thermocomp::hal::adc::{AdcError, ProbeAdc};

/// ADC1 channel 0 on PA0.
pub struct ProbeInput<'d> {
    adc: Adc<'d, ADC1>,
    pin: Peri<'d, PA0>,
}

impl<'d> ProbeInput<'d> {
    pub fn new(adc: Peri<'d, ADC1>, pin: Peri<'d, PA0>) -> Self {
        ProbeInput {
            adc: Adc::new(adc),
            pin,
        }
    }
}

impl ProbeAdc for ProbeInput<'_> {
    fn full_scale(&self) -> u16 {
        4095
    }

    async fn sample(&mut self) -> Result<u16, AdcError> {
        // 480 cycles at 21 MHz ADC clock ≈ 23 µs: the RC filter's source
        // impedance needs the long sample time.
        Ok(self.adc.blocking_read(&mut self.pin, SampleTime::CYCLES480))
    }
}

//! One analog input: the eddy-current displacement probe's conditioned output
//! on an ADC channel. The acquisition oversamples and calibrates
//! (`acquisition::probe`); the board only hands out raw conversions.
#![allow(async_fn_in_trait)]

/// ADC failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum AdcError {
    /// The conversion did not complete.
    Timeout,
    /// The converter reported an overrun or another hardware error.
    Hardware,
}

/// A single-channel ADC.
pub trait ProbeAdc {
    /// Largest raw code the converter returns (4095 for 12 bits).
    fn full_scale(&self) -> u16;
    /// One conversion, raw code `0..=full_scale()`.
    async fn sample(&mut self) -> Result<u16, AdcError>;
}

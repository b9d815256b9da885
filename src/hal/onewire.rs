//! A 1-Wire bus master at the bit level. Small on purpose so that three very
//! different things implement it: the STM32 open-drain bit-banger
//! (`boards/nucleo-f446re/src/onewire.rs`), the pin-level emulator in
//! `host-tests` (an emulated wired-AND line with datasheet timing windows) and
//! a plain byte-level emulator on the QEMU bench board.
//!
//! Only slot-level operations are required; byte operations have default
//! bodies built on them (an implementation may override them, e.g. a UART
//! 1-Wire that sends 8 slots per byte). The conversion wait is not part of
//! this trait: the acquisition awaits an `embedded_hal_async::delay::DelayNs`
//! so the executor keeps running during the 750 ms conversion.
//!
//! The methods are `async` so a DMA/UART implementation can suspend; a
//! bit-banger completes each slot synchronously (a slot is 62–70 µs).
#![allow(async_fn_in_trait)]

/// Bus-level failure, independent of the implementation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum BusError {
    /// The line stayed low after the reset (shorted to ground or a device
    /// stuck low): no slot can be trusted.
    Shorted,
    /// The implementation could not drive the pin (GPIO error).
    Pin,
}

/// A 1-Wire master (open drain, external pull-up ~4.7 kΩ).
pub trait OneWireBus {
    /// Reset pulse (≥ 480 µs low), then sample the presence pulse.
    /// `Ok(true)`: at least one device answered.
    async fn reset(&mut self) -> Result<bool, BusError>;

    /// One write slot: `true` releases the line within 15 µs, `false` holds it
    /// low for ≥ 60 µs.
    async fn write_bit(&mut self, bit: bool) -> Result<(), BusError>;

    /// One read slot: pull low ≥ 1 µs, release, sample before 15 µs after the
    /// falling edge.
    async fn read_bit(&mut self) -> Result<bool, BusError>;

    /// Drive the line hard high (strong pull-up, parasite power during a
    /// conversion) or return to the resistor pull-up. Buses with externally
    /// powered sensors do not need it; the default does nothing.
    async fn set_strong_pullup(&mut self, _enable: bool) -> Result<(), BusError> {
        Ok(())
    }

    /// Writes `byte`, then turns the strong pull-up on within 10 µs of the
    /// end of its last slot (parasite-powered Convert T). Implementations
    /// that can yield between bytes must override this so nothing runs in
    /// between.
    async fn write_byte_then_strong_pullup(&mut self, byte: u8) -> Result<(), BusError> {
        self.write_byte(byte).await?;
        self.set_strong_pullup(true).await
    }

    /// Eight write slots, least significant bit first.
    async fn write_byte(&mut self, byte: u8) -> Result<(), BusError> {
        for i in 0..8 {
            self.write_bit(byte & (1 << i) != 0).await?;
        }
        Ok(())
    }

    /// Eight read slots, least significant bit first.
    async fn read_byte(&mut self) -> Result<u8, BusError> {
        let mut byte = 0u8;
        for i in 0..8 {
            if self.read_bit().await? {
                byte |= 1 << i;
            }
        }
        Ok(byte)
    }
}

impl<T: OneWireBus + ?Sized> OneWireBus for &mut T {
    async fn reset(&mut self) -> Result<bool, BusError> {
        (**self).reset().await
    }
    async fn write_bit(&mut self, bit: bool) -> Result<(), BusError> {
        (**self).write_bit(bit).await
    }
    async fn read_bit(&mut self) -> Result<bool, BusError> {
        (**self).read_bit().await
    }
    async fn set_strong_pullup(&mut self, enable: bool) -> Result<(), BusError> {
        (**self).set_strong_pullup(enable).await
    }
    async fn write_byte(&mut self, byte: u8) -> Result<(), BusError> {
        (**self).write_byte(byte).await
    }
    async fn write_byte_then_strong_pullup(&mut self, byte: u8) -> Result<(), BusError> {
        (**self).write_byte_then_strong_pullup(byte).await
    }
    async fn read_byte(&mut self) -> Result<u8, BusError> {
        (**self).read_byte().await
    }
}

//! A [`OneWireBus`] on one open-drain GPIO and a precise busy-wait delay: the
//! slot timing of the DS18B20 datasheet, written once. The STM32 board
//! provides the pin (with interrupt masking around the timed parts) and a
//! cycle-counter delay; the host tests provide the pin-level emulator.
//!
//! Timing (µs), chosen inside the datasheet windows with margin for the
//! delay's overshoot:
//!
//! | slot | line low | released | sample at | total |
//! |---|---|---|---|---|
//! | reset | 500 (≥ 480) | 500 (≥ 480) | presence at 70 after release | 1000 |
//! | write 1 | 2 (1..15) | 60 | – | 62 |
//! | write 0 | 60 (60..120) | 2 (recovery ≥ 1) | – | 62 |
//! | read | 2 (≥ 1) | 60 | 10 after the fall (< 15) | 62 |
//!
//! `one-wire-bus` 0.1.1 samples at 15 µs, the end of the read window; this
//! one at 10 µs, so up to 5 µs of overshoot still reads correctly.

use crate::hal::onewire::{BusError, OneWireBus};

/// An open-drain pin with an external pull-up.
pub trait OpenDrainPin {
    /// Drive the line low.
    fn set_low(&mut self);
    /// Release the line (the pull-up or a device decides the level).
    fn release(&mut self);
    /// Sample the line.
    fn is_high(&mut self) -> bool;
    /// Drive the line hard high (strong pull-up for parasite power); the
    /// default cannot and reports [`BusError::Pin`].
    fn drive_high(&mut self) -> Result<(), BusError> {
        Err(BusError::Pin)
    }
    /// Run `f` with interrupts masked (a few tens of µs at most). The default
    /// does not mask (host emulator).
    fn critical<R>(&mut self, f: impl FnOnce(&mut Self) -> R) -> R {
        f(self)
    }
}

/// A busy-wait delay precise to about a microsecond.
pub trait BusyDelay {
    fn delay_us(&mut self, us: u32);
}

/// Slot timing, µs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlotTiming {
    pub reset_low: u32,
    pub presence_sample: u32,
    pub reset_rest: u32,
    pub write1_low: u32,
    pub write0_low: u32,
    pub read_low: u32,
    pub read_sample: u32,
    pub slot: u32,
}

impl SlotTiming {
    /// The timing in the module table.
    pub const STANDARD: SlotTiming = SlotTiming {
        reset_low: 500,
        presence_sample: 70,
        reset_rest: 430,
        write1_low: 2,
        write0_low: 60,
        read_low: 2,
        read_sample: 10,
        slot: 62,
    };
}

/// Bit-banged 1-Wire master.
pub struct BitBangBus<P, D> {
    pin: P,
    delay: D,
    timing: SlotTiming,
}

impl<P: OpenDrainPin, D: BusyDelay> BitBangBus<P, D> {
    /// Releases the line.
    pub fn new(mut pin: P, delay: D, timing: SlotTiming) -> Self {
        pin.release();
        BitBangBus { pin, delay, timing }
    }

    pub fn release(self) -> (P, D) {
        (self.pin, self.delay)
    }

    fn reset_blocking(&mut self) -> Result<bool, BusError> {
        let t = self.timing;
        // Long low phase: an interrupt lengthening it does no harm.
        self.pin.set_low();
        self.delay.delay_us(t.reset_low);
        let delay = &mut self.delay;
        let presence = self.pin.critical(|pin| {
            pin.release();
            delay.delay_us(t.presence_sample);
            !pin.is_high()
        });
        self.delay.delay_us(t.reset_rest);
        if !self.pin.is_high() {
            return Err(BusError::Shorted);
        }
        Ok(presence)
    }

    fn write_bit_blocking(&mut self, bit: bool) {
        let t = self.timing;
        let delay = &mut self.delay;
        let low = if bit { t.write1_low } else { t.write0_low };
        self.pin.critical(|pin| {
            pin.set_low();
            delay.delay_us(low);
            pin.release();
        });
        self.delay.delay_us(t.slot.saturating_sub(low));
    }

    fn read_bit_blocking(&mut self) -> bool {
        let t = self.timing;
        let delay = &mut self.delay;
        let bit = self.pin.critical(|pin| {
            pin.set_low();
            delay.delay_us(t.read_low);
            pin.release();
            delay.delay_us(t.read_sample.saturating_sub(t.read_low));
            pin.is_high()
        });
        self.delay.delay_us(t.slot.saturating_sub(t.read_sample));
        bit
    }
}

/// Lets the executor run other tasks once (wakes itself, returns Pending
/// once). Executor-agnostic.
pub async fn yield_now() {
    struct YieldNow(bool);
    impl core::future::Future for YieldNow {
        type Output = ();
        fn poll(
            mut self: core::pin::Pin<&mut Self>,
            cx: &mut core::task::Context<'_>,
        ) -> core::task::Poll<()> {
            if self.0 {
                core::task::Poll::Ready(())
            } else {
                self.0 = true;
                cx.waker().wake_by_ref();
                core::task::Poll::Pending
            }
        }
    }
    YieldNow(false).await
}

/// Slots are busy-waited, but the bus yields to the executor after every
/// reset and every byte, so no other task waits more than ~1 ms (a reset)
/// even during the ~210 ms of scratchpad reads of a 20-sensor cycle.
impl<P: OpenDrainPin, D: BusyDelay> OneWireBus for BitBangBus<P, D> {
    async fn reset(&mut self) -> Result<bool, BusError> {
        let r = self.reset_blocking();
        yield_now().await;
        r
    }

    async fn write_byte(&mut self, byte: u8) -> Result<(), BusError> {
        for i in 0..8 {
            self.write_bit_blocking(byte & (1 << i) != 0);
        }
        yield_now().await;
        Ok(())
    }

    async fn write_byte_then_strong_pullup(&mut self, byte: u8) -> Result<(), BusError> {
        for i in 0..7 {
            self.write_bit_blocking(byte & (1 << i) != 0);
        }
        // Last slot and the switch to the strong pull-up in one masked
        // section (≤ 62 µs): the datasheet allows 10 µs between them.
        let t = self.timing;
        let low = if byte & 0x80 != 0 {
            t.write1_low
        } else {
            t.write0_low
        };
        let delay = &mut self.delay;
        let r = self.pin.critical(|pin| {
            pin.set_low();
            delay.delay_us(low);
            pin.release();
            delay.delay_us(t.slot.saturating_sub(low));
            pin.drive_high()
        });
        yield_now().await;
        r
    }

    async fn read_byte(&mut self) -> Result<u8, BusError> {
        let mut byte = 0u8;
        for i in 0..8 {
            if self.read_bit_blocking() {
                byte |= 1 << i;
            }
        }
        yield_now().await;
        Ok(byte)
    }

    async fn write_bit(&mut self, bit: bool) -> Result<(), BusError> {
        self.write_bit_blocking(bit);
        Ok(())
    }

    async fn read_bit(&mut self) -> Result<bool, BusError> {
        Ok(self.read_bit_blocking())
    }

    async fn set_strong_pullup(&mut self, enable: bool) -> Result<(), BusError> {
        if enable {
            self.pin.drive_high()
        } else {
            self.pin.release();
            Ok(())
        }
    }
}

//! The RS-485 Modbus port as the application sees it: whole RTU frames.
//! The board times each received byte and finds frame ends with the
//! application's one framer (`modbus/rtu_framer.rs`: 3.5-character
//! end, 1.5-character break), and drives the transceiver's driver-enable
//! around each reply.

/// A received frame was longer than the buffer (it is discarded whole).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Overrun;

#[allow(async_fn_in_trait)]
pub trait RtuPort {
    /// Wait for the next frame; its length in `buf`.
    async fn read_frame(&mut self, buf: &mut [u8]) -> Result<usize, Overrun>;
    /// Send a reply: driver enable on, bytes out, wait until the last stop
    /// bit has left, driver enable off.
    async fn write_frame(&mut self, bytes: &[u8]);
    /// Change the line speed (after the reply that confirmed the change).
    fn set_baud(&mut self, baud: u32);
}

//! The RS-485 Modbus port: USART1 (PA9 TX, PA10 RX) through a half-duplex
//! transceiver whose driver enable is PA8 (a GPIO: the F4's USART has no
//! hardware DE). Frames are found by the application's one RTU framer
//! ([`thermocomp::modbus::rtu_framer`]: 3.5-character end, 1.5-character
//! break, 256-byte limit) in the receive loop both boards share
//! ([`board_support::rtu_receive`]), as on the bench.
//!
//! Reception runs into a DMA ring without pause (a 1-Wire critical section
//! cannot overrun it, and waiting for a frame's end can be cancelled without
//! losing a byte). The ring hands over bytes at an idle line (one character
//! of silence) or when the DMA passes the middle or the end of the ring;
//! each batch's bytes are stamped back from the time it was handed over,
//! one character apart, the last one a character before it (the idle
//! detection). The stamps are accurate to the task's latency, plus one
//! character for a batch cut at the ring's middle or end: at 115200 baud
//! the break rule (750 µs) has eight characters of margin; at 9600 baud a
//! silence just under 1.5 characters may be read as a break (the frame is
//! discarded; the master asks again), never a break as none.

use core::sync::atomic::{AtomicBool, Ordering};

use board_support::rtu_receive::{ByteSource, RtuReceiver};
use embassy_stm32::gpio::Output;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
use embassy_time::{with_deadline, Instant};
use thermocomp::hal::serial::{Overrun, RtuPort};
use thermocomp::modbus::rtu_framer::Timing;

/// One batch from the ring.
const BATCH: usize = 64;
/// The DMA ring: two frames.
pub const RX_RING: usize = 512;

/// The port drives the bus (driver enable high, until the last stop bit).
static TRANSMITTING: AtomicBool = AtomicBool::new(false);
/// A frame is being received (bytes since the last frame end).
static RECEIVING: AtomicBool = AtomicBool::new(false);

/// Neither sending nor receiving, and USART1's last stop bit is out (TC):
/// a flash erase, which stalls the CPU for 1–4 s, may start now without
/// holding the bus or delaying a reply. Called under the app lock (no task
/// runs in between).
pub fn line_quiet() -> bool {
    !TRANSMITTING.load(Ordering::Acquire)
        && !RECEIVING.load(Ordering::Acquire)
        && embassy_stm32::pac::USART1.sr().read().tc()
}

pub struct Rs485Port {
    tx: UartTx<'static, Async>,
    rx: RingRx,
    driver_enable: Output<'static>,
    receiver: RtuReceiver,
}

/// The DMA ring's receiver, handing the loop one time-stamped byte at a time.
struct RingRx {
    ring: RingBufferedUartRx<'static>,
    /// Bytes handed over by the ring, not yet given to the framer.
    batch: [u8; BATCH],
    batch_len: usize,
    batch_pos: usize,
    /// Time stamp of the batch's last byte (µs).
    batch_end_us: u64,
}

impl Rs485Port {
    pub fn new(
        tx: UartTx<'static, Async>,
        rx: RingBufferedUartRx<'static>,
        driver_enable: Output<'static>,
        baud: u32,
    ) -> Self {
        Rs485Port {
            tx,
            rx: RingRx {
                ring: rx,
                batch: [0; BATCH],
                batch_len: 0,
                batch_pos: 0,
                batch_end_us: 0,
            },
            driver_enable,
            receiver: RtuReceiver::new(Timing::for_baud(baud)),
        }
    }
}

impl ByteSource for RingRx {
    async fn next_byte(
        &mut self,
        deadline_us: Option<u64>,
        char_us: u64,
    ) -> Result<Option<(u8, u64)>, Overrun> {
        if self.batch_pos >= self.batch_len {
            let read = self.ring.read(&mut self.batch);
            let got = match deadline_us {
                None => Some(read.await),
                Some(d) => with_deadline(Instant::from_micros(d), read).await.ok(),
            };
            match got {
                None => return Ok(None),
                Some(Ok(n)) => {
                    self.batch_len = n.min(BATCH);
                    self.batch_pos = 0;
                    self.batch_end_us = Instant::now().as_micros().saturating_sub(char_us);
                }
                Some(Err(_)) => {
                    // Overrun, framing or noise error: the frame in progress
                    // lost or garbled bytes (the loop drops it); reception
                    // restarts at the next read.
                    self.batch_len = 0;
                    self.batch_pos = 0;
                    return Err(Overrun);
                }
            }
        }
        let Some(&byte) = self.batch.get(self.batch_pos) else {
            return Ok(None);
        };
        let behind = (self.batch_len - 1 - self.batch_pos) as u64;
        let at = self.batch_end_us.saturating_sub(behind * char_us);
        self.batch_pos += 1;
        Ok(Some((byte, at)))
    }

    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }

    fn receiving(&mut self, in_frame: bool) {
        RECEIVING.store(in_frame, Ordering::Release);
    }
}

impl RtuPort for Rs485Port {
    async fn read_frame(&mut self, buf: &mut [u8]) -> Result<usize, Overrun> {
        self.receiver.read_frame(&mut self.rx, buf).await
    }

    async fn write_frame(&mut self, bytes: &[u8]) {
        TRANSMITTING.store(true, Ordering::Release);
        self.driver_enable.set_high();
        let _ = self.tx.write(bytes).await;
        // Wait for the last stop bit (TC), not just an empty data register,
        // before releasing the line.
        let _ = self.tx.blocking_flush();
        self.driver_enable.set_low();
        TRANSMITTING.store(false, Ordering::Release);
    }

    fn set_baud(&mut self, baud: u32) {
        let _ = self.tx.set_baudrate(baud);
        let _ = self.rx.ring.set_baudrate(baud);
        self.receiver.set_timing(Timing::for_baud(baud));
    }
}

//! RTU framing on the bench board's UART0: a frame ends at a silent gap of
//! 3.5 characters (Modbus serial line spec; 1.75 ms fixed above 19200 baud).
//! The time driver ticks at 1 kHz, so the gap is rounded up to whole ms.

use embassy_time::{with_timeout, Duration};
use thermocomp::hal::serial::{Overrun, RtuPort};

use crate::uart::Uart0;

pub struct QemuRtuPort {
    uart: Uart0,
    gap: Duration,
}

/// 3.5 characters of 11 bits at `baud`, at least 1.75 ms, in whole ms.
fn frame_gap(baud: u32) -> Duration {
    let us = if baud > 19_200 {
        1_750
    } else {
        38_500_000 / u64::from(baud.max(1))
    };
    Duration::from_millis(us.div_ceil(1000))
}

impl QemuRtuPort {
    pub fn new(baud: u32) -> Self {
        QemuRtuPort {
            uart: Uart0::new(baud),
            gap: frame_gap(baud),
        }
    }
}

impl RtuPort for QemuRtuPort {
    async fn read_frame(&mut self, buf: &mut [u8]) -> Result<usize, Overrun> {
        let first = self.uart.read_byte().await;
        let mut n = 0;
        let mut overrun = false;
        let mut push = |b: u8, n: &mut usize| match buf.get_mut(*n) {
            Some(slot) => {
                *slot = b;
                *n += 1;
            }
            None => overrun = true,
        };
        push(first, &mut n);
        while let Ok(b) = with_timeout(self.gap, self.uart.read_byte()).await {
            push(b, &mut n);
        }
        if overrun {
            Err(Overrun)
        } else {
            Ok(n)
        }
    }

    async fn write_frame(&mut self, bytes: &[u8]) {
        // No driver-enable pin on this board; QEMU sends the bytes at once.
        self.uart.write_all(bytes);
    }

    fn set_baud(&mut self, baud: u32) {
        self.uart.set_baud(baud);
        self.gap = frame_gap(baud);
    }
}

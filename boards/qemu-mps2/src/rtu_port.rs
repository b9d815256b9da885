//! RTU framing on the bench board's UART0. A frame ends when its length is
//! complete (known from the function code) or, failing that, at a silent gap.
//! On a real line the gap is 3.5 characters (1.75 ms above 19200 baud); QEMU
//! does not model line timing (bytes arrive as fast as the guest takes them,
//! or in bursts when the host is busy), so a millisecond gap means nothing
//! here: complete frames are answered at once and only frames of unknown
//! length (garbage, unknown functions) wait for `BENCH_GAP` of silence.

use embassy_time::{with_timeout, Duration};
use thermocomp::hal::serial::{Overrun, RtuPort};
use thermocomp::modbus::server::expected_request_len;

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
        // Bytes past the buffer are counted, not stored: the frame is then refused whole.
        let first = self.uart.read_byte().await;
        let mut n = 0usize;
        let store = |b: u8, n: &mut usize, buf: &mut [u8]| {
            if let Some(slot) = buf.get_mut(*n) {
                *slot = b;
            }
            *n += 1;
        };
        store(first, &mut n, buf);
        loop {
            let head = &buf[..n.min(buf.len())];
            if expected_request_len(head).is_some_and(|len| n >= len) {
                break;
            }
            match with_timeout(self.gap, self.uart.read_byte()).await {
                Ok(b) => store(b, &mut n, buf),
                Err(_) => break,
            }
        }
        if n > buf.len() {
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

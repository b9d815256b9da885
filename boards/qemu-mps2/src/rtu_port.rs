//! RTU framing on the bench board's UART0. A frame ends when its length is
//! complete (known from the function code) or, failing that, at a silent gap.
//! On a real line the gap is 3.5 characters (1.75 ms above 19200 baud); QEMU
//! does not model line timing (bytes arrive as fast as the guest takes them,
//! or in bursts when the host is busy), so a millisecond gap means nothing
//! here: complete frames are answered at once and only frames of unknown
//! length (garbage, unknown functions) wait for the gap.
//!
//! Resynchronisation: a request may follow garbage with no gap at all (a
//! flood, a babbling node, or bytes queued on the host). The newest bytes
//! since the last gap are kept as a window, and as soon as a request of known
//! length with a valid CRC ends at the newest byte, that request is the
//! frame, whatever came before it. Recovery from a flood therefore takes no
//! gap: the first good request after it is answered when its last byte
//! arrives. (How fast the bytes arrive is QEMU's: its CMSDK UART takes one
//! byte per main-loop turn, ~15 kB/s on a busy host, so bytes already queued
//! in a host socket drain at that rate whatever the firmware does.)

use embassy_time::{with_timeout, Duration};
use thermocomp::hal::serial::{Overrun, RtuPort};
use thermocomp_protocol::rtu::{crc16, expected_request_len};

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

/// Where a complete request of known length with a valid CRC starts, if one
/// ends at the last byte of `window`; the earliest (longest) one first.
fn request_ending_here(window: &[u8]) -> Option<usize> {
    (0..window.len()).find(|&start| {
        let candidate = &window[start..];
        expected_request_len(candidate) == Some(candidate.len()) && candidate.len() >= 4 && {
            let (body, crc) = candidate.split_at(candidate.len() - 2);
            crc16(body).to_le_bytes() == [crc[0], crc[1]]
        }
    })
}

impl RtuPort for QemuRtuPort {
    async fn read_frame(&mut self, buf: &mut [u8]) -> Result<usize, Overrun> {
        // `buf[..n]`: the newest bytes since the last gap (at most the whole
        // buffer); `total` counts them all, so an oversize run of bytes that
        // holds no request is refused whole at the gap.
        if buf.is_empty() {
            return Err(Overrun);
        }
        let mut byte = self.uart.read_byte().await;
        let mut n = 0usize;
        let mut total = 0usize;
        loop {
            total = total.saturating_add(1);
            if n == buf.len() {
                buf.copy_within(1.., 0);
                n -= 1;
            }
            if let Some(slot) = buf.get_mut(n) {
                *slot = byte;
                n += 1;
            }
            if let Some(start) = request_ending_here(&buf[..n]) {
                buf.copy_within(start..n, 0);
                return Ok(n - start);
            }
            match with_timeout(self.gap, self.uart.read_byte()).await {
                Ok(b) => byte = b,
                Err(_) => break,
            }
        }
        if total > buf.len() {
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

//! The RS-485 Modbus port: USART1 (PA9 TX, PA10 RX) through a half-duplex
//! transceiver whose driver enable is PA8 (a GPIO: the F4's USART has no
//! hardware DE). Frame ends are found by the USART's IDLE-line detection
//! (`read_until_idle`), which the Modbus serial-line spec allows in place of
//! timing 3.5 characters; DMA receives, so a 1-Wire critical section cannot
//! overrun the receiver.

use embassy_stm32::gpio::Output;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::Uart;
use thermocomp::hal::serial::{Overrun, RtuPort};

pub struct Rs485Port {
    uart: Uart<'static, Async>,
    driver_enable: Output<'static>,
}

impl Rs485Port {
    pub fn new(uart: Uart<'static, Async>, driver_enable: Output<'static>) -> Self {
        Rs485Port {
            uart,
            driver_enable,
        }
    }
}

impl RtuPort for Rs485Port {
    async fn read_frame(&mut self, buf: &mut [u8]) -> Result<usize, Overrun> {
        // A frame that fills the buffer is longer than any valid RTU frame.
        match self.uart.read_until_idle(buf).await {
            Ok(n) if n < buf.len() => Ok(n),
            _ => Err(Overrun),
        }
    }

    async fn write_frame(&mut self, bytes: &[u8]) {
        self.driver_enable.set_high();
        let _ = self.uart.write(bytes).await;
        // Wait for the last stop bit (TC), not just an empty data register,
        // before releasing the line.
        let _ = self.uart.blocking_flush();
        self.driver_enable.set_low();
    }

    fn set_baud(&mut self, baud: u32) {
        let _ = self.uart.set_baudrate(baud);
    }
}

//! CMSDK APB UART0 of the MPS2 (0x4000_4000), the bench board's RS-485 port.
//! QEMU connects it to a host TCP socket or pty. Receive is interrupt driven
//! into a bounded ring of time-stamped bytes so the executor never
//! busy-waits on the line and the RTU framer sees the gaps; transmit
//! polls the TX-full flag (QEMU drains it at once). There is no driver-enable
//! pin on this board: the RS-485 direction calls are no-ops here.
//!
//! Hand-written: no crate drives the CMSDK UART, and it is five registers.

use core::cell::RefCell;
use core::future::poll_fn;
use core::ptr::{read_volatile, write_volatile};
use core::task::Poll;

use critical_section::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use heapless::Deque;

const BASE: usize = 0x4000_4000;
const DATA: *mut u32 = BASE as *mut u32;
const STATE: *mut u32 = (BASE + 0x04) as *mut u32;
const CTRL: *mut u32 = (BASE + 0x08) as *mut u32;
const INTSTATUS_CLEAR: *mut u32 = (BASE + 0x0C) as *mut u32;
const BAUDDIV: *mut u32 = (BASE + 0x10) as *mut u32;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_RX_INT_EN: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;

/// UART0 receive interrupt on mps2-an386 (QEMU hw/arm/mps2.c: RX irq 0, TX 1).
pub const UART0_RX_IRQ: u16 = 0;

/// Receive ring size: a full Modbus RTU frame (256 bytes) plus the start of
/// the next one.
const RX_CAPACITY: usize = 512;

/// Received bytes with their arrival time (µs since boot, taken in the
/// receive interrupt: [`crate::time_driver::now_us`]), so the RTU framer
/// sees the line's gaps however late the Modbus task reads them.
static RX: Mutex<RefCell<Deque<(u8, u64), RX_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_OVERRUNS: Mutex<core::cell::Cell<u32>> = Mutex::new(core::cell::Cell::new(0));
static RX_WAKER: AtomicWaker = AtomicWaker::new();

#[derive(Clone, Copy)]
struct Irq(u16);
// SAFETY: the number is a valid external interrupt of this machine.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

pub struct Uart0 {
    baud: u32,
}

impl Uart0 {
    /// Enable TX, RX and the RX interrupt at `baud`.
    pub fn new(baud: u32) -> Uart0 {
        let mut uart = Uart0 { baud };
        uart.set_baud(baud);
        // SAFETY: MMIO writes to UART0, owned by this driver alone.
        unsafe {
            write_volatile(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_INT_EN);
            cortex_m::peripheral::NVIC::unmask(Irq(UART0_RX_IRQ));
        }
        uart
    }

    pub fn set_baud(&mut self, baud: u32) {
        // QEMU refuses divisors below 16; timing on the socket is not modelled.
        let div = (crate::time_driver::CORE_CLOCK_HZ / baud.max(1)).max(16);
        self.baud = baud;
        // SAFETY: MMIO write to UART0.
        unsafe { write_volatile(BAUDDIV, div) };
    }

    /// The oldest received byte and its arrival time (µs), if any.
    pub fn try_read_byte(&mut self) -> Option<(u8, u64)> {
        critical_section::with(|cs| RX.borrow(cs).borrow_mut().pop_front())
    }

    /// Next received byte and its arrival time (µs), waiting without
    /// blocking the executor.
    pub async fn read_byte(&mut self) -> (u8, u64) {
        poll_fn(|cx| {
            if let Some(b) = critical_section::with(|cs| RX.borrow(cs).borrow_mut().pop_front()) {
                return Poll::Ready(b);
            }
            RX_WAKER.register(cx.waker());
            match critical_section::with(|cs| RX.borrow(cs).borrow_mut().pop_front()) {
                Some(b) => Poll::Ready(b),
                None => Poll::Pending,
            }
        })
        .await
    }

    pub fn write_all(&mut self, bytes: &[u8]) {
        for &b in bytes {
            // SAFETY: MMIO access to UART0.
            unsafe {
                while read_volatile(STATE) & STATE_TX_FULL != 0 {}
                write_volatile(DATA, u32::from(b));
            }
        }
    }
}

/// Called from the interrupt dispatcher for UART0 RX.
pub fn on_rx_interrupt() {
    critical_section::with(|cs| {
        let mut rx = RX.borrow(cs).borrow_mut();
        // SAFETY: MMIO access to UART0 from its own interrupt.
        unsafe {
            // Clear first, then drain: a byte that lands after the last
            // check raises the interrupt again. (Draining first and clearing
            // after lost that byte's interrupt, and with RX full the UART
            // never took another byte: the port went deaf.)
            write_volatile(INTSTATUS_CLEAR, INT_RX);
            while read_volatile(STATE) & STATE_RX_FULL != 0 {
                let b = (read_volatile(DATA) & 0xFF) as u8;
                if rx.push_back((b, crate::time_driver::now_us())).is_err() {
                    let n = RX_OVERRUNS.borrow(cs);
                    n.set(n.get().saturating_add(1));
                }
            }
        }
    });
    RX_WAKER.wake();
}

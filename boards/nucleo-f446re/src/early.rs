//! What runs before `embassy_stm32::init`, in this order (issue 30):
//! 1. the RS-485 driver enable (PA8) driven low: after a reset the pin is a
//!    floating input until software drives it, and the board's pull-down
//!    (README) holds the transceiver off only until then;
//! 2. the IWDG started: embassy's clock init waits for HSE and PLL with no
//!    timeout, so a hang there must end in a watchdog reset;
//! 3. the HSE (the ST-LINK's 8 MHz MCO, bypass) probed with a timeout: when
//!    it does not come up, the clock init runs from the HSI instead, and the
//!    board says so ([`ClockSource::HsiFallback`]).
//!
//! All through the PAC: nothing of embassy's is up yet.

use embassy_stm32::pac;

/// Where SYSCLK (168 MHz either way) comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ClockSource {
    /// HSE bypass, 8 MHz from the ST-LINK's MCO.
    Hse,
    /// The HSE did not start within [`HSE_TIMEOUT_MS`]: the internal 16 MHz
    /// RC (±1 % at 25 °C; the UART's baud error stays within Modbus's
    /// tolerance).
    HsiFallback,
}

/// How long the HSE may take to come up (a bypass clock is ready within
/// microseconds; a crystal within 2 ms).
pub const HSE_TIMEOUT_MS: u32 = 50;
/// Reset clock: HSI, 16 MHz.
const RESET_CLOCK_HZ: u32 = 16_000_000;

/// PA8 low and an output, before anything else.
pub fn release_bus() {
    pac::RCC.ahb1enr().modify(|w| w.set_gpioaen(true));
    // Output data low first, then output mode: the pin never drives high.
    pac::GPIOA.bsrr().write(|w| w.set_br(8, true));
    pac::GPIOA
        .moder()
        .modify(|w| w.set_moder(8, pac::gpio::vals::Moder::OUTPUT));
}

/// Start the IWDG at the application's timeout, with the very prescaler and
/// reload `IndependentWatchdog::new` computes for it later (÷128 on the
/// nominal 32 kHz LSI; reload `timeout / 128 × 32 kHz − 1`, 2,499 for 10 s),
/// so its rewrite changes nothing even if it lands while this update is
/// still in progress (PVU/RVU, up to 5 LSI cycles; waited for here, bounded).
/// A started IWDG cannot be stopped.
pub fn start_watchdog(timeout_us: u32) {
    let reload = (timeout_us / 128 * 32_000 / 1_000_000)
        .saturating_sub(1)
        .clamp(1, 0xFFF);
    let iwdg = pac::IWDG;
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::START));
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::ENABLE));
    iwdg.pr()
        .write(|w| w.set_pr(pac::iwdg::vals::Pr::DIVIDE_BY128));
    iwdg.rlr()
        .write(|w| w.set_rl(u16::try_from(reload).unwrap_or(0xFFF)));
    for _ in 0..1_000 {
        let sr = iwdg.sr().read();
        if !sr.pvu() && !sr.rvu() {
            break;
        }
        cortex_m::asm::delay(RESET_CLOCK_HZ / 100_000);
    }
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// Switch the HSE on (bypass) and wait for it at most [`HSE_TIMEOUT_MS`].
/// Left on when it came up (the clock init takes it from there), off when not.
pub fn probe_hse() -> ClockSource {
    let rcc = pac::RCC;
    rcc.cr().modify(|w| w.set_hsebyp(true));
    rcc.cr().modify(|w| w.set_hseon(true));
    for _ in 0..HSE_TIMEOUT_MS * 10 {
        if rcc.cr().read().hserdy() {
            return ClockSource::Hse;
        }
        cortex_m::asm::delay(RESET_CLOCK_HZ / 10_000);
    }
    rcc.cr().modify(|w| w.set_hseon(false));
    ClockSource::HsiFallback
}

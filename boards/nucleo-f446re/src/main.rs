//! Real board: the compensator on a NUCLEO-F446RE (STM32F446RE, Cortex-M4F).
//! Pin map and wiring: boards/nucleo-f446re/README.md.
//!
//! `cargo flash` (alias in .cargo/config.toml) builds in release, flashes over
//! the on-board ST-LINK with probe-rs and shows the defmt log.
#![no_std]
#![no_main]

use defmt::info;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::time::Hertz;
use embassy_stm32::Config;
use embassy_time::{Duration, Timer};
use {defmt_rtt as _, panic_probe as _};

/// 168 MHz from the ST-LINK's 8 MHz MCO (HSE bypass). 180 MHz would need the
/// regulator's over-drive mode for no gain the compensator needs.
fn clock_config() -> Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.sys = Sysclk::PLL1_P;
    config
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clock_config());
    info!("thermocomp on NUCLEO-F446RE, 168 MHz");
    let led = Output::new(p.PA5, Level::Low, Speed::Low);
    match heartbeat(led) {
        Ok(task) => spawner.spawn(task),
        Err(_) => defmt::error!("heartbeat task could not be spawned"),
    }
}

/// LD2 blinks at 1 Hz while the executor runs.
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    loop {
        led.toggle();
        Timer::after(Duration::from_millis(500)).await;
    }
}

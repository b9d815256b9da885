//! Real board: the compensator on a NUCLEO-F446RE (STM32F446RE, Cortex-M4F).
//! Pin map and wiring: boards/nucleo-f446re/README.md.
//!
//! `cargo flash` (alias in .cargo/config.toml) builds in release, flashes over
//! the on-board ST-LINK with probe-rs and shows the defmt log.
#![no_std]
#![no_main]

mod model_flash;
mod onewire;
mod probe_adc;
mod rtu_port;
mod safety;

use core::cell::RefCell;
use defmt::{info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::flash::Flash;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::time::Hertz;
use embassy_stm32::usart::{self, Uart};
use embassy_stm32::{bind_interrupts, dma, peripherals, Config};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_time::{Duration, Instant, Timer};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::{self, Calibration, ProbeConfig};
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp::fault;

const SYSCLK_HZ: u32 = 168_000_000;
/// Modbus unit address and baud rate at power-on.
const UNIT: u8 = 1;
const BAUD: u32 = 115_200;

bind_interrupts!(struct Irqs {
    USART1 => usart::InterruptHandler<peripherals::USART1>;
    DMA2_STREAM7 => dma::InterruptHandler<peripherals::DMA2_CH7>;
    DMA2_STREAM2 => dma::InterruptHandler<peripherals::DMA2_CH2>;
});

/// The application state shared by the measurement and Modbus tasks (never
/// locked across an await).
static APP: BlockingMutex<CriticalSectionRawMutex, RefCell<Option<App<model_flash::SlotFlash>>>> =
    BlockingMutex::new(RefCell::new(None));
/// One acquisition cycle per second: 20 sensors take 0.96 s on the bus
/// (BENCHMARKS.md, sensor acquisition).
const CYCLE_PERIOD: Duration = Duration::from_secs(1);
/// The bus is searched again every this many cycles (one minute).
const REDISCOVER_CYCLES: u32 = 60;

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

/// Boot (1-Wire search, sensor configuration, model load) must be done
/// within this long; until then the watchdog is fed unconditionally.
const BOOT_DEADLINE_MS: u64 = 20_000;

/// Sets everything up, then stays as the watchdog feeder: `main` never
/// returns, and an initialisation that fails is a fault (record + reset),
/// never a silent exit.
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clock_config());
    info!("thermocomp on NUCLEO-F446RE, 168 MHz");
    safety::note_watchdog_reset();
    let mut watchdog =
        embassy_stm32::wdg::IndependentWatchdog::new(p.IWDG, safety::WATCHDOG_TIMEOUT_US);
    watchdog.unleash();
    let led = Output::new(p.PA5, Level::Low, Speed::Low);
    let bus = onewire::new_bus(p.PC7, SYSCLK_HZ);
    let probe = probe_adc::ProbeInput::new(p.ADC1, p.PA0);
    let flash = model_flash::SlotFlash::new(Flash::new_blocking(p.FLASH));
    let mut uart_config = usart::Config::default();
    uart_config.baudrate = BAUD;
    let uart = match Uart::new(
        p.USART1,
        p.PA10,
        p.PA9,
        p.DMA2_CH7,
        p.DMA2_CH2,
        Irqs,
        uart_config,
    ) {
        Ok(u) => u,
        Err(e) => {
            defmt::error!("USART1 configuration refused: {}", e);
            fault::fault::<safety::Nucleo>(fault::kind::INIT_FAILED, 0, fault::init_step::UART)
        }
    };
    let driver_enable = Output::new(p.PA8, Level::Low, Speed::Medium);
    let port = rtu_port::Rs485Port::new(uart, driver_enable);
    match (heartbeat(led), acquisition(bus, probe, flash), modbus(port)) {
        (Ok(t1), Ok(t2), Ok(t3)) => {
            spawner.spawn(t1);
            spawner.spawn(t2);
            spawner.spawn(t3);
        }
        _ => {
            defmt::error!("tasks could not be spawned");
            fault::fault::<safety::Nucleo>(fault::kind::INIT_FAILED, 0, fault::init_step::SPAWN)
        }
    }
    feed_watchdog(watchdog).await
}

/// Feeds the IWDG while booting (up to [`BOOT_DEADLINE_MS`]), then only when
/// both the measurement loop and the Modbus task made progress
/// ([`thermocomp::watchdog::Feeder`]).
async fn feed_watchdog(
    mut watchdog: embassy_stm32::wdg::IndependentWatchdog<'static, peripherals::IWDG>,
) -> ! {
    // Each look also drives a flash commit in progress (erase outside the
    // lock, then programming): `App::poll_flash`.
    let progress = || {
        APP.lock(|a| {
            a.borrow_mut().as_mut().map(|app| {
                app.poll_flash();
                app.progress
            })
        })
    };
    let mut feeder: Option<thermocomp::watchdog::Feeder> = None;
    loop {
        Timer::after(Duration::from_millis(safety::FEED_CHECK_MS)).await;
        match (progress(), feeder.as_mut()) {
            (Some(p), Some(f)) => match f.check(&p) {
                Ok(()) => {
                    safety::set_watchdog_hint(0);
                    watchdog.pet();
                }
                Err(bits) => safety::set_watchdog_hint(bits),
            },
            (Some(p), None) => {
                feeder = Some(thermocomp::watchdog::Feeder::new(&p));
                watchdog.pet();
            }
            (None, _) if Instant::now().as_millis() < BOOT_DEADLINE_MS => watchdog.pet(),
            (None, _) => {}
        }
    }
}

/// Modbus RTU server: the application's loop on this board's port.
#[embassy_executor::task]
async fn modbus(mut port: rtu_port::Rs485Port) {
    thermocomp::app::serve_modbus::<safety::Nucleo, _, _, _>(&mut port, &APP, || {
        Instant::now().as_millis()
    })
    .await
}

type Bus =
    thermocomp::acquisition::bitbang::BitBangBus<onewire::DqPin<'static>, onewire::CycleDelay>;

/// Sensors: discover, set 12-bit resolution, then one cycle per second with
/// the probe read alongside.
#[embassy_executor::task]
async fn acquisition(
    mut bus: Bus,
    mut probe_input: probe_adc::ProbeInput<'static>,
    flash: model_flash::SlotFlash,
) {
    // The channel map stored with the model first: a search then only adds
    // new sensors on free channels, never renumbers the known ones.
    let mut app = App::new(flash, model_flash::SLOT_SIZE, UNIT, BAUD, ChannelMap::new());
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), app.channel_map());
    match acq.discover(&mut bus).await {
        Ok(n) => info!("1-Wire: {} sensor(s) found", n),
        Err(e) => warn!("1-Wire search failed: {}", e),
    }
    if !matches!(acq.configure(&mut bus).await, Ok(true)) {
        warn!("1-Wire: could not set the resolution (no sensor answered)");
    }
    app.update_channel_map(*acq.map());
    let record = fault::recorded::<safety::Nucleo>();
    if let Some(r) = record {
        warn!(
            "fault record: {} at pc={:x}, uptime {} ms, fault #{}, detail {:x}",
            fault::kind::name(r.kind),
            r.pc,
            r.uptime_ms,
            r.count,
            r.detail
        );
    }
    app.set_fault_record(record);
    if let Some(model) = app.compensation.model() {
        let (cycles, runs) = step_cycles(model.clone());
        info!(
            "one compensator step of the stored model: {} cycles (DWT, mean of {} steps) = {} us at 168 MHz; QEMU counts instructions for the same step (BENCHMARKS.md)",
            cycles,
            runs,
            cycles / (SYSCLK_HZ / 1_000_000)
        );
    }
    info!(
        "model: version {} crc {:x}",
        app.snapshot.model_version, app.snapshot.model_crc
    );
    APP.lock(|a| *a.borrow_mut() = Some(app));
    // Eddy-current probe: 2 mm range over 0..10 V -> 4096 codes after the divider.
    let probe_config = Calibration::linear(0, 20_000, 4096).map(|calibration| ProbeConfig {
        oversample: 64,
        saturation_margin: 8,
        calibration,
        min_tenth_um: 0,
        max_tenth_um: 20_000,
    });
    let mut cycles = 0u32;
    loop {
        let start = Instant::now();
        let now_ms = start.as_millis();
        cycles = cycles.wrapping_add(1);
        if cycles.is_multiple_of(REDISCOVER_CYCLES) {
            // Sensors added at run time go to free channels (reported in
            // input registers 172-173); missing ones keep their channel and
            // read "no presence" (170-171), never another sensor's value.
            if acq.discover(&mut bus).await.is_ok() {
                APP.lock(|a| {
                    if let Some(app) = a.borrow_mut().as_mut() {
                        app.update_channel_map(*acq.map());
                    }
                });
            }
        }
        let report = acq.cycle(&mut bus, &mut embassy_time::Delay, now_ms).await;
        let out = APP.lock(|a| {
            a.borrow_mut()
                .as_mut()
                .map(|app| app.cycle(&acq, now_ms, now_ms, None))
        });
        info!(
            "cycle: {} ok, {} faulty, {} retries; status {:x} corrections {}",
            report.ok,
            report.faulty,
            report.retries,
            out.map(|o| o.status),
            out.map(|o| o.corrections)
        );
        if let Some(cfg) = &probe_config {
            let reading = probe::measure(&mut probe_input, cfg).await;
            APP.lock(|a| {
                if let Some(app) = a.borrow_mut().as_mut() {
                    app.set_probe(&reading);
                }
            });
            info!("probe: {} {}", reading.state, reading.tenth_um);
        }
        Timer::at(start + CYCLE_PERIOD).await;
    }
}

/// Mean DWT cycle count of one `Compensator::step` of `model` at mid-range
/// inputs (all sensors 25 °C, 6000 rpm), measured on this chip at boot, with
/// flash wait states and the ART accelerator as they are in operation.
fn step_cycles(model: thermocomp_core::Model) -> (u32, u32) {
    use thermocomp_core::limits::{MAX_AXES, MAX_SENSORS};
    use thermocomp_core::{Compensator, StepInput};
    const RUNS: u32 = 100;
    // SAFETY: enabling the cycle counter (DEMCR.TRCENA, DWT.CTRL.CYCCNTENA)
    // at boot; nothing else on this board uses the DWT.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let n = model.sensors.len();
    let temps = [Some(400i32); MAX_SENSORS];
    let positions = [0i32; MAX_AXES];
    let mut comp = Compensator::new(Some(model));
    let mut now = 0u64;
    let start = cortex_m::peripheral::DWT::cycle_count();
    for _ in 0..RUNS {
        now += 1000;
        let input = StepInput {
            now_ms: now,
            temps: &temps[..n],
            spindle_rpm: 6000,
            positions: &positions,
            stale: false,
        };
        core::hint::black_box(comp.step(core::hint::black_box(&input)));
    }
    let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start);
    (cycles / RUNS, RUNS)
}

/// LD2 blinks at 1 Hz while the executor runs.
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    loop {
        led.toggle();
        Timer::after(Duration::from_millis(500)).await;
    }
}

//! Real board: the compensator on a NUCLEO-F446RE (STM32F446RE, Cortex-M4F).
//! Pin map and wiring: boards/nucleo-f446re/README.md.
//!
//! `cargo flash` (alias in .cargo/config.toml) builds with the firmware profile, flashes over
//! the on-board ST-LINK with probe-rs and shows the defmt log.
#![no_std]
#![no_main]

mod early;
mod model_flash;
mod onewire;
mod probe_adc;
mod rtu_port;
mod safety;
use board_support::stack;

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
use embassy_time::{Delay, Duration, Instant, Timer};
use static_cell::StaticCell;
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::{self, Calibration, ProbeConfig, ProbeReading};
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp::fault;
use thermocomp::hal::clock::Clock;
use thermocomp::runtime::{self, CycleDone, CycleInput, CycleSource, SharedApp};

const SYSCLK_HZ: u32 = 168_000_000;
/// Modbus unit address and baud rate at power-on.
const UNIT: u8 = 1;
const BAUD: u32 = 115_200;

bind_interrupts!(struct Irqs {
    USART1 => usart::InterruptHandler<peripherals::USART1>;
    DMA2_STREAM7 => dma::InterruptHandler<peripherals::DMA2_CH7>;
    DMA2_STREAM2 => dma::InterruptHandler<peripherals::DMA2_CH2>;
});

/// The application state the measurement, Modbus and watchdog loops share:
/// built in place once, before the tasks start (never locked across an await).
type Shared = SharedApp<CriticalSectionRawMutex, model_flash::SlotFlash>;
static APP: StaticCell<Shared> = StaticCell::new();
/// One acquisition cycle per second: 20 sensors take 0.96 s on the bus
/// (BENCHMARKS.md, sensor acquisition).
const CYCLE_PERIOD: Duration = Duration::from_secs(1);
/// Uptime until which the feeder pets the IWDG while the board boots
/// (1-Wire search and configuration of up to 20 sensors, the boot-time
/// step count: about 1 s). After it, a boot that has not finished is left
/// to the IWDG (10 s nominal, 6.8 s at the fastest LSI): no unconditional
/// feeding beyond the boot's own need.
const BOOT_WINDOW_MS: u64 = 3_000;
/// The bus is searched again every this many cycles (one minute).
const REDISCOVER_CYCLES: u32 = 60;

/// 168 MHz from the ST-LINK's 8 MHz MCO (HSE bypass), or from the 16 MHz
/// HSI when the HSE did not start ([`early::probe_hse`]). 180 MHz would need
/// the regulator's over-drive mode for no gain the compensator needs.
fn clock_config(source: early::ClockSource) -> Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    let prediv = match source {
        early::ClockSource::Hse => {
            config.rcc.hse = Some(Hse {
                freq: Hertz(8_000_000),
                mode: HseMode::Bypass,
            });
            config.rcc.pll_src = PllSource::HSE;
            PllPreDiv::DIV4
        }
        early::ClockSource::HsiFallback => {
            config.rcc.hse = None;
            config.rcc.pll_src = PllSource::HSI;
            PllPreDiv::DIV8
        }
    };
    // 2 MHz into the PLL either way: × 168 = 336 MHz, / 2 = 168 MHz, / 7 = 48 MHz.
    config.rcc.pll = Some(Pll {
        prediv,
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

/// Sets everything up, then stays as the watchdog feeder: `main` never
/// returns, and an initialisation that fails is a fault (record + reset),
/// never a silent exit. Boot order (issue 30): the bus released, the
/// watchdog running, the HSE probed with a timeout ([`early`]), then the
/// clock init.
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    early::release_bus();
    early::start_watchdog(safety::WATCHDOG_TIMEOUT_US);
    let source = early::probe_hse();
    let p = embassy_stm32::init(clock_config(source));
    // The same pin as an embassy output, still low.
    let driver_enable = Output::new(p.PA8, Level::Low, Speed::Medium);
    match source {
        early::ClockSource::Hse => info!("thermocomp on NUCLEO-F446RE, 168 MHz from the HSE"),
        early::ClockSource::HsiFallback => warn!(
            "thermocomp on NUCLEO-F446RE, 168 MHz from the HSI: the HSE did not start within {} ms",
            early::HSE_TIMEOUT_MS
        ),
    }
    safety::note_watchdog_reset();
    let mut watchdog = safety::Iwdg::start(p.IWDG);
    let led = Output::new(p.PA5, Level::Low, Speed::Low);
    let bus = onewire::new_bus(p.PC7, SYSCLK_HZ);
    let probe = probe_adc::ProbeInput::new(p.ADC1, p.PA0);
    let flash = model_flash::SlotFlash::new(Flash::new_blocking(p.FLASH));
    let mut uart_config = usart::Config::default();
    uart_config.baudrate = BAUD;
    let (tx, rx) = match Uart::new(
        p.USART1,
        p.PA10,
        p.PA9,
        p.DMA2_CH7,
        p.DMA2_CH2,
        Irqs,
        uart_config,
    ) {
        Ok(u) => u.split(),
        Err(e) => {
            defmt::error!("USART1 configuration refused: {}", e);
            fault::fault::<safety::Nucleo>(fault::kind::INIT_FAILED, 0, fault::init_step::UART)
        }
    };
    static RX_RING: StaticCell<[u8; rtu_port::RX_RING]> = StaticCell::new();
    let Some(ring) = RX_RING.try_init([0; rtu_port::RX_RING]) else {
        fault::fault::<safety::Nucleo>(fault::kind::INIT_FAILED, 0, fault::init_step::BUFFER)
    };
    let port = rtu_port::Rs485Port::new(tx, rx.into_ring_buffered(ring), driver_enable, BAUD);
    let app = build_app(flash);
    // Loaded in place: the model never sits on the stack inside an app.
    app.lock(|a| a.borrow_mut().load_stored());
    match (
        heartbeat(led),
        acquisition(app, bus, probe),
        modbus(app, port),
    ) {
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
    runtime::watchdog_loop(app, &mut watchdog, &Uptime, &mut Delay, BOOT_WINDOW_MS).await
}

/// The app state in its static: the model, settings and channel map
/// stored in the slots (the first search only adds new sensors on free
/// channels, never renumbers the known ones). Not inlined, so that its
/// temporaries take stack only while it runs, not in `main`'s frame, which
/// lives on as the watchdog feeder.
#[inline(never)]
fn build_app(flash: model_flash::SlotFlash) -> &'static Shared {
    APP.init_with(|| {
        BlockingMutex::new(RefCell::new(App::unloaded(
            flash,
            model_flash::SLOT_SIZE,
            UNIT,
            BAUD,
            ChannelMap::new(),
        )))
    })
}

/// Milliseconds since boot (embassy-time).
struct Uptime;

impl Clock for Uptime {
    fn now_ms(&self) -> u64 {
        Instant::now().as_millis()
    }
}

/// Modbus RTU server: the application's loop on this board's port.
#[embassy_executor::task]
async fn modbus(app: &'static Shared, mut port: rtu_port::Rs485Port) {
    runtime::modbus_loop::<safety::Nucleo, _, _, _, _>(&mut port, app, &Uptime).await
}

type Bus =
    thermocomp::acquisition::bitbang::BitBangBus<onewire::DqPin<'static>, onewire::CycleDelay>;

/// Sensors: discover, set 12-bit resolution, then one cycle per second with
/// the probe read alongside.
#[embassy_executor::task]
async fn acquisition(
    app: &'static Shared,
    mut bus: Bus,
    probe_input: probe_adc::ProbeInput<'static>,
) {
    let map = app.lock(|a| a.borrow().channel_map());
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), map);
    let start = runtime::start_sensors(&mut acq, &mut bus, None).await;
    match start.found {
        Ok(n) => info!("1-Wire: {} sensor(s) found", n),
        Err(e) => warn!("1-Wire search failed: {}", e),
    }
    if !start.configured {
        warn!("1-Wire: could not set the resolution (no sensor answered)");
    }
    // Timed before the boot report changes anything: the app's compensator
    // is then restarted from the slots exactly as it was loaded.
    let step = app.lock(|a| step_cycles(&mut a.borrow_mut()));
    let boot = runtime::boot_report::<safety::Nucleo, _, _>(app, *acq.map());
    if let Some(r) = boot.fault {
        warn!(
            "fault record: {} at pc={:x}, uptime {} ms, fault #{}, detail {:x}",
            fault::kind::name(r.kind),
            r.pc,
            r.uptime_ms,
            r.count,
            r.detail
        );
    }
    if let Some((cycles, runs)) = step {
        info!(
            "one compensator step of the stored model: {} cycles (DWT, mean of {} steps) = {} us at 168 MHz; QEMU counts instructions for the same step (BENCHMARKS.md)",
            cycles,
            runs,
            cycles / (SYSCLK_HZ / 1_000_000)
        );
    }
    info!(
        "model: version {} crc {:x}; stack high-water so far {} B",
        boot.model_version,
        boot.model_crc,
        stack::high_water()
    );
    let mut source = FieldCycles {
        next: None,
        started_ms: 0,
        probe_input,
        // Eddy-current probe: 2 mm range over 0..10 V -> 4096 codes after the divider.
        probe_config: Calibration::linear(0, 20_000, 4096).map(|calibration| ProbeConfig {
            oversample: 64,
            saturation_margin: 8,
            calibration,
            min_tenth_um: 0,
            max_tenth_um: 20_000,
        }),
    };
    runtime::measurement_loop(
        app,
        &mut acq,
        &mut bus,
        &mut Delay,
        &mut source,
        REDISCOVER_CYCLES,
    )
    .await
}

/// The field's cycles: one per [`CYCLE_PERIOD`], at the board's uptime, the
/// probe read after each.
struct FieldCycles {
    next: Option<Instant>,
    started_ms: u64,
    probe_input: probe_adc::ProbeInput<'static>,
    probe_config: Option<ProbeConfig>,
}

impl CycleSource<Bus> for FieldCycles {
    async fn next_cycle(&mut self, _bus: &mut Bus) -> Option<CycleInput> {
        if let Some(at) = self.next {
            Timer::at(at).await;
        }
        let start = Instant::now();
        self.next = Some(start + CYCLE_PERIOD);
        self.started_ms = start.as_millis();
        Some(CycleInput {
            now_ms: self.started_ms,
            spindle_override: None,
        })
    }

    fn uptime_ms(&mut self, _input: &CycleInput) -> u64 {
        self.started_ms
    }

    fn cycle_done(&mut self, done: &CycleDone<'_>) {
        info!(
            "cycle: {} ok, {} faulty, {} retries; status {:x} corrections {}",
            done.report.ok,
            done.report.faulty,
            done.report.retries,
            done.out.status,
            done.out.corrections
        );
        if done.cycle.is_multiple_of(REDISCOVER_CYCLES) {
            info!("stack high-water: {} B", stack::high_water());
        }
    }

    async fn probe(&mut self, reference_samples: Option<u16>) -> Option<ProbeReading> {
        let mut cfg = *self.probe_config.as_ref()?;
        // A probe reference (command 12) averages holding register 41's samples.
        cfg.oversample = reference_samples.unwrap_or(cfg.oversample);
        let reading = probe::measure(&mut self.probe_input, &cfg).await;
        info!("probe: {} {}", reading.state, reading.tenth_um);
        Some(reading)
    }
}

/// Mean DWT cycle count of one `Compensator::step` of the stored model at
/// mid-range inputs (all sensors 25 °C, 6000 rpm), measured on this chip at
/// boot, with flash wait states and the ART accelerator as they are in
/// operation. It steps the app's own compensator (no copy of the model),
/// then restarts it as it was loaded ([`App::restart_compensation`]). `None`: no model. Not inlined:
/// its buffers stay out of the measurement task's frame.
#[inline(never)]
fn step_cycles<F: thermocomp::hal::flash::BackgroundErase>(app: &mut App<F>) -> Option<(u32, u32)> {
    use thermocomp_core::limits::{MAX_AXES, MAX_SENSORS};
    use thermocomp_core::StepInput;
    const RUNS: u32 = 100;
    let n = app.model()?.sensors.len();
    // SAFETY: enabling the cycle counter (DEMCR.TRCENA, DWT.CTRL.CYCCNTENA)
    // at boot; nothing else on this board uses the DWT.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let temps = [Some(400i32); MAX_SENSORS];
    let positions = [0i32; MAX_AXES];
    let comp = app.compensator();
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
    app.restart_compensation();
    Some((cycles / RUNS, RUNS))
}

/// LD2 blinks at 1 Hz while the executor runs.
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    loop {
        led.toggle();
        Timer::after(Duration::from_millis(500)).await;
    }
}

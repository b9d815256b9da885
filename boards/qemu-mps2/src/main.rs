//! Bench board: the compensator on QEMU's mps2-an386 (Cortex-M4F, 25 MHz).
//!
//! Wiring (as QEMU emulates it):
//! - console and exit status: semihosting (`-semihosting-config enable=on`);
//! - RS-485 Modbus port: CMSDK UART0 at 0x4000_4000, on a host socket or pty;
//! - sensors: emulated, replaying a run CSV from the host (semihosting file);
//! - time: SysTick at 1 kHz driving embassy-time.
//!
//! The command line (QEMU `-append`) picks what the firmware does:
//! - `selftest [golden.bin]`: executor, timers and the math core's golden
//!   vectors; exits 0 when every check passes, 1 otherwise;
//! - `replay <run.csv> [model.img]`: acquire every sample of the trace on the
//!   emulated bus, compensate it with the model (none: "no model", zero
//!   correction), log each correction, exit 0 at its end (3 on a bad trace);
//! - `serve <run.csv> [model.img|-] [pace_ms]`: the Modbus RTU bench. The
//!   trace is acquired and compensated one sample every `pace_ms` (default
//!   100) while UART0 serves the register map; after the last sample the
//!   board keeps serving (a host test or the demo script stops QEMU).
//!   An optional fourth word `swap=<sensor>@<row>` replaces that emulated
//!   sensor by a new one (another ROM code) at that trace row. A fault in
//!   this mode resets the board (fault record, as in the field); the CMSDK
//!   watchdog runs.
//! - `bench [golden.bin] [model.img]`: instruction counts (run QEMU with `-icount
//!   shift=0`) of the calibration loop and, with the golden file's model, of
//!   one full evaluation and one compensator step, printed as one JSON line.
#![no_std]
#![no_main]

mod cycles;
mod emulated_bus;
mod executor;
mod flash;
mod host_trace;
mod rtu_port;
mod safety;
mod semihost;
mod time_driver;
mod uart;

use core::sync::atomic::{AtomicU32, Ordering};

use core::cell::RefCell;
use core::fmt::Write as _;
use cortex_m_rt::{entry, exception};
use embassy_executor::Spawner;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_time::{Duration, Instant, Timer};
use static_cell::StaticCell;
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{
    AcquisitionConfig, CycleReport, TemperatureAcquisition,
};
use thermocomp::app::App;
use thermocomp::compensation::{Compensation, PlcInputs};
use thermocomp::fault;
use thermocomp::trace::TraceSample;
use thermocomp_core::limits::{MAX_AXES, MAX_IMAGE_BYTES, MAX_SENSORS};
use thermocomp_core::{Compensator, Model, StepInput, StepOutput};

/// Exit codes of the bench firmware (the host tests check them).
pub mod exit_code {
    pub const OK: u32 = 0;
    pub const SELFTEST_FAILED: u32 = 1;
    pub const BAD_COMMAND_LINE: u32 = 2;
    pub const TRACE_ERROR: u32 = 3;
    pub const PANIC: u32 = 101;
}

static EXECUTOR: StaticCell<executor::Executor> = StaticCell::new();
static TICKS_SEEN: AtomicU32 = AtomicU32::new(0);

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        semihost::exit(exit_code::PANIC)
    };
    time_driver::init(core.SYST);
    log!("thermocomp bench board (mps2-an386) up");
    let executor = EXECUTOR.init(executor::Executor::new());
    executor.run(|spawner| {
        static CMDLINE: StaticCell<[u8; 256]> = StaticCell::new();
        let buf = CMDLINE.init([0; 256]);
        let cmdline = semihost::command_line(buf).unwrap_or("");
        dispatch(spawner, cmdline);
    })
}

fn dispatch(spawner: Spawner, cmdline: &'static str) {
    // QEMU's semihosting command line is the kernel's path, then `-append`.
    let mut words = cmdline.split_ascii_whitespace().skip(1);
    let mode = words.next().unwrap_or("selftest");
    let arg = words.next();
    match mode {
        "selftest" => match (ticker(), selftest(arg)) {
            (Ok(t1), Ok(t2)) => {
                spawner.spawn(t1);
                spawner.spawn(t2);
            }
            _ => semihost::exit(exit_code::PANIC),
        },
        "replay" => match arg.map(|a| replay(a, words.next())) {
            Some(Ok(task)) => spawner.spawn(task),
            Some(Err(_)) => semihost::exit(exit_code::PANIC),
            None => {
                log!("replay needs a run CSV path");
                semihost::exit(exit_code::BAD_COMMAND_LINE)
            }
        },
        "serve" => {
            let Some(trace) = arg else {
                log!("serve needs a run CSV path");
                semihost::exit(exit_code::BAD_COMMAND_LINE)
            };
            let model = words.next().filter(|m| *m != "-");
            let pace_ms = words.next().and_then(|p| p.parse().ok()).unwrap_or(100);
            // `swap=<sensor>@<row>`: the emulated sensor is replaced by a new
            // one (another ROM code) at that trace row.
            let swap = words.next().and_then(|w| {
                let (k, row) = w.strip_prefix("swap=")?.split_once('@')?;
                Some((k.parse::<usize>().ok()?, row.parse::<u32>().ok()?))
            });
            // From here on a fault resets the board, as in the field.
            safety::FIELD_MODE.store(true, Ordering::Relaxed);
            match (
                serve_measure(trace, model, pace_ms, swap),
                serve_modbus(),
                watchdog_feeder(),
            ) {
                (Ok(t1), Ok(t2), Ok(t3)) => {
                    spawner.spawn(t1);
                    spawner.spawn(t2);
                    spawner.spawn(t3);
                }
                _ => fault::fault::<safety::Bench>(
                    fault::kind::INIT_FAILED,
                    0,
                    fault::init_step::SPAWN,
                ),
            }
        }
        "bench" => match bench(arg, words.next()) {
            Ok(task) => spawner.spawn(task),
            Err(_) => semihost::exit(exit_code::PANIC),
        },
        other => {
            log!(
                "unknown mode {:?}; use selftest [golden.bin] | replay <run.csv> [model.img] | bench [golden.bin]",
                other
            );
            semihost::exit(exit_code::BAD_COMMAND_LINE)
        }
    }
}

/// Counts 10 ms timer periods, so the self-test can check that a second task
/// and the time driver really run.
#[embassy_executor::task]
async fn ticker() {
    loop {
        Timer::after(Duration::from_millis(10)).await;
        TICKS_SEEN.fetch_add(1, Ordering::Relaxed);
    }
}

#[embassy_executor::task]
async fn selftest(golden_path: Option<&'static str>) {
    let mut failures = 0u32;
    // 0. Whose clock: under `-icount shift=0,sleep=off` (the host tests) a
    // virtual nanosecond is one instruction, so the 3000-instruction loop
    // reads 3000, and every time below is virtual: the verdict cannot depend
    // on the host's load. Without it, time follows the host's clock.
    let loop_ns = cycles::instructions_x100(100, known_loop) / 100;
    let virtual_time = loop_ns.abs_diff(3000) <= 15;
    log!(
        "selftest clock: 3000-instruction loop took {} ns: {}",
        loop_ns,
        if virtual_time {
            "virtual (icount)"
        } else {
            "host-timed (no -icount)"
        }
    );
    // 1. Timers and a second task: 200 ms must pass as ~20 ticker periods;
    // exactly on time when time is virtual.
    let start = Instant::now();
    Timer::after(Duration::from_millis(200)).await;
    let elapsed = start.elapsed().as_millis();
    let ticks = TICKS_SEEN.load(Ordering::Relaxed);
    let timers_ok = if virtual_time {
        elapsed == 200 && (19..=20).contains(&ticks)
    } else {
        (200..=210).contains(&elapsed) && (18..=21).contains(&ticks)
    };
    log!(
        "selftest timers: {} ms elapsed, {} ticker periods: {}",
        elapsed,
        ticks,
        pass(timers_ok)
    );
    failures += u32::from(!timers_ok);

    // 2. The math core's golden vectors, produced on the host.
    if let Some(path) = golden_path {
        failures += u32::from(!golden::check_file(path));
    }
    log!("selftest: {} failure(s)", failures);
    semihost::exit(if failures == 0 {
        exit_code::OK
    } else {
        exit_code::SELFTEST_FAILED
    })
}

fn pass(ok: bool) -> &'static str {
    if ok {
        "pass"
    } else {
        "FAIL"
    }
}

#[embassy_executor::task]
async fn replay(path: &'static str, model_path: Option<&'static str>) {
    let mut trace = open_trace(path);
    let channels = trace.header().channels();
    log!("replaying {} ({} temperature channels)", path, channels);
    let mut sensors = Sensors::new(channels).await;
    let model = model_path.and_then(load_model);
    let mut compensation = Compensation::new(model, sensors.acquisition.map());
    let mut rows = 0u32;
    while let Some(sample) = next_sample_or_exit(&mut trace) {
        rows += 1;
        let report = sensors.acquire(&sample).await;
        let plc = PlcInputs {
            spindle_rpm: sample.spindle_rpm.unwrap_or(0),
            ..PlcInputs::default()
        };
        let out = compensation.step(&sensors.acquisition, sample.time_ms, &plc);
        let ch0 = sensors.acquisition.value(0, sample.time_ms);
        log_correction(
            &compensation,
            sample.time_ms,
            &report,
            (ch0.usable(), ch0.state),
            plc.spindle_rpm,
            &out,
        );
    }
    log!("replay done: {} samples", rows);
    semihost::exit(exit_code::OK)
}

/// One line per sample: time, sensors, each direction's served correction
/// in µm (and the model's prediction when limits changed it), status bits.
fn log_correction(
    c: &Compensation,
    t_ms: u64,
    report: &CycleReport,
    ch0: (Option<i16>, thermocomp::process_image::ChannelState),
    rpm: i32,
    out: &StepOutput,
) {
    let mut line: heapless::String<200> = heapless::String::new();
    let _ = write!(
        line,
        "t={} ms ok={} faulty={} T0={:?} {:?} rpm={} |",
        t_ms, report.ok, report.faulty, ch0.0, ch0.1, rpm
    );
    if let Some(m) = c.model() {
        for d in 0..m.directions.len() {
            let _ = write!(
                line,
                " {}={}",
                m.direction_name(d),
                Micrometres(out.corrections[d])
            );
            if out.corrections[d] != out.predicted[d] {
                let _ = write!(line, "({})", Micrometres(out.predicted[d]));
            }
        }
    }
    log!(
        "{} um status={:#06x}{}",
        line,
        out.status,
        StatusNames(out.status)
    );
}

/// 0.1 µm as a signed decimal µm value.
struct Micrometres(i32);

impl core::fmt::Display for Micrometres {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let sign = if self.0 < 0 { "-" } else { "+" };
        let a = self.0.unsigned_abs();
        write!(f, "{}{}.{}", sign, a / 10, a % 10)
    }
}

struct StatusNames(u16);

impl core::fmt::Display for StatusNames {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use thermocomp_core::compensator::status::*;
        const NAMES: [(u16, &str); 9] = [
            (VALID, "valid"),
            (SENSOR_FAULT, "sensor-fault"),
            (NO_MODEL, "no-model"),
            (CLAMPED, "clamped"),
            (WARMING_UP, "warming-up"),
            (STALE_INPUTS, "stale"),
            (OUT_OF_ENVELOPE, "out-of-envelope"),
            (RATE_LIMITED, "rate-limited"),
            (DEGRADED, "degraded"),
        ];
        for (bit, name) in NAMES {
            if self.0 & bit != 0 {
                write!(f, " {}", name)?;
            }
        }
        Ok(())
    }
}

/// Read a whole host file into `buf`; None (logged) when it cannot.
fn read_host_file<'a>(path: &str, buf: &'a mut [u8]) -> Option<&'a [u8]> {
    let mut path_nul = [0u8; 200];
    let dst = path_nul.get_mut(..path.len())?;
    dst.copy_from_slice(path.as_bytes());
    let Some(mut f) = semihost::HostFile::open(&path_nul[..=path.len()]) else {
        log!("cannot open {}", path);
        return None;
    };
    let mut n = 0;
    loop {
        let rest = buf.get_mut(n..)?;
        if rest.is_empty() {
            log!("{} is larger than {} bytes", path, n);
            return None;
        }
        match f.read(rest) {
            Ok(0) => return buf.get(..n),
            Ok(k) => n += k,
            Err(()) => {
                log!("cannot read {}", path);
                return None;
            }
        }
    }
}

/// Load and validate a model image from the host; a bad image is logged and
/// the board serves "no model".
fn load_model(path: &str) -> Option<Model> {
    static BUF: StaticCell<[u8; MAX_IMAGE_BYTES]> = StaticCell::new();
    let buf = BUF.try_init([0; MAX_IMAGE_BYTES])?;
    let bytes = read_host_file(path, buf)?;
    match Model::parse(bytes) {
        Ok(m) => {
            log!(
                "model {} loaded: version {}, crc {:#010x}, {} directions",
                path,
                m.model_version,
                m.crc,
                m.directions.len()
            );
            Some(m)
        }
        Err(e) => {
            log!("model {} refused: {:?}; serving no model", path, e);
            None
        }
    }
}

/// The application state both serve tasks share (never locked across an await).
type BenchApp = App<flash::RamNor>;
static APP: BlockingMutex<CriticalSectionRawMutex, RefCell<Option<BenchApp>>> =
    BlockingMutex::new(RefCell::new(None));

/// Modbus unit address and baud rate the bench board starts with.
const UNIT: u8 = 1;
const BAUD: u32 = 115_200;

#[embassy_executor::task]
async fn serve_measure(
    path: &'static str,
    model_path: Option<&'static str>,
    pace_ms: u64,
    swap: Option<(usize, u32)>,
) {
    let mut trace = open_trace(path);
    let channels = trace.header().channels();
    let mut sensors = Sensors::new(channels).await;
    let Some(flash) = flash::RamNor::take() else {
        fault::fault::<safety::Bench>(fault::kind::INIT_FAILED, 0, fault::init_step::FLASH)
    };
    let mut app = App::new(
        flash,
        flash::SLOT_SIZE,
        UNIT,
        BAUD,
        *sensors.acquisition.map(),
    );
    // The bench maps its emulated sensors in trace-column order; stored with
    // the model like a field board's map (by the programming below, when a
    // model is given; else in the background).
    app.update_channel_map(*sensors.acquisition.map());
    if let Some(p) = model_path {
        static BUF: StaticCell<[u8; MAX_IMAGE_BYTES]> = StaticCell::new();
        let Some(buf) = BUF.try_init([0; MAX_IMAGE_BYTES]) else {
            fault::fault::<safety::Bench>(fault::kind::INIT_FAILED, 0, fault::init_step::BUFFER)
        };
        match read_host_file(p, buf).map(|img| app.program(img)) {
            Some(Ok(())) => log!("model {} programmed into the flash slots", p),
            other => log!(
                "model {} not programmed ({:?}); serving what the slots hold",
                p,
                other
            ),
        }
    }
    let record = fault::recorded::<safety::Bench>();
    if let Some(r) = record {
        log!(
            "fault record: {} at pc={:#010x}, uptime {} ms, fault #{} since cleared, detail {:#x}",
            fault::kind::name(r.kind),
            r.pc,
            r.uptime_ms,
            r.count,
            r.detail
        );
    }
    app.set_fault_record(record);
    log!(
        "serving Modbus RTU on UART0: unit {}, {} baud, model version {} crc {:#010x}; replaying {} ({} channels), one sample per {} ms",
        UNIT, BAUD, app.snapshot.model_version, app.snapshot.model_crc, path, channels, pace_ms
    );
    APP.lock(|a| *a.borrow_mut() = Some(app));
    let mut rows = 0u32;
    while let Some(sample) = next_sample_or_exit(&mut trace) {
        rows += 1;
        if APP.lock(|a| a.borrow().as_ref().is_some_and(|app| app.stall_requested)) {
            // Test command 9: this loop stops making progress (the executor
            // and the Modbus task go on); the watchdog must notice.
            log!("measurement loop stalled on request (command 9)");
            core::future::pending::<()>().await;
        }
        if swap.is_some_and(|(_, row)| row == rows) {
            if let Some((k, _)) = swap {
                log!("sensor {} replaced by a new one (another ROM code)", k);
                sensors.bus.replace(k);
            }
        }
        if rows.is_multiple_of(REDISCOVER_ROWS) {
            // Search the bus again: a new sensor goes to a free channel.
            if sensors.acquisition.discover(&mut sensors.bus).await.is_ok() {
                let map = *sensors.acquisition.map();
                APP.lock(|a| {
                    if let Some(app) = a.borrow_mut().as_mut() {
                        app.update_channel_map(map);
                    }
                });
            }
        }
        let report = sensors.acquire(&sample).await;
        let uptime = Instant::now().as_millis();
        let out = APP.lock(|a| {
            a.borrow_mut().as_mut().map(|app| {
                app.cycle(
                    &sensors.acquisition,
                    sample.time_ms,
                    uptime,
                    sample.spindle_rpm,
                )
            })
        });
        if let (Some(out), true) = (out, rows % 50 == 1) {
            let ch0 = sensors.acquisition.value(0, sample.time_ms);
            APP.lock(|a| {
                if let Some(app) = a.borrow().as_ref() {
                    log_correction(
                        &app.compensation,
                        sample.time_ms,
                        &report,
                        (ch0.usable(), ch0.state),
                        sample.spindle_rpm.unwrap_or(0),
                        &out,
                    );
                }
            });
        }
        Timer::after(Duration::from_millis(pace_ms)).await;
    }
    log!("trace done: {} samples; still serving", rows);
    // The trace has ended, but the loop is not stalled: it keeps counting
    // (idle) cycles for the watchdog at the same pace.
    loop {
        APP.lock(|a| {
            if let Some(app) = a.borrow_mut().as_mut() {
                app.progress.cycles = app.progress.cycles.wrapping_add(1);
            }
        });
        Timer::after(Duration::from_millis(pace_ms)).await;
    }
}

/// Feeds the watchdog while booting (up to [`BOOT_DEADLINE_MS`]), then only
/// when both the measurement loop and the Modbus task made progress
/// ([`thermocomp::watchdog::Feeder`]).
#[embassy_executor::task]
async fn watchdog_feeder() {
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
    safety::watchdog_start();
    log!(
        "watchdog started: {} ms, fed when both tasks progressed",
        safety::WATCHDOG_TIMEOUT_MS
    );
    let mut feeder: Option<thermocomp::watchdog::Feeder> = None;
    loop {
        Timer::after(Duration::from_millis(safety::FEED_CHECK_MS)).await;
        match (progress(), feeder.as_mut()) {
            (Some(p), Some(f)) => match f.check(&p) {
                Ok(()) => {
                    safety::STALLED.store(0, Ordering::Relaxed);
                    safety::watchdog_feed();
                }
                Err(bits) => safety::STALLED.store(bits, Ordering::Relaxed),
            },
            (Some(p), None) => {
                feeder = Some(thermocomp::watchdog::Feeder::new(&p));
                safety::watchdog_feed();
            }
            (None, _) if Instant::now().as_millis() < BOOT_DEADLINE_MS => safety::watchdog_feed(),
            (None, _) => {}
        }
    }
}

/// The bench searches its bus again every this many trace rows.
const REDISCOVER_ROWS: u32 = 10;

/// Boot (trace, sensor search, model) must be done within this long; until
/// then the watchdog is fed unconditionally.
const BOOT_DEADLINE_MS: u64 = 20_000;

#[embassy_executor::task]
async fn serve_modbus() {
    let mut port = rtu_port::QemuRtuPort::new(BAUD);
    thermocomp::app::serve_modbus::<safety::Bench, _, _, _>(&mut port, &APP, || {
        Instant::now().as_millis()
    })
    .await
}

/// The next sample of a host trace; `None` at its end. A malformed line
/// ends the firmware with TRACE_ERROR (the host tests check the status).
fn next_sample_or_exit(trace: &mut host_trace::HostTrace) -> Option<TraceSample> {
    match trace.next_sample() {
        Ok(sample) => sample,
        Err(e) => {
            log!("trace error: {:?}", e);
            semihost::exit(exit_code::TRACE_ERROR)
        }
    }
}

fn open_trace(path: &str) -> host_trace::HostTrace {
    let mut path_nul = [0u8; 200];
    let Some(dst) = path_nul.get_mut(..path.len()) else {
        log!("trace path too long");
        semihost::exit(exit_code::BAD_COMMAND_LINE)
    };
    dst.copy_from_slice(path.as_bytes());
    match host_trace::HostTrace::open(&path_nul[..=path.len()]) {
        Ok(t) => t,
        Err(e) => {
            log!("cannot open trace {}: {:?}", path, e);
            semihost::exit(exit_code::TRACE_ERROR)
        }
    }
}

/// The emulated DS18B20 bus and the application's real acquisition on it.
struct Sensors {
    bus: emulated_bus::EmulatedBus,
    acquisition: TemperatureAcquisition,
}

impl Sensors {
    /// One emulated sensor per trace column, mapped to channels in column
    /// order (the configured map, as the engineer would persist it), then a
    /// ROM search that must find them all.
    async fn new(channels: usize) -> Sensors {
        let bus = emulated_bus::EmulatedBus::new(channels);
        let mut map = ChannelMap::new();
        for c in 0..channels {
            if map.set(c, bus.rom(c)).is_err() {
                log!("channel map refused channel {}", c);
                semihost::exit(exit_code::SELFTEST_FAILED)
            }
        }
        let mut sensors = Sensors {
            bus,
            acquisition: TemperatureAcquisition::new(
                AcquisitionConfig::default(),
                ChannelMap::new(),
            ),
        };
        match sensors.acquisition.discover(&mut sensors.bus).await {
            Ok(n) if n == channels => {}
            other => {
                log!("ROM search found {:?} of {} sensors", other, channels);
                semihost::exit(exit_code::SELFTEST_FAILED)
            }
        }
        sensors.acquisition.set_map(map);
        if !matches!(
            sensors.acquisition.configure(&mut sensors.bus).await,
            Ok(true)
        ) {
            log!("sensor configuration failed");
            semihost::exit(exit_code::SELFTEST_FAILED)
        }
        sensors
    }

    /// Put the sample's temperatures on the emulated sensors and run one
    /// acquisition cycle at the sample's time.
    async fn acquire(&mut self, sample: &TraceSample) -> CycleReport {
        for (c, t) in sample.temperatures.iter().enumerate() {
            // A value outside i16 cannot come from a DS18B20: the sensor is
            // treated as absent, and acquisition reports it.
            self.bus
                .set_temperature(c, t.and_then(|v| i16::try_from(v).ok()));
        }
        self.acquisition
            .cycle(&mut self.bus, &mut embassy_time::Delay, sample.time_ms)
            .await
    }
}

mod golden {
    use static_cell::StaticCell;

    /// Largest golden file the board reads.
    const MAX_GOLDEN_BYTES: usize = 256 * 1024;
    static BUF: StaticCell<[u8; MAX_GOLDEN_BYTES]> = StaticCell::new();

    /// The golden file's bytes (read once).
    pub fn load(path: &str) -> Option<&'static [u8]> {
        let buf = BUF.try_init([0; MAX_GOLDEN_BYTES])?;
        crate::read_host_file(path, buf)
    }

    /// Run the math core's golden vectors from a host file; true when all pass.
    pub fn check_file(path: &str) -> bool {
        let Some(bytes) = load(path) else {
            return false;
        };
        match thermocomp_core::golden::check(bytes) {
            Ok(n) => {
                crate::log!(
                    "golden vectors {}: {} steps reproduced bit for bit: pass",
                    path,
                    n
                );
                true
            }
            Err(e) => {
                crate::log!("golden vectors {}: {:?}: FAIL", path, e);
                false
            }
        }
    }
}

/// Device interrupts: this machine has no PAC, so every IRQ lands here.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == uart::UART0_RX_IRQ as i16 {
        uart::on_rx_interrupt();
    }
}

#[exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    // SAFETY: a read of the SCB's fault status register.
    let cfsr = unsafe { (*cortex_m::peripheral::SCB::PTR).cfsr.read() };
    log!("hard fault at pc={:#010x} cfsr={:#010x}", frame.pc(), cfsr);
    if safety::FIELD_MODE.load(Ordering::Relaxed) {
        fault::fault::<safety::Bench>(fault::kind::HARD_FAULT, frame.pc(), cfsr)
    }
    semihost::exit(exit_code::PANIC)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    log!("panic: {}", info);
    if safety::FIELD_MODE.load(Ordering::Relaxed) {
        let line = info.location().map_or(0, |l| l.line());
        fault::fault::<safety::Bench>(fault::kind::PANIC, 0, line)
    }
    semihost::exit(exit_code::PANIC)
}

/// A loop of exactly 1000 iterations of (nop, subs, bne): 3000 instructions
/// plus a few for setup; it calibrates the counting method itself.
#[inline(never)]
fn known_loop() {
    // SAFETY: only a register counter and nops.
    unsafe {
        core::arch::asm!(
            "2:",
            "nop",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) 1000u32 => _,
            options(nomem, nostack),
        );
    }
}

#[embassy_executor::task]
async fn bench(golden_path: Option<&'static str>, model_path: Option<&'static str>) {
    const RUNS: u32 = 2000;
    let known = cycles::instructions_x100(RUNS, known_loop);
    let mut line: heapless::String<600> = heapless::String::new();
    let _ = write!(
        line,
        "{{\"method\":\"qemu -icount shift=0, SysTick at 25 MHz = 40 insn/count, {} runs\",\"known_loop_3000_insn_x100\":{}",
        RUNS, known
    );
    if let Some(model) = golden_path
        .and_then(golden::load)
        .and_then(thermocomp_core::golden::image)
        .and_then(|b| Model::parse(b).ok())
    {
        // The seed's configuration (one 5-11-1 network and one position-
        // dependent table), the network alone, then the whole demo model.
        let mut seed_config = model.clone();
        seed_config.nets.truncate(1);
        seed_config.tables.truncate(1);
        let mut net_only = seed_config.clone();
        net_only.tables.clear();
        let (net, _, norm, _) = bench_model(net_only);
        let (seed, _, _, seed_corrections) = bench_model(seed_config);
        let (eval, step, _, _) = bench_model(model);
        let _ = write!(
            line,
            ",\"normalise_5_inputs_1_axis_insn_x100\":{},\"net_5_11_1_insn_x100\":{},\"net_plus_table_insn_x100\":{},\"net_plus_table_corrections_only_insn_x100\":{},\"demo_evaluate_insn_x100\":{},\"demo_step_insn_x100\":{},\"compensator_ram_bytes\":{},\"model_ram_bytes\":{}",
            norm, net, seed, seed_corrections, eval, step, core::mem::size_of::<Compensator>(), core::mem::size_of::<Model>()
        );
    }
    // A fitted model exported by tcomp (e.g. the FL_THERMAL demo model).
    if let Some(model) = model_path.and_then(load_model) {
        // Its volumetric section (issue 14), if it has one.
        let vol = model
            .volumetric
            .as_ref()
            .map(|v| (bench_volumetric(v), v.terms.len(), v.sensors.len()));
        let (eval, step, _, _) = bench_model(model);
        let _ = write!(
            line,
            ",\"image_model_evaluate_insn_x100\":{},\"image_model_step_insn_x100\":{}",
            eval, step
        );
        if let Some((insn, terms, sensors)) = vol {
            let _ = write!(
                line,
                ",\"volumetric_evaluate_insn_x100\":{},\"volumetric_terms\":{},\"volumetric_sensors\":{}",
                insn, terms, sensors
            );
        }
    }
    log!("{}}}", line);
    semihost::exit(exit_code::OK)
}

/// Instructions of one volumetric evaluation (section kind 3: every term,
/// x, y and z) at a third of each stroke, 200 mm of tool and every sensor
/// 5 K above its reference, averaged over many calls.
fn bench_volumetric(v: &thermocomp_core::volumetric::Volumetric) -> u64 {
    const RUNS: u32 = 500;
    let mut positions = [0i32; MAX_AXES];
    for k in 0..3 {
        if let Some(p) = positions.get_mut(usize::from(v.slots[k])) {
            *p = v.origin_um[k] + v.stroke_um[k] / 3;
        }
    }
    let temps: heapless::Vec<Option<i32>, { thermocomp_core::volumetric::MAX_VOL_SENSORS }> = v
        .sensors
        .iter()
        .map(|s| Some(s.sensor.ref_temp + 80))
        .collect();
    cycles::instructions_x100(RUNS, || {
        core::hint::black_box(v.evaluate(
            core::hint::black_box(&positions),
            core::hint::black_box(200_000),
            core::hint::black_box(&temps),
        ));
    })
}

/// Instructions of one full evaluation (all networks and tables) and of one
/// compensator step (features, lag filters for one step, evaluation, limits)
/// at mid-range inputs, averaged over many calls.
fn bench_model(model: Model) -> (u64, u64, u64, u64) {
    const RUNS: u32 = 500;
    // Mid-range features, Q8 of the raw unit as the compensator hands them.
    let features: heapless::Vec<i32, 16> =
        model.inputs.iter().map(|i| (i.min + i.max) << 7).collect();
    let positions = [0i32; MAX_AXES];
    let eval = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(model.evaluate(core::hint::black_box(&features), &positions));
    });
    let norm = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(model.normalise(core::hint::black_box(&features), &positions));
    });
    let corrections = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(
            model.evaluate_corrections(core::hint::black_box(&features), &positions),
        );
    });

    let temps = [Some(400i32); MAX_SENSORS];
    let n = model.sensors.len();
    let mut comp = Compensator::new(Some(model));
    let mut now = 0u64;
    let step = cycles::instructions_x100(RUNS, || {
        now += 1000;
        let input = StepInput {
            now_ms: now,
            temps: &temps[..n],
            spindle_rpm: 6000,
            positions: &positions,
            stale: false,
        };
        core::hint::black_box(comp.step(core::hint::black_box(&input)));
    });
    (eval, step, norm, corrections)
}

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
//! - `replay <run.csv>`: compensate the whole trace, log each correction,
//!   exit 0 at its end (non-zero on a bad trace);
//! - `bench`: instruction counts (run QEMU with `-icount shift=0`), printed
//!   as one JSON line.
#![no_std]
#![no_main]

mod cycles;
mod emulated_bus;
mod executor;
mod host_trace;
mod semihost;
mod time_driver;
// The Modbus port (issue 4) is wired next; until then the driver is unused.
#[allow(dead_code)]
mod uart;

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m_rt::{entry, exception};
use embassy_executor::Spawner;
use embassy_time::{Duration, Instant, Timer};
use static_cell::StaticCell;
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{
    AcquisitionConfig, CycleReport, TemperatureAcquisition,
};
use thermocomp::trace::TraceSample;

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
        "replay" => match arg.map(replay) {
            Some(Ok(task)) => spawner.spawn(task),
            Some(Err(_)) => semihost::exit(exit_code::PANIC),
            None => {
                log!("replay needs a run CSV path");
                semihost::exit(exit_code::BAD_COMMAND_LINE)
            }
        },
        "bench" => match bench() {
            Ok(task) => spawner.spawn(task),
            Err(_) => semihost::exit(exit_code::PANIC),
        },
        other => {
            log!("unknown mode {:?}; use selftest | replay <run.csv>", other);
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
    // 1. Timers and a second task: 200 ms must pass as ~20 ticker periods.
    let start = Instant::now();
    Timer::after(Duration::from_millis(200)).await;
    let elapsed = start.elapsed().as_millis();
    let ticks = TICKS_SEEN.load(Ordering::Relaxed);
    let timers_ok = (200..=210).contains(&elapsed) && (18..=21).contains(&ticks);
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
async fn replay(path: &'static str) {
    let mut trace = open_trace(path);
    let channels = trace.header().channels();
    log!("replaying {} ({} temperature channels)", path, channels);
    let mut sensors = Sensors::new(channels).await;
    let mut rows = 0u32;
    loop {
        match trace.next_sample() {
            Ok(Some(sample)) => {
                rows += 1;
                let report = sensors.acquire(&sample).await;
                let ch0 = sensors.acquisition.value(0, sample.time_ms);
                log!(
                    "t={} ms ok={} faulty={} T0={:?} {:?} rpm={:?}",
                    sample.time_ms,
                    report.ok,
                    report.faulty,
                    ch0.usable(),
                    ch0.state,
                    sample.spindle_rpm
                );
            }
            Ok(None) => break,
            Err(e) => {
                log!("trace error: {:?}", e);
                semihost::exit(exit_code::TRACE_ERROR)
            }
        }
    }
    log!("replay done: {} samples", rows);
    semihost::exit(exit_code::OK)
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
    /// Run the math core's golden vectors from a host file; true when all pass.
    pub fn check_file(path: &str) -> bool {
        crate::log!("golden vectors {}: not wired yet", path);
        false
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
    log!("hard fault at pc={:#010x}", frame.pc());
    semihost::exit(exit_code::PANIC)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    log!("panic: {}", info);
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
async fn bench() {
    const RUNS: u32 = 2000;
    let known = cycles::instructions_x100(RUNS, known_loop);
    log!(
        "{{\"method\":\"qemu -icount shift=0, SysTick at 25 MHz = 40 insn/count, {} runs\",\"known_loop_3000_insn_x100\":{}}}",
        RUNS, known
    );
    semihost::exit(exit_code::OK)
}

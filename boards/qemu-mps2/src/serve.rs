//! The `serve` mode: the Modbus RTU bench. The board runs the application's
//! own loops ([`thermocomp::runtime`]) as a field board does; only the
//! cycles come from a run CSV (one sample every `pace_ms`) on emulated
//! sensors instead of a 1 s period on a real bus.

use core::cell::RefCell;
use embassy_executor::Spawner;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_time::{Delay, Duration, Instant, Timer};
use static_cell::StaticCell;
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::app::App;
use thermocomp::fault;
use thermocomp::runtime::{self, CycleDone, CycleInput, CycleSource, SharedApp};
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_protocol::trace::TraceSample;

use crate::emulated_bus::EmulatedBus;
use crate::host_files::{next_sample_or_exit, open_trace, read_host_file};
use crate::host_trace::HostTrace;
use crate::probe::EmulatedProbe;
use crate::replay::log_correction;
use crate::semihost::log;
use crate::sensors::{put_sample, Sensors};
use crate::time_driver::Uptime;
use crate::{flash, rtu_port, safety};
use board_support::stack;
use thermocomp::acquisition::probe::ProbeReading;

/// The application state the serve tasks share: built in place once,
/// before they start (never locked across an await).
type Shared = SharedApp<CriticalSectionRawMutex, flash::RamNor>;
static APP: StaticCell<Shared> = StaticCell::new();

/// Modbus unit address and baud rate the bench board starts with.
const UNIT: u8 = 1;
const BAUD: u32 = 115_200;
/// The bench searches its bus again every this many trace rows.
const REDISCOVER_ROWS: u32 = 10;
/// Every this many rows one correction is logged.
const LOG_EVERY_ROWS: u32 = 50;

/// What the command line asks of the serve mode.
pub struct ServeArgs {
    pub trace: &'static str,
    pub model: Option<&'static str>,
    pub pace_ms: u64,
    /// `(sensor, row)`: that emulated sensor is replaced by a new one
    /// (another ROM code) at that trace row.
    pub swap: Option<(usize, u32)>,
    /// The PLC of `tcomp replay --reference-when-asked`, which probes at the
    /// sample after the one that raised input register 23: while a
    /// reference is wanted and no command 12 is pending, the trace waits
    /// (up to [`LOCKSTEP_WAIT_MS`]) before its next row.
    pub lockstep: bool,
}

/// Longest wait of the lockstep mode for the PLC's command 12 (then the
/// trace goes on: a PLC that does not answer does not stop the bench).
const LOCKSTEP_WAIT_MS: u64 = 20_000;

/// Open the trace, build the app (model, settings and channel map from the
/// slots; the trace columns' map when none is stored), spawn the tasks.
pub fn start(spawner: Spawner, args: ServeArgs) {
    let trace = open_trace(args.trace);
    let (sensors, map) = Sensors::emulate(trace.header().channels());
    let Some(flash) = flash::RamNor::take() else {
        fault::fault::<safety::Bench>(fault::kind::INIT_FAILED, 0, fault::init_step::FLASH)
    };
    let app = build_app(flash, map);
    // Loaded in place: the model never sits on the stack inside an app.
    app.lock(|a| a.borrow_mut().load_stored());
    match (
        measure(app, trace, sensors, map, args),
        modbus(app),
        watchdog(app),
    ) {
        (Ok(t1), Ok(t2), Ok(t3)) => {
            spawner.spawn(t1);
            spawner.spawn(t2);
            spawner.spawn(t3);
        }
        _ => fault::fault::<safety::Bench>(fault::kind::INIT_FAILED, 0, fault::init_step::SPAWN),
    }
}

/// The app state in its static. Not inlined, so that its temporaries take
/// stack only while it runs.
#[inline(never)]
fn build_app(flash: flash::RamNor, map: ChannelMap) -> &'static Shared {
    APP.init_with(|| {
        BlockingMutex::new(RefCell::new(App::unloaded(
            flash,
            flash::SLOT_SIZE,
            UNIT,
            BAUD,
            map,
        )))
    })
}

#[embassy_executor::task]
async fn measure(
    app: &'static Shared,
    trace: HostTrace,
    mut sensors: Sensors,
    map: ChannelMap,
    args: ServeArgs,
) {
    sensors.start(map).await;
    let boot = runtime::boot_report::<safety::Bench, _, _>(app, *sensors.acquisition.map());
    if let Some(p) = args.model {
        // A factory programs a blank board once: a model already in the
        // slots (an upload, or this one at an earlier boot) stays, so a
        // reset never goes back to the command line's model.
        let stored = app.lock(|a| a.borrow().model_version());
        if stored == 0 {
            program(app, p);
        } else {
            log!(
                "model {} not programmed: the flash slots hold version {}",
                p,
                stored
            );
        }
    }
    if let Some(r) = boot.fault {
        log!(
            "fault record: {} at pc={:#010x}, uptime {} ms, fault #{} since cleared, detail {:#x}",
            fault::kind::name(r.kind),
            r.pc,
            r.uptime_ms,
            r.count,
            r.detail
        );
    }
    // The unit and baud rate in force: the stored settings, else the defaults.
    let (version, crc, unit, baud) = app.lock(|a| {
        let a = a.borrow();
        let s = a.settings();
        (a.model_version(), a.model_crc(), s.unit, s.baud)
    });
    log!(
        "serving Modbus RTU on UART0: unit {}, {} baud, model version {} crc {:#010x}; replaying {} ({} channels), one sample per {} ms",
        unit, baud, version, crc, args.trace, trace.header().channels(), args.pace_ms
    );
    let mut source = TraceCycles {
        trace,
        pace_ms: args.pace_ms,
        swap: args.swap,
        lockstep: args.lockstep.then_some(app),
        rows: 0,
        sample: None,
    };
    let Sensors {
        mut bus,
        mut acquisition,
        ..
    } = sensors;
    runtime::measurement_loop(
        app,
        &mut acquisition,
        &mut bus,
        &mut Delay,
        &mut source,
        REDISCOVER_ROWS,
    )
    .await
}

/// The bench's initial model from the host, programmed into the slots like
/// a factory-programmed board's (with the channel map in force).
fn program(app: &Shared, path: &str) {
    static BUF: StaticCell<[u8; MAX_IMAGE_BYTES]> = StaticCell::new();
    let Some(buf) = BUF.try_init([0; MAX_IMAGE_BYTES]) else {
        fault::fault::<safety::Bench>(fault::kind::INIT_FAILED, 0, fault::init_step::BUFFER)
    };
    match read_host_file(path, buf).map(|img| app.lock(|a| a.borrow_mut().program(img))) {
        Some(Ok(())) => log!("model {} programmed into the flash slots", path),
        other => log!(
            "model {} not programmed ({:?}); serving what the slots hold",
            path,
            other
        ),
    }
}

/// The bench's cycles: one trace row every `pace_ms`, at the row's time
/// and recorded spindle speed.
struct TraceCycles {
    trace: HostTrace,
    pace_ms: u64,
    swap: Option<(usize, u32)>,
    /// Lockstep mode ([`ServeArgs::lockstep`]): the app it waits on.
    lockstep: Option<&'static Shared>,
    /// Rows read so far.
    rows: u32,
    /// The row being measured.
    sample: Option<TraceSample>,
}

impl CycleSource<EmulatedBus> for TraceCycles {
    async fn next_cycle(&mut self, bus: &mut EmulatedBus) -> Option<CycleInput> {
        if self.rows > 0 {
            Timer::after(Duration::from_millis(self.pace_ms)).await;
            if let Some(app) = self.lockstep {
                wait_for_reference(app).await;
            }
        }
        let sample = next_sample_or_exit(&mut self.trace)?;
        self.rows += 1;
        if let Some((k, _)) = self.swap.filter(|(_, row)| *row == self.rows) {
            log!("sensor {} replaced by a new one (another ROM code)", k);
            bus.replace(k);
        }
        let input = CycleInput {
            now_ms: sample.time_ms,
            spindle_override: sample.spindle_rpm,
        };
        self.sample = Some(sample);
        Some(input)
    }

    fn prepare(&mut self, bus: &mut EmulatedBus, _input: &CycleInput) {
        if let Some(sample) = &self.sample {
            put_sample(bus, sample);
        }
    }

    fn uptime_ms(&mut self, _input: &CycleInput) -> u64 {
        Instant::now().as_millis()
    }

    fn cycle_done(&mut self, done: &CycleDone<'_>) {
        if done.cycle % LOG_EVERY_ROWS == 1 {
            let ch0 = done.acquisition.value(0, done.input.now_ms);
            log_correction(
                done.model,
                done.input.now_ms,
                done.report,
                (ch0.usable(), ch0.state),
                done.input.spindle_override.unwrap_or(0),
                done.out,
            );
        }
    }

    fn stalled(&mut self) {
        log!("measurement loop stalled on request (command 9)");
    }

    fn ended(&mut self, rows: u32) {
        log!("trace done: {} samples; still serving", rows);
        log!("stack high-water: {} B", stack::high_water());
    }

    async fn idle(&mut self) {
        Timer::after(Duration::from_millis(self.pace_ms)).await;
    }

    /// The emulated probe at the row's `dprobe_um` (none without that column).
    async fn probe(&mut self, reference_samples: Option<u16>) -> Option<ProbeReading> {
        if !self.trace.header().has_probe() {
            return None;
        }
        let value = self.sample.as_ref().and_then(|s| s.probe_tenth_um);
        EmulatedProbe::read(value, reference_samples).await
    }
}

/// Lockstep mode: while the last cycle raised "reference wanted" (input
/// register 23) and no command 12 is pending, idle cycles (the watchdog
/// sees the loop alive) until it comes or [`LOCKSTEP_WAIT_MS`] passed.
async fn wait_for_reference(app: &'static Shared) {
    let start = Instant::now();
    while start.elapsed().as_millis() < LOCKSTEP_WAIT_MS {
        let waiting = app.lock(|a| {
            let mut a = a.borrow_mut();
            let waiting =
                a.snapshot().reference_wanted != 0 && a.probe_reference_samples().is_none();
            if waiting {
                a.idle_cycle();
            }
            waiting
        });
        if !waiting {
            return;
        }
        Timer::after(Duration::from_millis(1)).await;
    }
    log!(
        "lockstep: no command 12 within {} ms; the trace goes on",
        LOCKSTEP_WAIT_MS
    );
}

#[embassy_executor::task]
async fn modbus(app: &'static Shared) {
    let mut port = rtu_port::QemuRtuPort::new(BAUD);
    runtime::modbus_loop::<safety::Bench, _, _, _, _>(&mut port, app, &Uptime).await
}

/// The CMSDK watchdog, fed by the application's feeder.
#[embassy_executor::task]
async fn watchdog(app: &'static Shared) {
    let mut watchdog = safety::CmsdkWatchdog::start();
    log!(
        "watchdog started: {} ms, fed when both tasks progressed",
        safety::WATCHDOG_TIMEOUT_MS
    );
    runtime::watchdog_loop(
        app,
        &mut watchdog,
        &Uptime,
        &mut Delay,
        runtime::BOOT_DEADLINE_MS,
    )
    .await
}

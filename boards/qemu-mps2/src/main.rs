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
//!   Optional further words: `swap=<sensor>@<row>` replaces that emulated
//!   sensor by a new one (another ROM code) at that trace row; `lockstep`
//!   holds the trace after a cycle that raised "reference wanted" (input
//!   register 23) until the PLC's command 12 is pending, so the reference
//!   is taken at the next sample, as `tcomp replay --reference-when-asked`
//!   models the PLC. A fault in
//!   this mode resets the board (fault record, as in the field); the CMSDK
//!   watchdog runs.
//! - `bench [golden.bin] [model.img]`: instruction counts (run QEMU with `-icount
//!   shift=0`) of the calibration loop and, with the golden file's model, of
//!   one full evaluation and one compensator step, printed as one JSON line.
#![no_std]
#![no_main]

mod bench;
mod cycles;
mod emulated_bus;
mod executor;
mod exit;
mod flash;
mod host_files;
mod host_trace;
mod overflow;
mod probe;
mod replay;
mod rtu_port;
mod safety;
mod selftest;
mod semihost;
mod sensors;
mod serve;
mod time_driver;
mod uart;

use core::sync::atomic::Ordering;

use cortex_m_rt::{entry, exception};
use embassy_executor::Spawner;
use static_cell::StaticCell;
use thermocomp::fault;

use exit::exit_code;
use semihost::log;

static EXECUTOR: StaticCell<executor::Executor> = StaticCell::new();

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
        "selftest" => match (selftest::ticker(), selftest::selftest(arg)) {
            (Ok(t1), Ok(t2)) => {
                spawner.spawn(t1);
                spawner.spawn(t2);
            }
            _ => semihost::exit(exit_code::PANIC),
        },
        "replay" => match arg.map(|a| replay::replay(a, words.next())) {
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
            // `lockstep`: the PLC probes at the sample after a request.
            let (mut swap, mut lockstep) = (None, false);
            for w in words {
                lockstep |= w == "lockstep";
                swap = swap.or_else(|| {
                    let (k, row) = w.strip_prefix("swap=")?.split_once('@')?;
                    Some((k.parse::<usize>().ok()?, row.parse::<u32>().ok()?))
                });
            }
            // From here on a fault resets the board, as in the field.
            safety::FIELD_MODE.store(true, Ordering::Relaxed);
            serve::start(
                spawner,
                serve::ServeArgs {
                    trace,
                    model,
                    pace_ms,
                    swap,
                    lockstep,
                },
            );
        }
        // The stack-overflow check (host-tests/tests/qemu_overflow.rs).
        "overflow" => overflow::run(),
        "bench" => match bench::bench(arg, words.next()) {
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

/// Device interrupts: this machine has no PAC, so every IRQ lands here.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == uart::UART0_RX_IRQ as i16 {
        uart::on_rx_interrupt();
    }
}

/// HardFault, called by `board_support::fault_entry` on a valid stack with
/// the stack pointer at the fault (a stack overflow leaves no frame: kind
/// stack overflow, detail the SP).
#[no_mangle]
unsafe extern "C" fn board_hard_fault(sp: u32) -> ! {
    // SAFETY: a read of the SCB's fault status register.
    let cfsr = unsafe { (*cortex_m::peripheral::SCB::PTR).cfsr.read() };
    // The bus first (the UART off), then the log: a log over semihosting
    // takes host time while the line would be held.
    <safety::Bench as fault::FaultBoard>::safe_state();
    let pc = board_support::fault_entry::frame_pc(sp);
    match pc {
        Some(pc) => log!("hard fault at pc={:#010x} cfsr={:#010x}", pc, cfsr),
        None => log!("stack overflow: sp={:#010x} cfsr={:#010x}", sp, cfsr),
    }
    if safety::FIELD_MODE.load(Ordering::Relaxed) {
        match pc {
            Some(pc) => fault::fault::<safety::Bench>(fault::kind::HARD_FAULT, pc, cfsr),
            None => fault::fault::<safety::Bench>(fault::kind::STACK_OVERFLOW, 0, sp),
        }
    }
    semihost::exit(exit_code::PANIC)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // The bus first (the UART off), then the log.
    <safety::Bench as fault::FaultBoard>::safe_state();
    log!("panic: {}", info);
    if safety::FIELD_MODE.load(Ordering::Relaxed) {
        let line = info.location().map_or(0, |l| l.line());
        fault::fault::<safety::Bench>(fault::kind::PANIC, 0, line)
    }
    semihost::exit(exit_code::PANIC)
}

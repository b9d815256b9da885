//! The `selftest` mode: executor, timers and the math core's golden vectors.

use core::sync::atomic::{AtomicU32, Ordering};
use embassy_time::{Duration, Instant, Timer};

use crate::cycles;
use crate::exit::{exit_code, finish};
use crate::host_files::golden;
use crate::semihost::log;

static TICKS_SEEN: AtomicU32 = AtomicU32::new(0);

/// Counts 10 ms timer periods, so the self-test can check that a second task
/// and the time driver really run.
#[embassy_executor::task]
pub async fn ticker() {
    loop {
        Timer::after(Duration::from_millis(10)).await;
        TICKS_SEEN.fetch_add(1, Ordering::Relaxed);
    }
}

#[embassy_executor::task]
pub async fn selftest(golden_path: Option<&'static str>) {
    let mut failures = 0u32;
    // 0. Whose clock: under `-icount shift=0,sleep=off` (the host tests) a
    // virtual nanosecond is one instruction, so the 3000-instruction loop
    // reads 3000, and every time below is virtual: the verdict cannot depend
    // on the host's load. Without it, time follows the host's clock.
    let loop_ns = cycles::instructions_x100(100, cycles::known_loop) / 100;
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
    finish(if failures == 0 {
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

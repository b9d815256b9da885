//! The watchdog feeder of every board ([`crate::watchdog`] decides, the
//! board's [`Watchdog`] pets the hardware).

use embassy_sync::blocking_mutex::raw::RawMutex;
use embedded_hal_async::delay::DelayNs;

use super::shared::SharedApp;
use crate::hal::clock::Clock;
use crate::hal::flash::BackgroundErase;
use crate::hal::watchdog::Watchdog;
use crate::watchdog::{Feeder, Progress};

/// The bench's boot window: its boot (host files over semihosting, sensor
/// search on the emulated bus) must be done within this long; until then
/// the watchdog is fed unconditionally. A field board passes its own,
/// shorter window to [`watchdog_loop`] (the NUCLEO: 3 s).
pub const BOOT_DEADLINE_MS: u64 = 20_000;
/// How often the feeder looks at the progress counters.
pub const FEED_CHECK_MS: u32 = 100;

/// Feeds the watchdog while booting (up to `boot_deadline_ms` of uptime,
/// the board's boot window; then no more until booted, so a boot that
/// hangs ends in a watchdog reset), then only
/// when both the measurement loop and the Modbus task made progress
/// ([`Feeder`]). Each look also drives a flash commit in progress (erase
/// outside the lock, then programming): [`crate::app::App::poll_flash`].
pub async fn watchdog_loop<M, F, W, C, D>(
    shared: &SharedApp<M, F>,
    watchdog: &mut W,
    clock: &C,
    delay: &mut D,
    boot_deadline_ms: u64,
) -> !
where
    M: RawMutex,
    F: BackgroundErase,
    W: Watchdog,
    C: Clock,
    D: DelayNs,
{
    let progress = || -> Option<Progress> {
        shared.lock(|a| {
            let mut app = a.borrow_mut();
            app.booted().then(|| {
                app.poll_flash();
                app.progress()
            })
        })
    };
    let mut feeder: Option<Feeder> = None;
    loop {
        delay.delay_ms(FEED_CHECK_MS).await;
        match (progress(), feeder.as_mut()) {
            (Some(p), Some(f)) => match f.check(&p) {
                Ok(()) => {
                    watchdog.note_stalled(0);
                    watchdog.pet();
                }
                Err(bits) => watchdog.note_stalled(bits),
            },
            (Some(p), None) => {
                feeder = Some(Feeder::new(&p));
                watchdog.pet();
            }
            (None, _) if clock.now_ms() < boot_deadline_ms => watchdog.pet(),
            (None, _) => {}
        }
    }
}

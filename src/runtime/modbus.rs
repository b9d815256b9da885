//! The Modbus task of every board.

use embassy_sync::blocking_mutex::raw::RawMutex;

use super::shared::SharedApp;
use crate::app::LinkChange;
use crate::fault::FaultBoard;
use crate::hal::clock::Clock;
use crate::hal::flash::BackgroundErase;
use crate::hal::serial::RtuPort;
use thermocomp_protocol::rtu::MAX_FRAME;

/// One frame in, at most one reply out, from the shared app state (locked
/// only between awaits). A frame that arrives before the measurement loop
/// has booted gets no answer, as from a board still booting. `B` is the
/// board's fault path (command 6 clears its record; the test-only command 8
/// panics into it once the reply is out).
pub async fn modbus_loop<B, P, M, F, C>(port: &mut P, shared: &SharedApp<M, F>, clock: &C) -> !
where
    B: FaultBoard,
    P: RtuPort,
    M: RawMutex,
    F: BackgroundErase,
    C: Clock,
{
    let mut frame = [0u8; MAX_FRAME + 1];
    let mut reply: heapless::Vec<u8, MAX_FRAME> = heapless::Vec::new();
    // The baud rate the port runs at: the board's default until the app
    // (with its stored settings) has booted.
    let mut applied_baud: Option<u32> = None;
    loop {
        let want = shared.lock(|a| {
            let app = a.borrow();
            app.booted().then_some(app.settings().baud)
        });
        if let Some(b) = want.filter(|b| applied_baud != Some(*b)) {
            port.set_baud(b);
            applied_baud = Some(b);
        }
        let Ok(n) = port.read_frame(&mut frame).await else {
            continue;
        };
        let Some(request) = frame.get(..n) else {
            continue;
        };
        let now = clock.now_ms();
        reply.clear();
        let change = shared.lock(|a| {
            let mut app = a.borrow_mut();
            app.booted().then(|| {
                app.progress_mut().modbus_busy = true;
                app.request(request, now, &mut reply)
            })
        });
        if !reply.is_empty() {
            port.write_frame(&reply).await;
        }
        shared.lock(|a| {
            let mut app = a.borrow_mut();
            if app.booted() {
                let progress = app.progress_mut();
                progress.modbus_busy = false;
                progress.requests = progress.requests.wrapping_add(1);
            }
        });
        match change {
            Some(LinkChange::Reconfigure { baud }) => {
                port.set_baud(baud);
                applied_baud = Some(baud);
            }
            Some(LinkChange::ClearFaultRecord) => crate::fault::clear::<B>(),
            // On purpose, and only in the bench build: command 8 exists to drive
            // the real panic → fault record → reset path under QEMU. Without
            // `test-faults` (every field board) holding.rs refuses the command
            // and this arm is not compiled.
            #[cfg(feature = "test-faults")]
            Some(LinkChange::TestPanic) => panic!("test panic requested by command 8"),
            _ => {}
        }
    }
}

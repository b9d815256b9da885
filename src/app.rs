//! The compensator application state shared by its two activities: the
//! measurement cycle (acquisition → compensation → snapshot) and the Modbus
//! server (requests → registers, commands, model upload). Board code holds
//! one `App` behind a mutex and never awaits while holding it.

use embedded_storage::nor_flash::NorFlash;
use thermocomp_core::limits::{MAX_AXES, MAX_DIRECTIONS};
use thermocomp_core::{Model, StepOutput};

use crate::acquisition::channel_map::ChannelMap;
use crate::acquisition::temperature::TemperatureAcquisition;
use crate::compensation::{Compensation, PlcInputs};
use crate::modbus::holding::{result, Command};
use crate::modbus::registers::{centidegrees, Snapshot};
use crate::modbus::server::MAX_FRAME;
use crate::modbus::Server;
use crate::model_store::ModelStore;
use crate::process_image::MAX_CHANNELS;

/// PLC registers older than this make the inputs "stale".
pub const PLC_TIMEOUT_MS: u64 = 10_000;

pub struct App<F: NorFlash> {
    pub server: Server,
    pub snapshot: Snapshot,
    pub compensation: Compensation,
    pub store: ModelStore<F>,
    map: ChannelMap,
}

/// What the board must do after a request (after sending the reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkChange {
    None,
    /// New unit address and/or baud rate: reconfigure the port.
    Reconfigure {
        baud: u32,
    },
}

impl<F: NorFlash> App<F> {
    /// Load the newest valid model from the slots (none: "no model").
    pub fn new(flash: F, slot_size: u32, unit: u8, baud: u32, map: ChannelMap) -> Self {
        let mut server = Server::new(unit, baud);
        let mut store = ModelStore::new(flash, slot_size);
        let model = store.load(server.holding.scratch());
        let mut app = App {
            server,
            snapshot: Snapshot::default(),
            compensation: Compensation::new(None, &map),
            store,
            map,
        };
        app.install(model);
        app
    }

    /// Store an image (factory programming, or the bench's initial model) and use it.
    pub fn program(&mut self, image: &[u8]) -> Result<(), u16> {
        let model = Model::parse(image).map_err(|e| result::of_image_error(&e))?;
        self.store.commit(image).map_err(|_| result::STORE_FAILED)?;
        self.install(Some(model));
        Ok(())
    }

    fn install(&mut self, model: Option<Model>) {
        self.compensation.load(model, &self.map);
        self.apply_limits();
        let (v, crc, nd, na, ns) = match self.compensation.model() {
            Some(m) => (
                m.model_version,
                m.crc,
                m.directions.len(),
                m.axes.len(),
                m.sensors.len(),
            ),
            None => (0, 0, 0, 0, 0),
        };
        self.snapshot.model_version = v;
        self.server.holding.running_version = v;
        self.snapshot.model_crc = crc;
        self.snapshot.n_directions = nd as u16;
        self.snapshot.n_axes = na as u16;
        self.snapshot.n_sensors = ns as u16;
    }

    fn apply_limits(&mut self) {
        let h = &self.server.holding;
        let (clamp, rate) = (h.clamp, h.rate);
        for d in 0..MAX_DIRECTIONS {
            let c = if clamp[d] == u16::MAX {
                i32::MAX
            } else {
                i32::from(clamp[d])
            };
            let r = if rate[d] == u16::MAX {
                i32::MAX
            } else {
                i32::from(rate[d])
            };
            self.compensation.compensator().set_limit_override(d, c, r);
        }
    }

    /// One measurement cycle: compensate the latest acquisition and publish a
    /// new snapshot. `spindle_override` replaces the PLC's register (the bench
    /// replays the trace's recorded speed).
    pub fn cycle(
        &mut self,
        acq: &TemperatureAcquisition,
        now_ms: u64,
        uptime_ms: u64,
        spindle_override: Option<i32>,
    ) -> StepOutput {
        let h = &self.server.holding;
        let plc_stale = spindle_override.is_none()
            && h.plc_written_ms
                .is_none_or(|t| uptime_ms.saturating_sub(t) > PLC_TIMEOUT_MS);
        let mut positions = [0i32; MAX_AXES];
        positions.copy_from_slice(&h.positions);
        let plc = PlcInputs {
            spindle_rpm: spindle_override.unwrap_or(i32::from(h.spindle_rpm)),
            positions,
            stale: plc_stale,
        };
        let out = self.compensation.step(acq, now_ms, &plc);
        let s = &mut self.snapshot;
        s.sequence = s.sequence.wrapping_add(1);
        s.heartbeat = s.heartbeat.wrapping_add(1);
        s.uptime_s = (uptime_ms / 1000) as u32;
        s.sample_time_s = (now_ms / 1000) as u32;
        s.status = out.status;
        s.corrections = out.corrections;
        s.predictions = out.predicted;
        s.axes = out.axes;
        s.active = out.active;
        for c in 0..MAX_CHANNELS {
            let v = acq.value(c, now_ms);
            s.temperatures[c] = v.usable().map(centidegrees);
            s.states[c] = v.state.code();
        }
        out
    }

    /// Publish the eddy-current probe's latest reading (0.1 µm and state code).
    pub fn set_probe(&mut self, reading: &crate::acquisition::probe::ProbeReading) {
        self.snapshot.probe = reading.tenth_um.unwrap_or(0);
        self.snapshot.probe_state = reading.state.code();
    }

    /// Handle one request frame; `reply` gets the answer (empty: stay silent).
    pub fn request(
        &mut self,
        frame: &[u8],
        uptime_ms: u64,
        reply: &mut heapless::Vec<u8, MAX_FRAME>,
    ) -> LinkChange {
        match self.server.handle(frame, uptime_ms, &self.snapshot, reply) {
            Command::None => LinkChange::None,
            Command::CommitModel { len } => {
                // The server validated the image; store it in the other slot, then swap.
                let staged =
                    &self.server.holding.staged()[..len.min(self.server.holding.staged().len())];
                let outcome = Model::parse(staged).map(|m| (m, self.store.commit(staged)));
                match outcome {
                    Ok((m, Ok(()))) => {
                        self.install(Some(m));
                        self.server.holding.result = result::OK;
                    }
                    _ => self.server.holding.result = result::STORE_FAILED,
                }
                LinkChange::None
            }
            Command::Rereference => {
                self.compensation.compensator().rereference();
                LinkChange::None
            }
            Command::LimitsChanged => {
                self.apply_limits();
                LinkChange::None
            }
            Command::LinkChanged => LinkChange::Reconfigure {
                baud: self.server.holding.baud,
            },
        }
    }
}

/// The app state as the boards share it between their two tasks.
pub type SharedApp<M, F> =
    embassy_sync::blocking_mutex::Mutex<M, core::cell::RefCell<Option<App<F>>>>;

/// The Modbus task of every board: one frame in, at most one reply out, from
/// the shared app state (locked only between awaits). A frame that arrives
/// before the app is set up gets no answer, as from a board still booting.
pub async fn serve_modbus<P, F, M>(
    port: &mut P,
    shared: &SharedApp<M, F>,
    uptime_ms: impl Fn() -> u64,
) -> !
where
    P: crate::hal::serial::RtuPort,
    F: NorFlash,
    M: embassy_sync::blocking_mutex::raw::RawMutex,
{
    let mut frame = [0u8; MAX_FRAME + 1];
    let mut reply: heapless::Vec<u8, MAX_FRAME> = heapless::Vec::new();
    loop {
        let Ok(n) = port.read_frame(&mut frame).await else {
            continue;
        };
        let Some(request) = frame.get(..n) else {
            continue;
        };
        let now = uptime_ms();
        reply.clear();
        let change = shared.lock(|a| {
            a.borrow_mut()
                .as_mut()
                .map(|app| app.request(request, now, &mut reply))
        });
        if !reply.is_empty() {
            port.write_frame(&reply).await;
        }
        if let Some(LinkChange::Reconfigure { baud }) = change {
            port.set_baud(baud);
        }
    }
}

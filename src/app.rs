//! The compensator application state shared by its two activities: the
//! measurement cycle (acquisition → compensation → snapshot) and the Modbus
//! server (requests → registers, commands, model upload). Board code holds
//! one `App` behind a mutex ([`crate::runtime::SharedApp`]) and never
//! awaits while holding it.

use embedded_storage::nor_flash::NorFlash;
use thermocomp_core::StepOutput;

use crate::acquisition::channel_map::ChannelMap;
use crate::acquisition::channel_map::CHANNEL_MAP_BYTES;
use crate::acquisition::rom::RomCode;
use crate::acquisition::temperature::TemperatureAcquisition;
use crate::acquisition::temperature::Validity;
use crate::compensation::Compensation;
use crate::fault::FaultRecord;
use crate::hal::flash::BackgroundErase;
use crate::modbus::Server;
use crate::model_store::ModelStore;
use crate::probe_reference::{ProbeSetup, References, BLOCK_LEN as REFERENCES_LEN};
use crate::snapshot::{centidegrees, Snapshot};
use crate::staging::ParseCandidate;
use crate::state::AppState;
use crate::state::Command;
use thermocomp_core::ask::AskParams;
use thermocomp_core::compensator::Compensator;
use thermocomp_core::image::ImageError;

mod access;
mod probe;
mod records;
use crate::model_store::MAX_SETTINGS_BYTES;
use crate::settings::{KeptReference, Settings, ENCODED_LEN as SETTINGS_LEN};
use crate::settings_store::SettingsStore;
use crate::volumetric::VolContext;
use crate::watchdog::Progress;
use thermocomp_core::limits::MAX_SENSORS;
use thermocomp_core::volumetric::MAX_VOL_SENSORS;
use thermocomp_protocol::holding::{result, rule};
use thermocomp_protocol::rtu::MAX_FRAME;
use thermocomp_protocol::states::ChannelState;
use thermocomp_protocol::MAX_CHANNELS;

// The old slots' settings block (read once, to migrate it to the settings
// store) held the settings, the channel map, a kept reference, the probe
// references and the keys.
const _: () = assert!(
    SETTINGS_LEN
        + CHANNEL_MAP_BYTES
        + crate::settings::REFERENCE_LEN
        + REFERENCES_LEN
        + crate::settings::KEYS_LEN
        <= MAX_SETTINGS_BYTES
);

pub use crate::plc::PLC_TIMEOUT_MS;

pub struct App<F: NorFlash> {
    /// The Modbus codec: frames in, replies out, the unlock rule.
    server: Server,
    /// What masters set: settings, PLC data, probe setup, keys, the staged
    /// image, the result code ([`AppState`]).
    state: AppState,
    /// What the board reports, published by each cycle.
    snapshot: Snapshot,
    compensation: Compensation,
    store: ModelStore<F>,
    /// Settings, keys, the kept reference and the probe-reference terms
    /// ([`crate::settings_store`], in the flash area the board names).
    settings_store: SettingsStore,
    /// CRC-32 of each record as the store holds it (`None`: not stored or
    /// unknown): only records that changed are written ([`records`]).
    written: [Option<u32>; crate::settings_store::RECORDS],
    map: ChannelMap,
    /// What the watchdog feeder looks at ([`crate::watchdog`]).
    progress: Progress,
    /// Set by the test-only command 9: the measurement loop must stop.
    stall_requested: bool,
    /// The measurement loop has booted (sensors searched, channel map and
    /// fault record settled): until then Modbus frames get no answer, as
    /// from a board still booting, and the watchdog is fed unconditionally
    /// ([`crate::runtime`]).
    booted: bool,
    /// The board's settings without stored ones (command 7 goes back to them).
    defaults: Settings,
    /// The flash write in progress ([`App::poll_flash`]).
    job: Option<FlashJob>,
    /// The reference sample kept across reboots (commands 10, 11).
    kept: Option<KeptReference>,
    /// Command 10 accepted: take the reference at the next cycle with every
    /// model sensor fresh.
    reference_pending: bool,
    /// The volumetric section's sensors at the last cycle (1/16 °C) and
    /// whether one was held: a PLC write of positions is answered with
    /// these at once ([`App::update_volumetric`]).
    vol_temps: [Option<i32>; MAX_VOL_SENSORS],
    vol_held: bool,
    /// Uptime of the last cycle or request (ms), for the PLC-timeout rule.
    vol_uptime_ms: u64,
    /// Probe references and re-zero ([`crate::probe_reference`]).
    references: References,
    /// HR_RESULT once the settings job in progress is stored (a refused
    /// probe reference says so after its count is stored).
    stored_result: Option<u16>,
}

/// A flash write accepted over Modbus and done in the background: the
/// erase outside the app lock, programming (a few ms) inside it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FlashJob {
    /// Store the staged image (this long) with the settings in force.
    Model { len: usize, erasing: bool },
    /// Store the records that changed in the settings store.
    Settings,
    /// The same, for the board's own sake (a reference request raised):
    /// HR_RESULT and the busy flag are left alone, so a master's last
    /// command keeps its answer. A master's store meanwhile turns it into
    /// [`FlashJob::Settings`].
    Quiet,
}

/// What the board must do after a request (after sending the reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkChange {
    None,
    /// New unit address and/or baud rate: reconfigure the port.
    Reconfigure {
        baud: u32,
    },
    /// Command 6: the board forgets its fault record ([`crate::fault::clear`]).
    ClearFaultRecord,
    /// Command 8 (feature `test-faults`): panic once the reply is out.
    TestPanic,
}

impl<F: BackgroundErase> App<F> {
    /// Load the newest valid model and the settings and channel map stored
    /// with it from the slots (none: "no model"; `unit` and `baud` with no
    /// clamp or rate override when no settings are stored; `map` when no
    /// channel map is stored): [`App::unloaded`], then [`App::load_stored`].
    pub fn new(flash: F, slot_size: u32, unit: u8, baud: u32, map: ChannelMap) -> Self {
        let mut app = Self::unloaded(flash, slot_size, unit, baud, map);
        app.load_stored();
        app
    }

    /// The app before [`App::load_stored`]: no model, the board's settings
    /// and `map`. A board builds this straight into its static and loads
    /// it there, so the app never sits on the stack with a model in it.
    // Inlined into the board's (not inlined) builder, where the app is
    // built once and copied into the static, not again on the way out.
    #[inline(always)]
    pub fn unloaded(flash: F, slot_size: u32, unit: u8, baud: u32, map: ChannelMap) -> Self {
        App {
            server: Server::new(),
            state: AppState::new(unit, baud),
            snapshot: Snapshot::default(),
            compensation: Compensation::empty(),
            settings_store: SettingsStore::new(flash.settings_area()),
            written: [None; crate::settings_store::RECORDS],
            store: ModelStore::new(flash, slot_size),
            map,
            progress: Progress::default(),
            stall_requested: false,
            booted: false,
            defaults: Settings {
                unit,
                baud,
                ..Settings::default()
            },
            job: None,
            kept: None,
            reference_pending: false,
            vol_temps: [None; MAX_VOL_SENSORS],
            vol_held: false,
            vol_uptime_ms: 0,
            references: References::new(),
            stored_result: None,
        }
    }

    /// The newest valid model from the slots and the settings, channel map
    /// and kept reference stored with it, in force.
    #[inline(never)]
    pub fn load_stored(&mut self) {
        // Parsed straight into the compensator (no model on the stack).
        let (store, buf) = (&mut self.store, self.state.staging.scratch());
        self.compensation
            .compensator()
            .load_with(|m| store.load_into(buf, m));
        // The settings store, or (a board updated from the old layout, whose
        // store holds no settings yet) the old slot's settings block, then
        // copied to the store at once.
        let stored = match self.load_records() {
            Some(stored) => Some(stored),
            None => {
                let legacy = self.load_slot_settings();
                if self.store.settings().is_some() {
                    self.migrate();
                }
                legacy
            }
        };
        self.state.settings = stored.unwrap_or(self.defaults);
        self.publish_references();
        self.snapshot.reference_state = u16::from(self.kept.is_some());
        self.publish_map();
        self.installed();
    }

    /// The settings in force (unit, baud, clamp and rate overrides).
    pub fn settings(&self) -> Settings {
        self.state.settings
    }

    /// Store what changed of the settings, keys, kept reference and probe
    /// terms ([`crate::settings_store`], power-cut safe per record; no
    /// model-slot erase); a flash failure leaves them applied until the
    /// next reboot and says so in HR_RESULT ([`result::SETTINGS_NOT_STORED`]).
    fn store_settings(&mut self) {
        let quiet = matches!(self.job, Some(FlashJob::Quiet));
        if (self.job.is_some() && !quiet) || !self.records_dirty() {
            return;
        }
        self.job = Some(FlashJob::Settings);
        self.state.busy = true;
        self.state.result = result::COMMIT_IN_PROGRESS;
    }

    /// Store the records that changed for the board's own sake
    /// ([`FlashJob::Quiet`]); nothing when a store is already running (it
    /// writes every record that differs when it runs).
    fn store_quietly(&mut self) {
        if self.job.is_none() && self.records_dirty() {
            self.job = Some(FlashJob::Quiet);
        }
    }

    /// The kept reference sample (commands 10, 11), if any.
    pub fn kept_reference(&self) -> Option<KeptReference> {
        self.kept
    }

    /// Command 10 (or 2 on a machine with a fixed reference): the next
    /// cycle with every model sensor fresh takes the reference and keeps it.
    fn request_reference(&mut self) {
        self.reference_pending = true;
        self.snapshot.reference_state = 2;
        self.state.result = result::REFERENCE_PENDING;
    }

    /// Take the pending reference sample now if every model sensor reads
    /// fresh: per mapped channel its reading, used from this cycle on and stored.
    fn take_reference(&mut self, acq: &TemperatureAcquisition, now_ms: u64) {
        let fresh = |c: usize| {
            let v = acq.value(c, now_ms);
            (v.validity == Validity::Fresh).then_some(v.raw)
        };
        let n = self.compensation.model().map_or(0, |m| m.sensors.len());
        let ready = (0..n).all(|i| {
            self.compensation
                .channel_of(i)
                .is_some_and(|c| fresh(usize::from(c)).is_some())
        });
        if !ready {
            return;
        }
        let mut temps = [None; MAX_CHANNELS];
        for (c, t) in temps.iter_mut().enumerate() {
            if self.map.get(c).is_some() {
                *t = fresh(c);
            }
        }
        self.kept = Some(KeptReference { temps });
        self.reference_pending = false;
        self.snapshot.reference_state = 1;
        self.apply_kept_reference();
        self.state.result = result::OK;
        self.store_settings();
    }

    /// The kept reference, per model sensor through its channel, as the
    /// compensator's next reference sample.
    fn apply_kept_reference(&mut self) {
        let Some(k) = self.kept else {
            return;
        };
        let n = self.compensation.model().map_or(0, |m| m.sensors.len());
        let refs: [Option<i32>; MAX_SENSORS] = core::array::from_fn(|i| {
            self.compensation
                .channel_of(i)
                .and_then(|c| k.temps.get(usize::from(c)).copied().flatten())
                .map(i32::from)
        });
        self.compensation
            .compensator()
            .preset_reference(refs.get(..n).unwrap_or(&refs));
    }

    /// The channel map's ROM codes into the identity registers (200–279).
    fn publish_map(&mut self) {
        for (c, r) in self.snapshot.roms.iter_mut().enumerate() {
            *r = self.map.get(c).map_or([0; 8], |rom| rom.0);
        }
    }

    /// The channel map in force (stored, or the board's at first boot).
    pub fn channel_map(&self) -> ChannelMap {
        self.map
    }

    /// A new channel map from a bus search (sensors found that were not
    /// mapped went to free channels; mapped ones keep theirs): stored in
    /// the slots, the channels it added reported (input registers 172–173),
    /// and the model's sensors resolved again if that changes where one reads.
    pub fn update_channel_map(&mut self, map: ChannelMap) {
        if map == self.map {
            return;
        }
        for c in 0..MAX_CHANNELS {
            if self.map.get(c).is_none() && map.get(c).is_some() {
                self.snapshot.map_added |= 1 << c;
            }
        }
        let resolved_before: [Option<u8>; MAX_SENSORS] =
            core::array::from_fn(|i| self.compensation.channel_of(i));
        let vol_before: [Option<u8>; MAX_VOL_SENSORS] =
            core::array::from_fn(|i| self.compensation.vol_channel_of(i));
        self.map = map;
        self.publish_map();
        let moved = |rom: [u8; 8], before: Option<u8>| {
            rom != [0; 8]
                && map
                    .channel_of(&RomCode(rom))
                    .and_then(|c| u8::try_from(c).ok())
                    != before
        };
        let changes = self.compensation.model().is_some_and(|m| {
            m.sensors
                .iter()
                .zip(resolved_before)
                .any(|(s, before)| moved(s.rom, before))
                || m.volumetric.as_ref().is_some_and(|v| {
                    v.sensors
                        .iter()
                        .zip(vol_before)
                        .any(|(s, before)| moved(s.sensor.rom, before))
                })
        });
        if changes {
            // The model held now, restarted (as an upload of it would).
            self.compensation.compensator().restart();
            self.installed();
        }
        self.store_settings();
    }

    /// True while a commit (model or settings) is being written.
    pub fn flash_busy(&self) -> bool {
        self.job.is_some()
    }

    /// Drive the flash write in progress; call it every few tens of ms (the
    /// boards' watchdog feeder does, every 100 ms). The first call starts
    /// the erase of the inactive slot — at once on a flash that erases in
    /// the background — and returns; a later call, once the erase is done,
    /// programs the slot (image or the model held now, then the settings in
    /// force, magic last), swaps it in and sets HR_RESULT. Modbus requests
    /// are answered meanwhile; writes that would change what is being
    /// stored get exception 06 (busy). Returns true while a job remains.
    // Not inlined: a model install's temporaries stay out of the feeder's frame.
    #[inline(never)]
    pub fn poll_flash(&mut self) -> bool {
        let Some(job) = self.job else {
            return false;
        };
        let FlashJob::Model { len, erasing } = job else {
            // A record store erases at most one 16 KiB page, and only when
            // its page is full: still only while the line is quiet.
            if !self.store.ready_to_erase() {
                return true;
            }
            let ok = self.store_records().is_ok();
            self.end_job(job, ok);
            return false;
        };
        if !erasing {
            if !self.store.ready_to_erase() {
                return true;
            }
            if self.store.begin().is_err() {
                self.end_job(job, false);
                return false;
            }
            self.job = Some(FlashJob::Model { len, erasing: true });
        }
        if !self.store.erase_done() {
            return true;
        }
        let staged = self.state.staging.staged();
        let staged = staged.get(..len).unwrap_or(staged);
        // The server checked the image when it took the command, and the
        // staging area is read-only while the job runs: stored, then parsed
        // straight into the compensator (no model on this stack; should it
        // ever fail, the compensator holds no model and the slots still
        // hold the old one as the newest that parses).
        let ok = self.store.finish(Some(staged), &[]).is_ok();
        if ok {
            let (comp, state) = (&mut self.compensation, &self.state);
            let staged = state.staging.staged();
            let staged = staged.get(..len).unwrap_or(staged);
            comp.compensator()
                .load_with(|m| m.parse_into(staged).is_ok());
            self.installed();
            // A new model's terms restart; the stored ones name the old
            // model's CRC and are not loaded with this one.
            self.references.reset();
            let _ = self.store_records();
        }
        self.end_job(job, ok);
        false
    }

    fn end_job(&mut self, job: FlashJob, ok: bool) {
        self.job = None;
        if job == FlashJob::Quiet {
            // A failed quiet store is retried by the next store (its
            // records still differ from what the store holds).
            return;
        }
        self.state.busy = false;
        let after = self.stored_result.take().unwrap_or(result::OK);
        let h = &mut self.state;
        match (job, ok) {
            (FlashJob::Model { .. }, true) => h.result = result::OK,
            (FlashJob::Model { .. }, false) => h.result = result::STORE_FAILED,
            (FlashJob::Settings, true) => h.result = after,
            (FlashJob::Settings, false) => h.result = result::SETTINGS_NOT_STORED,
            (FlashJob::Quiet, _) => {}
        }
    }

    /// Serve the fault record found at boot (status bit 9, input registers 160–168).
    pub fn set_fault_record(&mut self, record: Option<FaultRecord>) {
        self.snapshot.fault = record;
    }

    /// Store an image (factory programming, or the bench's initial model) and use it.
    #[inline(never)]
    pub fn program(&mut self, image: &[u8]) -> Result<(), u16> {
        if matches!(self.job, Some(FlashJob::Model { .. })) {
            return Err(result::COMMIT_IN_PROGRESS);
        }
        // Parsed straight into the compensator (no model on this stack);
        // refused or not stored: the stored model back in force.
        let mut parsed = Ok(());
        self.compensation.compensator().load_with(|m| {
            parsed = m.parse_into(image);
            parsed.is_ok()
        });
        if let Err(e) = parsed {
            self.load_stored();
            return Err(result::of_image_error(&e));
        }
        // A new model's terms restart (stored with its CRC; a pending
        // settings write is done by this one).
        if self.store.commit(image).is_err() {
            self.load_stored();
            return Err(result::STORE_FAILED);
        }
        self.references.reset();
        if self.job.is_some() {
            self.job = None;
            self.state.busy = false;
        }
        self.installed();
        let _ = self.store_records();
        Ok(())
    }

    /// The compensator as it was right after [`App::load_stored`] (never
    /// stepped), for a board that timed compensator steps on the app's own
    /// compensator at boot: call it before anything else changed the app.
    pub fn restart_compensation(&mut self) {
        self.clear_compensation();
        self.load_stored();
    }

    /// No model and a fresh compensator, in place.
    fn clear_compensation(&mut self) {
        self.compensation.clear();
    }

    /// After the compensator's model changed or restarted: its sensors
    /// resolved through the map in force, the kept reference and limits
    /// applied, the model's registers published.
    fn installed(&mut self) {
        self.compensation.resolve(&self.map);
        self.apply_kept_reference();
        self.apply_limits();
        for (i, ch) in self.snapshot.sensor_channels.iter_mut().enumerate() {
            *ch = self.compensation.channel_of(i).unwrap_or(0xFF);
        }
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
        self.snapshot.model_crc = crc;
        self.snapshot.n_directions = register_count(nd);
        self.snapshot.n_axes = register_count(na);
        self.snapshot.n_sensors = register_count(ns);
        // No temperatures of the new section's sensors yet: "sensor fault"
        // (not available) until the next cycle, never the old model's values.
        self.vol_temps = [None; MAX_VOL_SENSORS];
        self.vol_held = false;
        self.update_volumetric(self.vol_uptime_ms);
    }

    /// Evaluate the volumetric correction (image section kind 3, and the
    /// five-axis part of kind 4 at the PLC's A and C) at the PLC's
    /// positions and tool length with the last cycle's temperatures, into
    /// input registers 180–199 and 330–359 ([`crate::volumetric`]).
    /// Without a section, without positions (or, with kind 4, angles) from
    /// the PLC or with a sensor fault the correction registers read "not
    /// available" (0x8000 0000) and the status says why.
    pub fn update_volumetric(&mut self, uptime_ms: u64) {
        self.vol_uptime_ms = uptime_ms;
        let plc = &self.state.plc;
        let cx = VolContext {
            temps: &self.vol_temps,
            held: self.vol_held,
            plc_stale: plc.stale(uptime_ms),
            sequence: self.snapshot.vol.sequence.wrapping_add(1),
        };
        self.snapshot.vol = crate::volumetric::snapshot(self.compensation.model(), plc, &cx);
    }

    fn apply_limits(&mut self) {
        let (clamp, rate) = (self.state.settings.clamp, self.state.settings.rate);
        // 0xFFFF: no override.
        let limit = |v: u16| {
            if v == u16::MAX {
                i32::MAX
            } else {
                i32::from(v)
            }
        };
        for (d, (&c, &r)) in clamp.iter().zip(rate.iter()).enumerate() {
            self.compensation
                .compensator()
                .set_limit_override(d, limit(c), limit(r));
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
        let plc = self.state.plc.inputs(uptime_ms, spindle_override);
        if self.reference_pending {
            self.take_reference(acq, now_ms);
        }
        let out = self.compensation.step(acq, now_ms, &plc);
        (self.vol_temps, self.vol_held) = self.compensation.vol_temperatures(acq, now_ms);
        self.update_volumetric(uptime_ms);
        self.progress.cycles = self.progress.cycles.wrapping_add(1);
        let s = &mut self.snapshot;
        s.sequence = s.sequence.wrapping_add(1);
        s.heartbeat = s.heartbeat.wrapping_add(1);
        // The registers hold the low 32 bits of the seconds (136 years).
        s.uptime_s = ((uptime_ms / 1000) & 0xFFFF_FFFF) as u32;
        s.sample_time_s = ((now_ms / 1000) & 0xFFFF_FFFF) as u32;
        s.status = out.status;
        // The model's served correction plus each direction's probe terms.
        let (limits, n_dir) = self.served_limits();
        let s = &mut self.snapshot;
        s.corrections = self
            .references
            .serve(&out.corrections, limits, n_dir, now_ms);
        self.ask_after_cycle(now_ms, (!plc.stale).then_some(plc.spindle_rpm));
        self.publish_references();
        let s = &mut self.snapshot;
        s.predictions = out.predicted;
        s.axes = out.axes;
        s.map_missing = 0;
        s.active = out.active;
        s.envelope_steps = self.compensation.compensator().envelope_steps();
        let channels = s.temperatures.iter_mut().zip(s.states.iter_mut());
        for (c, (temperature, state)) in channels.enumerate() {
            let v = acq.value(c, now_ms);
            *temperature = v.usable().map(centidegrees);
            *state = v.state.code();
            if self.map.get(c).is_some()
                && matches!(
                    v.state,
                    ChannelState::NoPresence | ChannelState::Disconnected
                )
            {
                s.map_missing |= 1 << c;
            }
        }
        // A model sensor whose ROM is not mapped, or whose channel does not answer.
        let n = self.compensation.model().map_or(0, |m| m.sensors.len());
        s.sensors_missing = (0..n.min(32)).fold(0u32, |m, i| {
            let gone = self.compensation.channel_of(i).is_none_or(|c| {
                matches!(
                    acq.value(usize::from(c), now_ms).state,
                    ChannelState::Unused | ChannelState::NoPresence | ChannelState::Disconnected
                )
            });
            m | (u32::from(gone) << i)
        });
        out
    }

    /// A cycle without a sample (the bench's trace has ended): the loop is
    /// alive, so the watchdog sees progress, but nothing is measured.
    pub fn idle_cycle(&mut self) {
        self.progress.cycles = self.progress.cycles.wrapping_add(1);
    }

    /// Handle one request frame; `reply` gets the answer (empty: stay silent).
    pub fn request(
        &mut self,
        frame: &[u8],
        uptime_ms: u64,
        reply: &mut heapless::Vec<u8, MAX_FRAME>,
    ) -> LinkChange {
        let geometry_before = self.state.plc.geometry();
        let (snapshot, state) = (&self.snapshot, &mut self.state);
        // A commit check parses the candidate in the compensator's model
        // and puts the model in force back from its slot.
        let mut lend = LendModel {
            compensator: self.compensation.compensator(),
            store: &self.store,
        };
        let command = self
            .server
            .handle_lending(frame, uptime_ms, snapshot, state, reply, &mut lend);
        if self.state.plc.geometry() != geometry_before {
            // New positions, tool length or angles: the volumetric correction follows
            // at once (not at the next cycle), so the PLC's next read has it.
            self.update_volumetric(uptime_ms);
        }
        match command {
            Command::None => LinkChange::None,
            Command::CommitModel { len } => {
                // The server validated the image; it is written to the other
                // slot in the background (poll_flash) and swapped in when done.
                self.job = Some(FlashJob::Model {
                    len,
                    erasing: false,
                });
                self.state.busy = true;
                self.state.result = result::COMMIT_IN_PROGRESS;
                LinkChange::None
            }
            Command::Rereference if self.state.probe.direction.is_some() => {
                self.probe_command(command);
                LinkChange::None
            }
            Command::Rereference
                if self.kept.is_some()
                    || self.compensation.model().is_some_and(|m| {
                        m.flags & thermocomp_core::image::FLAG_FIXED_REFERENCE != 0
                    }) =>
            {
                // A machine with a fixed reference: the new sample is kept.
                self.request_reference();
                LinkChange::None
            }
            Command::KeepReference => {
                self.request_reference();
                LinkChange::None
            }
            Command::ForgetReference => {
                self.kept = None;
                self.reference_pending = false;
                self.snapshot.reference_state = 0;
                self.state.result = result::OK;
                self.store_settings();
                LinkChange::None
            }
            Command::Rereference => {
                self.compensation.compensator().rereference();
                LinkChange::None
            }
            Command::TakeProbeReference
            | Command::ResetReferenceTerms
            | Command::ProbeSetupChanged
            | Command::RuleChanged => {
                self.probe_command(command);
                LinkChange::None
            }
            Command::LimitsChanged => {
                self.apply_limits();
                self.store_settings();
                LinkChange::None
            }
            Command::LinkChanged => {
                self.store_settings();
                LinkChange::Reconfigure {
                    baud: self.state.settings.baud,
                }
            }
            Command::ClearFault => {
                self.snapshot.fault = None;
                LinkChange::ClearFaultRecord
            }
            Command::RestoreDefaults => {
                // No fixed reference either (the one in use stays until
                // the next boot or command 2).
                self.kept = None;
                self.reference_pending = false;
                self.snapshot.reference_state = 0;
                self.state.settings = self.defaults;
                self.state.probe = ProbeSetup::default();
                self.state.ask = AskParams::default();
                self.state.rule = [rule::DEFAULT; rule::N];
                self.rule_in_force();
                self.apply_limits();
                self.store_settings();
                LinkChange::Reconfigure {
                    baud: self.defaults.baud,
                }
            }
            Command::KeysChanged | Command::AskChanged => {
                // In force at once; stored like the settings (23, then 0 or 22).
                self.store_settings();
                LinkChange::None
            }
            Command::TestPanic => LinkChange::TestPanic,
            Command::TestStall => {
                self.stall_requested = true;
                LinkChange::None
            }
        }
    }
}

/// A model's count (directions, axes, sensors, terms: far below 65,535) as a register.
fn register_count(n: usize) -> u16 {
    u16::try_from(n).unwrap_or(u16::MAX)
}

/// The commit check's [`ParseCandidate`] on a board: the candidate is
/// parsed in the compensator's own model storage, and the model in force
/// is parsed back from its slot where the flash maps it
/// ([`Compensator::check_with`], [`ModelStore::reparse_active`]): no second
/// model (≈ 17 KB) on the Modbus task's stack.
struct LendModel<'a, F: BackgroundErase> {
    compensator: &'a mut Compensator,
    store: &'a ModelStore<F>,
}

impl<F: BackgroundErase> ParseCandidate for LendModel<'_, F> {
    fn parse_candidate(&mut self, image: &[u8]) -> Result<u32, ImageError> {
        let store = self.store;
        self.compensator.check_with(
            |m| m.parse_into(image).map(|()| m.model_version),
            |m| store.reparse_active(m),
        )
    }
}

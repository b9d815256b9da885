//! What a board, the runtime and the tests may look at (and the few
//! things they may set) of the app, by name: its fields stay its own.

use thermocomp_core::{Compensator, Model};

use super::App;
use crate::compensation::Compensation;
use crate::hal::flash::BackgroundErase;
use crate::keys::Keys;
use crate::plc::PlcState;
use crate::probe_reference::{ProbeSetup, References};
use crate::snapshot::Snapshot;
use crate::watchdog::Progress;

impl<F: BackgroundErase> App<F> {
    /// What the board reports now (the input registers' source).
    pub fn snapshot(&self) -> &Snapshot {
        &self.snapshot
    }

    /// Version of the model serving now (0: none).
    pub fn model_version(&self) -> u32 {
        self.snapshot.model_version
    }

    /// CRC-32 of the model serving now (0: none).
    pub fn model_crc(&self) -> u32 {
        self.snapshot.model_crc
    }

    /// The result of the last command (HR_RESULT).
    pub fn result(&self) -> u16 {
        self.state.result
    }

    /// The keys in force (the unlock key is never shown on the wire).
    pub fn keys(&self) -> &Keys {
        &self.state.keys
    }

    /// The probe setup in force (holding registers 40–45).
    pub fn probe_setup(&self) -> ProbeSetup {
        self.state.probe
    }

    /// What the PLC wrote, and when.
    pub fn plc(&self) -> &PlcState {
        &self.state.plc
    }

    /// Is the board unlocked at `now_ms`?
    pub fn unlocked(&self, now_ms: u64) -> bool {
        self.server.unlocked(now_ms)
    }

    /// The model serving now.
    pub fn model(&self) -> Option<&Model> {
        self.compensation.model()
    }

    /// The model's sensors resolved to bus channels, and its compensator.
    pub fn compensation(&self) -> &Compensation {
        &self.compensation
    }

    /// The compensator itself (a board timing its steps at boot; tests).
    pub fn compensator(&mut self) -> &mut Compensator {
        self.compensation.compensator()
    }

    /// The probe references' terms.
    pub fn references(&self) -> &References {
        &self.references
    }

    /// The flash under the model slots and the settings store.
    pub fn flash_mut(&mut self) -> &mut F {
        self.store.flash()
    }

    /// The test-only command 9 asked the measurement loop to stop.
    pub fn stall_requested(&self) -> bool {
        self.stall_requested
    }

    /// The measurement loop has booted ([`crate::runtime`]).
    pub fn booted(&self) -> bool {
        self.booted
    }

    /// The measurement loop's boot is done: Modbus frames are answered.
    pub fn set_booted(&mut self) {
        self.booted = true;
    }

    /// The progress counters the watchdog feeder looks at.
    pub fn progress(&self) -> Progress {
        self.progress
    }

    /// The Modbus task's side of the progress counters.
    pub fn progress_mut(&mut self) -> &mut Progress {
        &mut self.progress
    }
}

//! The application's side of probe references (issue 28): the probe
//! reading after a cycle, commands 2 (with a probe direction), 12 and 13,
//! holding registers 40–48 and 90–99, input registers 23 and 300–329.

use thermocomp_core::limits::MAX_DIRECTIONS;
use thermocomp_protocol::holding::result;
use thermocomp_protocol::registers::IR_REF_TIME;

use super::App;
use crate::acquisition::temperature::{TemperatureAcquisition, Validity};
use crate::hal::flash::BackgroundErase;
use crate::probe_reference::Taken;
use crate::state::Command;

impl<F: BackgroundErase> App<F> {
    /// Per direction the clamp in force (the model's max correction, or the
    /// tighter override of holding registers 20–25), and the direction count.
    pub(super) fn served_limits(&self) -> ([i32; MAX_DIRECTIONS], usize) {
        let Some(m) = self.compensation.model() else {
            return ([0; MAX_DIRECTIONS], 0);
        };
        let clamp = &self.state.settings.clamp;
        let limits = core::array::from_fn(|d| {
            let own = m.directions.get(d).map_or(0, |dir| dir.max_correction);
            match clamp.get(d) {
                Some(&c) if c != u16::MAX => own.min(i32::from(c)),
                _ => own,
            }
        });
        (limits, m.directions.len())
    }

    /// Publish the eddy-current probe's latest reading (0.1 µm and state
    /// code); with `reference` (the reading averaged over holding register
    /// 41's samples for a pending command 12) take the probe reference with
    /// it against the last cycle ([`App::take_probe_reference`]).
    pub fn set_probe(
        &mut self,
        reading: &crate::acquisition::probe::ProbeReading,
        reference: Option<(&TemperatureAcquisition, u64)>,
    ) {
        self.snapshot.probe = reading.tenth_um.unwrap_or(0);
        self.snapshot.probe_state = reading.state.code();
        if let Some((acq, now_ms)) = reference {
            let ok = reading.state == thermocomp_protocol::states::ProbeState::Ok;
            self.take_probe_reference(ok.then_some(reading.tenth_um).flatten(), acq, now_ms);
        }
    }

    /// ADC samples the next probe reading averages: `Some` while a probe
    /// reference (command 12) is pending, then that reading is the reference.
    pub fn probe_reference_samples(&self) -> Option<u16> {
        self.references.pending_samples(&self.state.probe)
    }

    /// The pending probe reference with this reading (0.1 µm; `None`: the
    /// board has no probe or its reading is not OK): the rule runs, the
    /// served corrections follow at once, the state is stored; HR_RESULT
    /// says what happened (0 accepted, 61 refused, 62–64 not taken).
    pub fn take_probe_reference(
        &mut self,
        reading: Option<i32>,
        acq: &TemperatureAcquisition,
        now_ms: u64,
    ) {
        let setup = self.state.probe;
        let temp = setup.temp_channel.and_then(|c| {
            let v = acq.value(usize::from(c), now_ms);
            (v.validity == Validity::Fresh).then_some(i32::from(v.raw))
        });
        match self.references.take(reading, temp, &setup) {
            Taken::NotTaken(code) => {
                self.state.result = code;
                // A settings store still running ends by writing its result:
                // it must end on this refusal, not on 0 ("accepted").
                if self.job.is_some() {
                    self.stored_result = Some(code);
                }
            }
            Taken::Done(outcome) => {
                self.snapshot.corrections = self.references.served();
                let code = match outcome {
                    thermocomp_core::reference::ReferenceOutcome::Accepted { .. } => result::OK,
                    thermocomp_core::reference::ReferenceOutcome::Refused { .. } => {
                        result::REFERENCE_REFUSED
                    }
                };
                if code == result::OK {
                    let ask = self.state.ask;
                    self.references.ask_referenced(&ask, now_ms);
                }
                self.stored_result = Some(code);
                self.publish_references();
                self.store_settings();
                if self.job.is_none() {
                    // Nothing to store (cannot happen: the counts moved).
                    self.stored_result = None;
                    self.state.result = code;
                }
            }
        }
    }

    /// Commands 2 (a machine with a probe direction), 12 and 13, and a
    /// write of holding registers 40–45 or 90–99.
    pub(super) fn probe_command(&mut self, command: Command) {
        match command {
            Command::Rereference => {
                // A machine with probe references works in the gauge's frame:
                // command 2 is the operator's touch-off, the served correction
                // restarts from 0 now and the model keeps its reference sample.
                self.references.rezero();
                self.snapshot.corrections = self.references.served();
                self.state.result = result::OK;
                self.store_settings();
            }
            Command::TakeProbeReference => {
                self.references.request();
                self.state.result = result::PROBE_REFERENCE_PENDING;
            }
            Command::ResetReferenceTerms => {
                self.references.reset();
                self.snapshot.corrections = self.references.served();
                self.state.result = result::OK;
                self.store_settings();
            }
            Command::RuleChanged => {
                self.rule_in_force();
                self.store_settings();
            }
            _ => self.store_settings(),
        }
        self.publish_references();
    }

    /// The rule that asks for a reference, after a cycle at `now_ms` with
    /// the spindle at `rpm` ([`thermocomp_core::ask`]; holding registers
    /// 46–48). It runs only with a probe direction set (holding register
    /// 40). A request raised is stored at once, quietly, so that a reset
    /// keeps it; input register 23 shows it.
    pub(super) fn ask_after_cycle(&mut self, now_ms: u64, rpm: Option<i32>) {
        let ask = self.state.ask;
        if self.state.probe.direction.is_some() && self.references.ask_step(&ask, now_ms, rpm) {
            self.store_quietly();
        }
    }

    /// The rule's parameters as holding registers 90–99 say, in force at
    /// once: the served corrections follow ([`crate::probe_reference::References::set_params`]).
    pub(super) fn rule_in_force(&mut self) {
        let params = thermocomp_protocol::holding::rule::decode(&self.state.rule);
        self.references.set_params(params);
        self.snapshot.corrections = self.references.served();
    }

    /// Input registers 23 and 300–329 from the terms as they are now.
    pub(super) fn publish_references(&mut self) {
        self.snapshot.reference_wanted = self.references.wanted() as u16;
        let dir = self.state.probe.direction;
        for (a, r) in (IR_REF_TIME..).zip(self.snapshot.references.iter_mut()) {
            *r = self.references.register(a, dir);
        }
    }
}

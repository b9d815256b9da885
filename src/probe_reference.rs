//! Probe references on the board (issue 28): the learned correction terms
//! per direction, updated from a probe reading at a fixed gauge by the math
//! core's rule ([`thermocomp_core::reference`], the very code `tcomp replay
//! --reference-every` runs), the operator's re-zero, and what the slots keep.
//!
//! Served per direction: `model + b(t) − z` ([`ReferenceState::serve`])
//! where `model` is the compensator's served correction at that cycle. The
//! terms never feed back into the compensator.
//!
//! Which direction the probe measures: holding register 40 (default 0,
//! the image's first direction; 0xFFFF none), stored with the settings.
//! A reference reading is the averaged probe (0.1 µm) with the probe's own
//! drift removed (`reading − k·(T − 20 °C)`, holding registers 42–43)
//! minus the gauge zero (44–45): the displacement of the gauge since the
//! machine's reference state, the model's frame.
//!
//! Time: the cycle's sample time (ms since boot in the field, the trace's
//! time on the bench). The board has no clock across a reset: the stored
//! state's last reference is taken as made at the first cycle after boot
//! (the time the board was off is not counted; the terms resume as they
//! were stored).

use thermocomp_core::ask::{AskParams, AskReason, AskState, ASK_STATE_BYTES};
use thermocomp_core::limits::MAX_DIRECTIONS;
use thermocomp_core::reference::{
    remove_probe_drift, ReferenceOutcome, ReferenceParams, ReferenceState, STATE_BYTES,
};
use thermocomp_protocol::holding::{result, DEFAULT_PROBE_DIRECTION, DEFAULT_REFERENCE_SAMPLES};
use thermocomp_protocol::registers::{
    IR_REF_ACCEPTED, IR_REF_BIAS, IR_REF_INNOVATION, IR_REF_REFUSED, IR_REF_TIME, IR_REF_ZERO,
};

/// The probe setup (holding registers 40–45): which direction the probe
/// measures, how it is averaged, its temperature and drift, its gauge zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeSetup {
    /// Model direction the probe measures (`None`: references refused).
    pub direction: Option<u8>,
    /// ADC samples averaged per reference, 1..=1024.
    pub samples: u16,
    /// Bus channel of the probe's DS18B20 (`None`: no drift removed).
    pub temp_channel: Option<u8>,
    /// The probe's drift, nm/K.
    pub drift_nm_per_k: i16,
    /// Probe reading at the gauge at the machine's reference state, 0.1 µm.
    pub gauge_zero: i32,
}

impl Default for ProbeSetup {
    fn default() -> Self {
        ProbeSetup {
            direction: u8::try_from(DEFAULT_PROBE_DIRECTION).ok(),
            samples: DEFAULT_REFERENCE_SAMPLES,
            temp_channel: None,
            drift_nm_per_k: 0,
            gauge_zero: 0,
        }
    }
}

/// Stored block: tag, version, the setup (direction, samples, temperature
/// channel, drift, gauge zero: 10 bytes), one state per direction.
pub const BLOCK_LEN: usize = 2 + SETUP_LEN + MAX_DIRECTIONS * STATE_BYTES;
const SETUP_LEN: usize = 10;
/// Tag of the block in the settings slot (`settings::tail_records`).
pub const TAG: u8 = b'Q';
const VERSION: u8 = 1;
/// "None" for a stored index (direction, channel).
const NONE_U8: u8 = 0xFF;

pub struct References {
    /// The rule's parameters (holding registers 90–99; by default the
    /// core's, tuned on FL_THERMAL's last 20 %: BENCHMARKS.md "Closing the
    /// loop with the probe"); set by [`References::set_params`].
    params: ReferenceParams,
    states: [ReferenceState; MAX_DIRECTIONS],
    /// Command 12 accepted: take the reference with the next probe reading.
    pending: bool,
    /// Loaded from the slots: the first cycle re-bases the last reference time.
    rebase: bool,
    /// The compensator's served correction per direction at the last cycle
    /// (0.1 µm), the clamp in force, the model's direction count, the time.
    model: [i32; MAX_DIRECTIONS],
    limit: [i32; MAX_DIRECTIONS],
    n: usize,
    now_ms: Option<u64>,
    /// When to ask for a reference ([`thermocomp_core::ask`]).
    ask: AskState,
    /// The rule's state as stored, as of its last event (a request raised,
    /// a reference accepted): the ask record holds this, so that it changes
    /// only then and not at every cycle.
    ask_saved: [u8; ASK_STATE_BYTES],
    /// The rule has not run since boot: its first cycle starts it (from
    /// `ask_saved` when the store held one, else afresh).
    ask_fresh: bool,
    ask_loaded: bool,
}

impl Default for References {
    fn default() -> Self {
        Self::new()
    }
}

/// What a reference did, for HR_RESULT and the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taken {
    /// The rule ran: accepted or refused (both change the stored state).
    Done(ReferenceOutcome),
    /// Not taken (a result code 62–64); nothing changed.
    NotTaken(u16),
}

impl References {
    pub fn new() -> Self {
        let params = ReferenceParams::DEFAULT;
        References {
            params,
            states: [ReferenceState::new(&params); MAX_DIRECTIONS],
            pending: false,
            rebase: false,
            model: [0; MAX_DIRECTIONS],
            limit: [0; MAX_DIRECTIONS],
            n: 0,
            now_ms: None,
            ask: AskState::new(0),
            ask_saved: AskState::new(0).to_bytes(0),
            ask_fresh: true,
            ask_loaded: false,
        }
    }

    /// One look of the reference-request rule at `now_ms` with the spindle
    /// at `rpm`: `true` when it raised a request (store the state then).
    pub fn ask_step(&mut self, params: &AskParams, now_ms: u64, rpm: Option<i32>) -> bool {
        if self.ask_fresh {
            let stored = self
                .ask_loaded
                .then(|| AskState::restore(&self.ask_saved, now_ms));
            self.ask = stored.flatten().unwrap_or(AskState::new(now_ms));
            self.ask_fresh = false;
        }
        let raised = self.ask.step(params, now_ms, rpm);
        if raised {
            self.ask_saved = self.ask.to_bytes(now_ms);
        }
        raised
    }

    /// A reference was accepted at `now_ms`: the request clears and the
    /// schedule starts again from here.
    pub fn ask_referenced(&mut self, params: &AskParams, now_ms: u64) {
        self.ask.referenced(params, now_ms);
        self.ask_saved = self.ask.to_bytes(now_ms);
    }

    /// Why a reference is wanted now.
    pub fn wanted(&self) -> AskReason {
        self.ask.wanted()
    }

    /// The rule's state as the store keeps it.
    pub fn ask_saved(&self) -> &[u8; ASK_STATE_BYTES] {
        &self.ask_saved
    }

    /// A stored state, taken up at the first cycle (`false`: not of this
    /// length; nothing changes).
    pub fn load_ask(&mut self, b: &[u8]) -> bool {
        let Ok(b) = <[u8; ASK_STATE_BYTES]>::try_from(b) else {
            return false;
        };
        self.ask_saved = b;
        self.ask_loaded = true;
        self.ask_fresh = true;
        true
    }

    /// The rule's parameters from now on (holding registers 90–99). A
    /// direction without an accepted reference yet starts from these
    /// parameters' prior, as a fresh state would; the others go on from
    /// what they learned.
    pub fn set_params(&mut self, params: ReferenceParams) {
        self.params = params;
        let prior = ReferenceState::new(&params).p;
        for st in &mut self.states {
            if st.last_ms.is_none() {
                st.p = prior;
            }
        }
    }

    /// Command 13 or a new model: every direction's terms and re-zero
    /// offset back to nothing (the prior).
    pub fn reset(&mut self) {
        self.states = [ReferenceState::new(&self.params); MAX_DIRECTIONS];
        self.rebase = false;
    }

    /// The state of direction `d` (tests, logs).
    pub fn state(&self, d: usize) -> Option<&ReferenceState> {
        self.states.get(d)
    }

    /// Command 12: take a reference with the next probe reading.
    pub fn request(&mut self) {
        self.pending = true;
    }

    /// ADC samples to average now: `Some(samples)` while a reference is pending.
    pub fn pending_samples(&self, setup: &ProbeSetup) -> Option<u16> {
        self.pending.then_some(setup.samples)
    }

    /// After a compensator step: the served correction per direction (0.1 µm),
    /// `model` plus each direction's terms, for the model's `n` directions
    /// clamped to `limit`; directions past `n` as the compensator gave them.
    pub fn serve(
        &mut self,
        model: &[i32; MAX_DIRECTIONS],
        limit: [i32; MAX_DIRECTIONS],
        n: usize,
        now_ms: u64,
    ) -> [i32; MAX_DIRECTIONS] {
        if self.rebase {
            for st in &mut self.states {
                if st.last_ms.is_some() {
                    st.last_ms = Some(now_ms);
                }
            }
            self.rebase = false;
        }
        self.model = *model;
        self.limit = limit;
        self.n = n.min(MAX_DIRECTIONS);
        self.now_ms = Some(now_ms);
        self.served()
    }

    /// The served corrections at the last cycle with the terms as they are now.
    pub fn served(&self) -> [i32; MAX_DIRECTIONS] {
        let mut out = self.model;
        let Some(now) = self.now_ms else {
            return out;
        };
        for (d, o) in out.iter_mut().enumerate().take(self.n) {
            if let (Some(st), Some(&l)) = (self.states.get(d), self.limit.get(d)) {
                *o = st.serve(&self.params, now, *o, l);
            }
        }
        out
    }

    /// The pending reference with this probe reading (0.1 µm; `None`: the
    /// probe is not OK) and the probe's temperature (1/16 °C; `None`: no
    /// fresh value), against the last cycle's model output.
    pub fn take(
        &mut self,
        reading: Option<i32>,
        probe_temp: Option<i32>,
        setup: &ProbeSetup,
    ) -> Taken {
        self.pending = false;
        let d = setup.direction.map(usize::from).filter(|&d| d < self.n);
        let (Some(d), Some(now)) = (d, self.now_ms) else {
            return Taken::NotTaken(result::NO_PROBE_DIRECTION);
        };
        let Some(reading) = reading else {
            return Taken::NotTaken(result::PROBE_NOT_READY);
        };
        let reading = match (setup.temp_channel, probe_temp) {
            (None, _) => reading,
            (Some(_), Some(t)) => remove_probe_drift(reading, t, setup.drift_nm_per_k.into()),
            (Some(_), None) => return Taken::NotTaken(result::PROBE_TEMPERATURE_MISSING),
        };
        let y = reading.saturating_sub(setup.gauge_zero);
        let (Some(st), Some(&m)) = (self.states.get_mut(d), self.model.get(d)) else {
            return Taken::NotTaken(result::NO_PROBE_DIRECTION);
        };
        Taken::Done(st.reference(&self.params, now, m, y))
    }

    /// Command 2 (the operator's touch-off): every direction's served
    /// correction restarts from 0 at the last cycle ([`ReferenceState::rezero`]).
    pub fn rezero(&mut self) {
        let Some(now) = self.now_ms else {
            return;
        };
        for (st, &m) in self.states.iter_mut().zip(&self.model).take(self.n) {
            st.rezero(&self.params, now, m);
        }
    }

    /// Input registers 300–329 for the probe's direction `dir`.
    pub fn register(&self, addr: u16, dir: Option<u8>) -> u16 {
        let now = self.now_ms.unwrap_or(0);
        let probe = dir.and_then(|d| self.states.get(usize::from(d)));
        let hi = |v: u32| (v >> 16) as u16;
        let lo = |v: u32| (v & 0xFFFF) as u16;
        let word = |base: u16, v: u32| match addr.wrapping_sub(base) {
            0 => Some(hi(v)),
            1 => Some(lo(v)),
            _ => None,
        };
        let time = probe.and_then(|s| s.last_ms).map_or(u32::MAX, |t| {
            u32::try_from(t / 1000).unwrap_or(u32::MAX - 1)
        });
        let innovation = probe.map_or(0, |s| div_round(i64::from(s.last_innovation_nm), 100));
        if let Some(w) = word(IR_REF_TIME, time) {
            return w;
        }
        if let Some(w) = word(IR_REF_INNOVATION, sat_i32(innovation) as u32) {
            return w;
        }
        if addr == IR_REF_ACCEPTED {
            return probe.map_or(0, |s| s.accepted);
        }
        if addr == IR_REF_REFUSED {
            return probe.map_or(0, |s| s.refused);
        }
        let k = usize::from(addr.wrapping_sub(IR_REF_BIAS));
        if k < 2 * MAX_DIRECTIONS {
            let Some(st) = self.states.get(k % MAX_DIRECTIONS) else {
                return 0;
            };
            let (b, s) = st.terms_at(&self.params, now);
            let v = if k < MAX_DIRECTIONS { b } else { s };
            return sat_i16(div_round(v, 100)) as u16;
        }
        let k = usize::from(addr.wrapping_sub(IR_REF_ZERO));
        match self.states.get(k / 2) {
            Some(st) if k < 2 * MAX_DIRECTIONS => {
                let z = sat_i32(div_round(i64::from(st.zero_nm), 100)) as u32;
                if k % 2 == 0 {
                    hi(z)
                } else {
                    lo(z)
                }
            }
            _ => 0,
        }
    }

    /// The stored block of the old slot layout (before issue 47): the
    /// setup (holding registers 40–45) and the states. Still written by
    /// tests that build an old-layout board; the board itself now keeps
    /// the setup and each direction's state as records of their own
    /// ([`crate::settings_store`]).
    pub fn encode(&self, setup: &ProbeSetup) -> [u8; BLOCK_LEN] {
        let mut b = [0u8; BLOCK_LEN];
        let (head, states) = b.split_at_mut(SETUP_RECORD_LEN);
        head.copy_from_slice(&encode_setup(setup));
        let (chunks, _) = states.as_chunks_mut::<STATE_BYTES>();
        for (c, st) in chunks.iter_mut().zip(&self.states) {
            *c = st.to_bytes();
        }
        b
    }

    /// A stored block of the old slot layout back: the setup and the
    /// states in force, to be re-based at the first cycle. `None` (nothing
    /// changed) for another tag, version or length, a value out of range
    /// or a state the core refuses.
    pub fn decode(&mut self, b: &[u8]) -> Option<ProbeSetup> {
        if b.len() != BLOCK_LEN {
            return None;
        }
        let (head, rest) = b.split_at_checked(SETUP_RECORD_LEN)?;
        let setup = decode_setup(head)?;
        let mut states = [ReferenceState::default(); MAX_DIRECTIONS];
        let (chunks, _) = rest.as_chunks::<STATE_BYTES>();
        for (st, c) in states.iter_mut().zip(chunks) {
            *st = ReferenceState::from_bytes(c).ok()?;
        }
        self.load_states(states);
        Some(setup)
    }

    /// Direction `d`'s state as stored (`None`: no such direction).
    pub fn state_bytes(&self, d: usize) -> Option<[u8; STATE_BYTES]> {
        self.states.get(d).map(ReferenceState::to_bytes)
    }

    /// Stored states in force, to be re-based at the first cycle.
    pub fn load_states(&mut self, states: [ReferenceState; MAX_DIRECTIONS]) {
        self.states = states;
        self.rebase = true;
    }
}

/// Length of the stored probe setup: tag, version, 10 bytes of setup.
pub const SETUP_RECORD_LEN: usize = 2 + SETUP_LEN;

/// The probe setup (holding registers 40–45) as stored.
pub fn encode_setup(setup: &ProbeSetup) -> [u8; SETUP_RECORD_LEN] {
    let [s0, s1] = setup.samples.to_le_bytes();
    let [k0, k1] = setup.drift_nm_per_k.to_le_bytes();
    let [g0, g1, g2, g3] = setup.gauge_zero.to_le_bytes();
    [
        TAG,
        VERSION,
        setup.direction.unwrap_or(NONE_U8),
        s0,
        s1,
        setup.temp_channel.unwrap_or(NONE_U8),
        k0,
        k1,
        g0,
        g1,
        g2,
        g3,
    ]
}

/// A stored probe setup back; `None` for another tag, version or length,
/// or a value out of range.
pub fn decode_setup(b: &[u8]) -> Option<ProbeSetup> {
    let &[tag, version, dir, s0, s1, ch, k0, k1, g0, g1, g2, g3] = b else {
        return None;
    };
    if tag != TAG || version != VERSION {
        return None;
    }
    let index = |v: u8, n: usize| match v {
        NONE_U8 => Some(None),
        v if usize::from(v) < n => Some(Some(v)),
        _ => None,
    };
    let samples = u16::from_le_bytes([s0, s1]);
    if !(1..=crate::acquisition::probe::MAX_OVERSAMPLE).contains(&samples) {
        return None;
    }
    Some(ProbeSetup {
        direction: index(dir, MAX_DIRECTIONS)?,
        samples,
        temp_channel: index(ch, thermocomp_protocol::MAX_CHANNELS)?,
        drift_nm_per_k: i16::from_le_bytes([k0, k1]),
        gauge_zero: i32::from_le_bytes([g0, g1, g2, g3]),
    })
}

/// Division rounding to nearest, ties away from zero.
fn div_round(n: i64, d: i64) -> i64 {
    if n >= 0 {
        (n + d / 2) / d
    } else {
        -((-n + d / 2) / d)
    }
}

fn sat_i32(v: i64) -> i32 {
    i32::try_from(v).unwrap_or(if v < 0 { i32::MIN } else { i32::MAX })
}

fn sat_i16(v: i64) -> i16 {
    i16::try_from(v).unwrap_or(if v < 0 { i16::MIN } else { i16::MAX })
}

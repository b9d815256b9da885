//! What masters set and the application acts on: the settings, the PLC's
//! data, the probe setup, the keys, the staged image and the result code
//! of the last command ([`AppState`]), and the changes a master's write
//! asks of the application ([`Command`]). The Modbus codec (`modbus/`)
//! decodes holding-register writes into these and encodes reads from
//! them; nothing here knows a register.

use thermocomp_core::ask::AskParams;
use thermocomp_protocol::holding::rule;

use crate::keys::Keys;
use crate::plc::PlcState;
use crate::probe_reference::ProbeSetup;
use crate::settings::Settings;
use crate::staging::Staging;
use thermocomp_protocol::holding::result;

pub struct AppState {
    /// Unit address, baud rate, clamp and rate overrides.
    pub settings: Settings,
    /// What the PLC wrote, and when.
    pub plc: PlcState,
    /// Which direction the probe measures, and how.
    pub probe: ProbeSetup,
    /// When the board asks for a probe reference (all 0: never).
    pub ask: AskParams,
    /// The probe-reference rule's parameters as written (holding registers
    /// 90–99; `rule::DEFAULT`: the firmware's default).
    pub rule: [u16; rule::N],
    /// The unlock key and the signing key ([`Keys`]).
    pub keys: Keys,
    /// The model staging area.
    pub staging: Staging,
    /// The result of the last command (HR_RESULT's codes).
    pub result: u16,
    /// A commit is being written: what it stores must not change.
    pub busy: bool,
}

impl AppState {
    /// Fresh state with the unit address and baud rate `unit`, `baud`.
    // Inlined (as `Staging::new`), so that the board's app is written in its
    // static, not built on the stack and copied (`scripts/size.sh`).
    #[inline(always)]
    pub fn new(unit: u8, baud: u32) -> Self {
        AppState {
            settings: Settings {
                unit,
                baud,
                ..Settings::default()
            },
            plc: PlcState::default(),
            probe: ProbeSetup::default(),
            ask: AskParams::default(),
            rule: [rule::DEFAULT; rule::N],
            keys: Keys::default(),
            staging: Staging::new(),
            result: result::NONE,
            busy: false,
        }
    }
}

/// What the application must do after a write was accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    None,
    /// The staged image (this long) parsed: store it and swap it in.
    CommitModel {
        len: usize,
    },
    Rereference,
    /// Limits changed: apply them to the compensator.
    LimitsChanged,
    /// Unit address or baud rate changed: apply after the reply is sent.
    LinkChanged,
    /// Command 6: forget the fault record.
    ClearFault,
    /// Command 7: back to the default settings.
    RestoreDefaults,
    /// Command 8 (feature `test-faults`): panic after the reply.
    TestPanic,
    /// Command 9 (feature `test-faults`): stall the measurement loop.
    TestStall,
    /// Command 10: take a reference sample and keep it.
    KeepReference,
    /// Command 11: forget the kept reference.
    ForgetReference,
    /// Command 12: take a probe reference after the next cycle.
    TakeProbeReference,
    /// Command 13: reset the learned reference terms.
    ResetReferenceTerms,
    /// Holding registers 40–45 changed: store them.
    ProbeSetupChanged,
    /// Holding registers 46–48 (when to ask for a reference) changed: store them.
    AskChanged,
    /// Holding registers 90–99 (the probe-reference rule) changed: in
    /// force at once, then stored.
    RuleChanged,
    /// Commands 14–16: a key changed (in force at once): store it.
    KeysChanged,
}

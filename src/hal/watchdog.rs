//! The hardware watchdog as the feeder ([`crate::runtime::watchdog_loop`])
//! sees it. The board starts it and states its timeout next to its longest
//! legitimate operation; the feeding rule is the application's
//! ([`crate::watchdog`]).

pub trait Watchdog {
    /// Reload the counter (the board stays alive for another timeout).
    fn pet(&mut self);
    /// What the feeder saw stalled at its last look (0: fed), kept for the
    /// detail word of a watchdog fault record ([`crate::watchdog::stalled`]).
    fn note_stalled(&mut self, bits: u32);
}

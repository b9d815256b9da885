//! The fit-mode room: `tcomp diagnose fit`, the diagnosis without a machine
//! file. `fitmode` scores, claims and ranks the effects of `open_effects`
//! against the identified nominal; `fit_nominal` reports that nominal,
//! `fit_untestable` and `reach` what the runs cannot test, and why,
//! `undecided` what they show but cannot decide; `margins` the claim's levels.

mod coolant_line;
mod fit_nominal;
mod fit_untestable;
pub mod fitmode;
mod margins;
pub mod reach;
mod undecided;

//! Blind check of the diagnoser: generated "measured" runs with withheld
//! effects (singles, pairs, none) at random strengths and duty cycles.
//! `draw` draws the closed-world cases, `closed`, `open` and `cross` run
//! the three worlds, `tally` scores them; `approx` runs issue 27's columns
//! (exact file, design file off by σ = 15 % via `perturb`, no file) scored
//! by `score`; `worlds` runs them on the open, cross and blind third
//! (`third`, its own generator and scorer) worlds with the worst world per
//! column (`worst`); `cpu` reads the process's CPU time.

mod approx;
mod closed;
mod cpu;
mod cross;
mod draw;
pub mod file_truth;
mod open;
mod periodic;
pub mod perturb;
pub mod score;
mod tally;
pub mod third;
mod worlds;
pub mod worst;

pub use approx::{approx_text, run_approx_bench, ApproxConfig, Column, World, HELDOUT_SEEDS};
pub use closed::run_bench;
pub use cross::{cross_cases, run_cross_bench, CrossCase, CROSS_KINDS};
pub use draw::{random_duty, random_effect, BenchConfig};
pub use open::{names_truth, open_cases, run_open_bench, run_open_machine_bench, OpenCase};
pub use periodic::{periodic_cases, run_periodic_bench};
pub use tally::{Visibility, VISIBLE_C, VISIBLE_UM};
pub use worlds::{default_cases, run_worlds, worlds_text, WorldsConfig};

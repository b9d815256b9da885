//! tcomp: the desktop side of thermocomp. Every subcommand is a module here;
//! `main.rs` only parses the command line and dispatches.

pub mod export;
pub mod replay;
pub mod runcsv;
pub mod sim;
pub mod diagnose;
pub mod fit;
pub mod select;

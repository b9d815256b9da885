//! thermocomp: the compensator application, written once against the narrow
//! hardware traits in [`hal`] and run unchanged on every board in `boards/`.
#![no_std]
// No unsafe in the application: registers and RAM the board owns are
// reached only through the board crates (boards/*), behind src/hal traits.
#![forbid(unsafe_code)]

pub mod acquisition;
pub mod app;
pub mod compensation;
pub mod fault;
pub mod hal;
pub mod keys;
pub mod modbus;
pub mod model_store;
pub mod plc;
pub mod probe_reference;
pub mod runtime;
pub mod settings;
pub mod settings_store;
pub mod snapshot;
pub mod staging;
pub mod state;
pub mod volumetric;
pub mod watchdog;

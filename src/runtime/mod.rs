//! The board loop, written once: what every board runs on top of its
//! drivers. A board builds its one [`crate::app::App`] into a `static` before it spawns
//! anything ([`SharedApp`]), then runs
//! - the measurement loop ([`measurement_loop`]): sensor search and
//!   configuration at boot ([`start_sensors`]), the boot report
//!   ([`boot_report`]), then one cycle after another (acquisition,
//!   compensation, snapshot), searching the bus again now and then;
//! - the Modbus server ([`modbus_loop`]);
//! - the watchdog feeder ([`watchdog_loop`]), which also drives a flash
//!   commit in progress.
//!
//! What differs between boards — where a cycle's time and inputs come from,
//! the probe, how a line is logged — is the board's [`CycleSource`]; the
//! hardware is reached only through the [`crate::hal`] traits.

mod boot;
mod feeder;
mod measurement;
mod modbus;
mod shared;

pub use boot::{boot_report, start_sensors, BootReport, SensorStart};
pub use feeder::{watchdog_loop, BOOT_DEADLINE_MS, FEED_CHECK_MS};
pub use measurement::{measurement_loop, CycleDone, CycleInput, CycleSource};
pub use modbus::modbus_loop;
pub use shared::SharedApp;

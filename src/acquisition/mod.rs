//! Sensor acquisition: DS18B20 temperature sensors on a 1-Wire bus and the
//! eddy-current displacement probe on an ADC.
//!
//! - [`bitbang`]: the slot timing on an open-drain pin + busy delay.
//! - [`rom`]: 64-bit ROM codes and the ROM search.
//! - [`ds18b20`]: DS18B20 commands, scratchpad decoding and the scratchpad
//!   faults that the CRC does not catch.
//! - [`channel_map`]: ROM code → channel, persisted as a fixed byte block.
//! - [`temperature`]: the acquisition cycle (Convert T on all, Match ROM +
//!   Read Scratchpad per sensor, retries, plausibility, hold, recovery).
//! - [`probe`]: oversampling, saturation detection and calibration to 0.1 µm.
//!
//! # Why not the `ds18b20` / `one-wire-bus` crates
//! The customer named `one-wire-bus` 0.1.1 and `ds18b20` 0.1.1. They are not
//! used in the firmware; this module replaces them (about 400 lines). The
//! evidence is in `host-tests/tests/acquisition_crates.rs`, which runs both
//! crates against the pin-level emulator:
//! - `ds18b20` decodes the raw value as `u16` (−10.125 °C reads 4085.875 °C)
//!   and divides again below 12 bits (23.5 °C at 9 bits reads 188 °C); its
//!   `read_scratchpad` accepts nine zero bytes (they pass the CRC-8) and
//!   `read_data` rejects them only by accident (config byte 0 is no
//!   resolution) under the wrong name `CrcMismatch`; the 85.0 °C power-on
//!   value comes back as a valid reading.
//! - `one-wire-bus` samples a read slot at 6 + 9 µs = 15 µs after the falling
//!   edge, exactly at the end of the window (tRDV = 15 µs); any delay overshoot
//!   (1 µs per delay call in the emulator) reads the line after the device has
//!   released it and the reading is lost. Its slots (70 µs, reset 960 µs)
//!   make a scratchpad read 11.6 ms against 10.4 ms here.
//! - Both are blocking embedded-hal 0.2 code: the 750 ms conversion would
//!   block the executor; there is no strong pull-up for parasite power.
//!
//! `onewire` 0.4 (embedded-hal 1.0) decodes correctly but is also blocking
//! over `DelayNs` and still takes the delay it is given for slot timing;
//! the slot timing lives in the board's [`crate::hal::onewire::OneWireBus`]
//! implementation instead, where the board can use a cycle counter and mask
//! interrupts for the few microseconds that matter.

pub mod bitbang;
pub mod channel_map;
pub mod ds18b20;
pub mod probe;
pub mod rom;
pub mod temperature;

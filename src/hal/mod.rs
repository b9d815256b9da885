//! The narrow hardware traits the application is written against. Boards in
//! `boards/` implement them; `host-tests` implements them with emulators and
//! fault-injecting mocks. Nothing in this crate names a register.
//!
//! One file per device class, each owned by the part of the application that
//! uses it:
//! - [`clock`]: monotonic time for ages, timeouts and filter time steps.
//! - [`onewire`]: 1-Wire bus master at slot level (DS18B20 sensors).
//! - [`adc`]: one ADC channel (the eddy-current probe).
//! - [`serial`]: the RS-485 Modbus port, one RTU frame at a time.
//! - parameter storage: `embedded_storage::nor_flash::NorFlash` (the model
//!   slots, [`crate::model_store`]), with [`flash::BackgroundErase`] so a
//!   commit's erase runs outside the app lock.
//! - [`watchdog`]: the hardware watchdog the feeder pets.

pub mod adc;
pub mod clock;
pub mod flash;
pub mod onewire;
pub mod serial;
pub mod watchdog;

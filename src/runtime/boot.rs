//! Boot: find and configure the sensors, then settle the app's state before
//! the first cycle (channel map, fault record). Returns what happened; the
//! board logs it in its own way.

use embassy_sync::blocking_mutex::raw::RawMutex;

use super::shared::SharedApp;
use crate::acquisition::channel_map::ChannelMap;
use crate::acquisition::rom::SearchError;
use crate::acquisition::temperature::TemperatureAcquisition;
use crate::fault::{self, FaultBoard, FaultRecord};
use crate::hal::flash::BackgroundErase;
use crate::hal::onewire::OneWireBus;

/// How the sensors answered at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorStart {
    /// The ROM search: sensors found, or why it failed.
    pub found: Result<usize, SearchError>,
    /// The resolution and reset marker were written (some sensor answered).
    pub configured: bool,
}

/// Search the bus, then (with `map`: the board's fixed channel map in
/// force instead of the searched one) write every sensor's configuration.
/// The acquisition starts from the stored channel map, so a search only
/// adds new sensors on free channels, never renumbers the known ones.
pub async fn start_sensors<B: OneWireBus>(
    acq: &mut TemperatureAcquisition,
    bus: &mut B,
    map: Option<ChannelMap>,
) -> SensorStart {
    let found = acq.discover(bus).await;
    if let Some(map) = map {
        acq.set_map(map);
    }
    let configured = matches!(acq.configure(bus).await, Ok(true));
    SensorStart { found, configured }
}

/// What the board reports once booted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BootReport {
    /// The fault that ended the previous run, if one is recorded.
    pub fault: Option<FaultRecord>,
    /// The model in use (0 and 0: none).
    pub model_version: u32,
    pub model_crc: u32,
}

/// The channel map the search settled on (stored with the model, new
/// channels reported) and the fault record of the previous run into the
/// app's registers.
pub fn boot_report<B, M, F>(shared: &SharedApp<M, F>, map: ChannelMap) -> BootReport
where
    B: FaultBoard,
    M: RawMutex,
    F: BackgroundErase,
{
    shared.lock(|a| {
        let mut app = a.borrow_mut();
        app.update_channel_map(map);
        let fault = fault::recorded::<B>();
        app.set_fault_record(fault);
        BootReport {
            fault,
            model_version: app.model_version(),
            model_crc: app.model_crc(),
        }
    })
}

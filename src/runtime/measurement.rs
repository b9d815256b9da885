//! The measurement loop of every board: one acquisition cycle after another,
//! compensated and published under the app lock, the bus searched again
//! every so many cycles.

use embassy_sync::blocking_mutex::raw::RawMutex;
use embedded_hal_async::delay::DelayNs;
use thermocomp_core::{Model, StepOutput};

use super::shared::SharedApp;
use crate::acquisition::probe::ProbeReading;
use crate::acquisition::temperature::{CycleReport, TemperatureAcquisition};
use crate::hal::flash::BackgroundErase;
use crate::hal::onewire::OneWireBus;

/// When one cycle measures, and what replaces the PLC's registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleInput {
    /// Time of the sample (ms): the board's uptime at the cycle's start in
    /// the field, the recorded time on the bench.
    pub now_ms: u64,
    /// Replaces the PLC's spindle-speed register (the bench replays the
    /// recorded speed).
    pub spindle_override: Option<i32>,
}

/// One finished cycle, for the board's log.
pub struct CycleDone<'a> {
    /// Cycles since boot, this one included.
    pub cycle: u32,
    pub input: &'a CycleInput,
    pub report: &'a CycleReport,
    pub out: &'a StepOutput,
    pub acquisition: &'a TemperatureAcquisition,
    /// The model in use (its direction names).
    pub model: Option<&'a Model>,
}

/// What a board brings to the measurement loop besides its 1-Wire bus: the
/// pace and the inputs of each cycle, the probe, the log.
// Both boards run single-threaded executors: no Send bound is wanted.
#[allow(async_fn_in_trait)]
pub trait CycleSource<B: OneWireBus> {
    /// Wait until the next cycle is due; its inputs, or `None` when there
    /// are no more samples (the bench's trace has ended).
    async fn next_cycle(&mut self, bus: &mut B) -> Option<CycleInput>;
    /// Just before the acquisition, after a search of the bus (the bench
    /// puts the sample's temperatures on its emulated sensors here).
    fn prepare(&mut self, _bus: &mut B, _input: &CycleInput) {}
    /// Uptime (ms) the cycle is published at.
    fn uptime_ms(&mut self, input: &CycleInput) -> u64;
    /// Called under the app lock once the cycle is published: log it.
    fn cycle_done(&mut self, done: &CycleDone<'_>);
    /// Read the eddy-current probe, if the board has one (after the cycle);
    /// `reference_samples`: a probe reference is pending, average this many
    /// ADC samples instead of the board's usual count.
    async fn probe(&mut self, _reference_samples: Option<u16>) -> Option<ProbeReading> {
        None
    }
    /// The loop stopped on request (test command 9).
    fn stalled(&mut self) {}
    /// No more samples after `cycles` cycles: from here on the loop idles.
    fn ended(&mut self, _cycles: u32) {}
    /// The pause between two idle cycles.
    async fn idle(&mut self) {
        core::future::pending::<()>().await
    }
}

/// Marks the app booted (Modbus answers, the feeder starts checking), then
/// runs the cycles `source` paces, searching the bus again every
/// `rediscover_every` cycles: sensors added at run time go to free channels
/// (reported in input registers 172–173); missing ones keep their channel
/// and read "no presence", never another sensor's value. When the source
/// has no more samples the loop keeps counting (idle) cycles for the
/// watchdog at the source's pace: it has ended, not stalled.
pub async fn measurement_loop<M, F, B, D, S>(
    shared: &SharedApp<M, F>,
    acq: &mut TemperatureAcquisition,
    bus: &mut B,
    delay: &mut D,
    source: &mut S,
    rediscover_every: u32,
) -> !
where
    M: RawMutex,
    F: BackgroundErase,
    B: OneWireBus,
    D: DelayNs,
    S: CycleSource<B>,
{
    shared.lock(|a| a.borrow_mut().set_booted());
    let mut cycle = 0u32;
    while let Some(input) = source.next_cycle(bus).await {
        cycle = cycle.wrapping_add(1);
        #[cfg(feature = "test-faults")]
        if shared.lock(|a| a.borrow().stall_requested()) {
            // Test command 9: this loop stops making progress (the executor
            // and the Modbus task go on); the watchdog must notice.
            source.stalled();
            core::future::pending::<()>().await;
        }
        if cycle.is_multiple_of(rediscover_every) && acq.discover(bus).await.is_ok() {
            let map = *acq.map();
            shared.lock(|a| a.borrow_mut().update_channel_map(map));
        }
        source.prepare(bus, &input);
        let report = acq.cycle(bus, delay, input.now_ms).await;
        let uptime = source.uptime_ms(&input);
        shared.lock(|a| {
            let mut app = a.borrow_mut();
            let out = app.cycle(acq, input.now_ms, uptime, input.spindle_override);
            source.cycle_done(&CycleDone {
                cycle,
                input: &input,
                report: &report,
                out: &out,
                acquisition: acq,
                model: app.model(),
            });
        });
        // A pending probe reference (command 12) takes this cycle's reading
        // against this cycle's model output; a board without a probe
        // answers it "probe not ready".
        let reference = shared.lock(|a| a.borrow().probe_reference_samples());
        let reading = source.probe(reference).await;
        shared.lock(|a| {
            let mut app = a.borrow_mut();
            let at = reference.map(|_| (&*acq, input.now_ms));
            match &reading {
                Some(r) => app.set_probe(r, at),
                None if reference.is_some() => {
                    app.take_probe_reference(None, acq, input.now_ms);
                }
                None => {}
            }
        });
    }
    source.ended(cycle);
    loop {
        shared.lock(|a| a.borrow_mut().idle_cycle());
        source.idle().await;
    }
}

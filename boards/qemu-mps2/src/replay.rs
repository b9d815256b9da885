//! The `replay` mode: every sample of a run CSV acquired on the emulated bus
//! and compensated, one log line each (the host tests compare them with the
//! desktop's replay).

use core::fmt::Write as _;
use thermocomp::acquisition::temperature::CycleReport;
use thermocomp::compensation::{Compensation, PlcInputs};
use thermocomp_core::{Model, StepOutput};

use crate::exit::{exit_code, finish};
use crate::host_files::{load_model, next_sample_or_exit, open_trace};
use crate::semihost::log;
use crate::sensors::Sensors;

#[embassy_executor::task]
pub async fn replay(path: &'static str, model_path: Option<&'static str>) {
    let mut trace = open_trace(path);
    let channels = trace.header().channels();
    log!("replaying {} ({} temperature channels)", path, channels);
    let (mut sensors, map) = Sensors::emulate(channels);
    sensors.start(map).await;
    let model = model_path.and_then(load_model);
    let mut compensation = Compensation::new(model, sensors.acquisition.map());
    let mut rows = 0u32;
    while let Some(sample) = next_sample_or_exit(&mut trace) {
        rows += 1;
        let report = sensors.acquire(&sample).await;
        let plc = PlcInputs {
            spindle_rpm: sample.spindle_rpm.unwrap_or(0),
            ..PlcInputs::default()
        };
        let out = compensation.step(&sensors.acquisition, sample.time_ms, &plc);
        let ch0 = sensors.acquisition.value(0, sample.time_ms);
        log_correction(
            compensation.model(),
            sample.time_ms,
            &report,
            (ch0.usable(), ch0.state),
            plc.spindle_rpm,
            &out,
        );
    }
    log!("replay done: {} samples", rows);
    finish(exit_code::OK)
}

/// One line per sample: time, sensors, each direction's served correction
/// in µm (and the model's prediction when limits changed it), status bits.
pub fn log_correction(
    model: Option<&Model>,
    t_ms: u64,
    report: &CycleReport,
    ch0: (Option<i16>, thermocomp_protocol::states::ChannelState),
    rpm: i32,
    out: &StepOutput,
) {
    let mut line: heapless::String<200> = heapless::String::new();
    let _ = write!(
        line,
        "t={} ms ok={} faulty={} T0={:?} {:?} rpm={} |",
        t_ms, report.ok, report.faulty, ch0.0, ch0.1, rpm
    );
    if let Some(m) = model {
        for d in 0..m.directions.len() {
            let _ = write!(
                line,
                " {}={}",
                m.direction_name(d),
                Micrometres(out.corrections[d])
            );
            if out.corrections[d] != out.predicted[d] {
                let _ = write!(line, "({})", Micrometres(out.predicted[d]));
            }
        }
    }
    log!(
        "{} um status={:#06x}{}",
        line,
        out.status,
        StatusNames(out.status)
    );
}

/// 0.1 µm as a signed decimal µm value.
struct Micrometres(i32);

impl core::fmt::Display for Micrometres {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let sign = if self.0 < 0 { "-" } else { "+" };
        let a = self.0.unsigned_abs();
        write!(f, "{}{}.{}", sign, a / 10, a % 10)
    }
}

struct StatusNames(u16);

impl core::fmt::Display for StatusNames {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use thermocomp_core::compensator::status::*;
        const NAMES: [(u16, &str); 9] = [
            (VALID, "valid"),
            (SENSOR_FAULT, "sensor-fault"),
            (NO_MODEL, "no-model"),
            (CLAMPED, "clamped"),
            (WARMING_UP, "warming-up"),
            (STALE_INPUTS, "stale"),
            (OUT_OF_ENVELOPE, "out-of-envelope"),
            (RATE_LIMITED, "rate-limited"),
            (DEGRADED, "degraded"),
        ];
        for (bit, name) in NAMES {
            if self.0 & bit != 0 {
                write!(f, " {}", name)?;
            }
        }
        Ok(())
    }
}

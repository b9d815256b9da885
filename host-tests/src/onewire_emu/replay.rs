//! Replays run CSVs (`docs/formats/run-csv.md`) into the emulated sensors:
//! temperature column k (in file order) drives device k. Parsing and the
//! rounding to 1/16 °C are the board's own (`thermocomp_protocol::trace`), so the
//! emulator and the bench board quantise identically.

use super::Bus;
use thermocomp_protocol::trace::{TraceHeader, TraceSample};

/// A parsed run: header plus every sample, or the line that failed.
pub struct Run {
    pub header: TraceHeader,
    pub samples: Vec<TraceSample>,
}

/// Parses a whole run file (`#` metadata lines skipped).
pub fn parse_run(text: &str) -> Result<Run, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !thermocomp_protocol::trace::is_comment_or_blank(l));
    let (_, head) = lines.next().ok_or("empty run file")?;
    let header = TraceHeader::parse(head).map_err(|e| format!("header: {e:?}"))?;
    let mut samples = Vec::new();
    for (i, line) in lines {
        samples
            .push(TraceSample::parse(&header, line).map_err(|e| format!("line {}: {e:?}", i + 1))?);
    }
    Ok(Run { header, samples })
}

/// Sets each device's temperature from the sample. An empty field (not
/// measured) leaves the device at its previous temperature. Values outside
/// i16 are an error (no silent clamping).
pub fn apply(bus: &Bus, sample: &TraceSample) -> Result<(), String> {
    for (k, t) in sample
        .temperatures
        .iter()
        .enumerate()
        .take(bus.device_count())
    {
        if let Some(t) = t {
            let raw = i16::try_from(*t).map_err(|_| format!("T column {k}: {t} out of i16"))?;
            bus.with_device(k, |d| d.temperature = raw);
        }
    }
    Ok(())
}

//! What a machine description, a duty cycle and the `sim` options may ask
//! for (documented in `examples/machines/README.md`, "Limits"). Every size
//! that sets an allocation is bounded, so a typo such as `segments = 100000`
//! is refused in one line instead of asking for tens of gigabytes, and every
//! physical quantity must be a finite number of the right sign and a
//! possible magnitude.

use anyhow::{bail, Result};
use std::fmt::Display;

/// Network nodes in all: lumped nodes plus rod slices (the state matrices
/// are dense, n × n).
pub const MAX_NODES: usize = 200;
/// Slices of the spindle rod.
pub const MAX_ROD_SEGMENTS: usize = 100;
pub const MAX_LINKS: usize = 2_000;
pub const MAX_BEARINGS: usize = 32;
pub const MAX_SOURCES: usize = 64;
pub const MAX_SENSORS: usize = 100;
pub const MAX_DIRECTIONS: usize = 16;
/// Terms of one direction (`rod` counts once).
pub const MAX_TERMS: usize = 64;
/// Simulated duration, h (the 1 s input grid of 30 days is ~80 MB).
pub const MAX_SIM_HOURS: f64 = 720.0;
/// Rows of a simulated run (55 h at 1 s, 23 days at 10 s).
pub const MAX_SIM_ROWS: usize = 200_000;
/// Output sample period, s.
pub const MAX_SAMPLE_PERIOD_S: f64 = 3_600.0;
/// Breakpoints of a TOML duty: segments × repeat.
pub const MAX_DUTY_SEGMENTS: usize = 100_000;
/// Machine and duty TOML files are read whole.
pub const MAX_TOML_BYTES: u64 = 1 << 20;

/// `v` must lie in `[lo, hi]`.
pub fn within(key: impl Display, v: f64, lo: f64, hi: f64, unit: &str) -> Result<()> {
    if !(lo..=hi).contains(&v) {
        bail!("{key} = {v}: allowed {lo}..={hi}{}", with_space(unit));
    }
    Ok(())
}

/// `v` must lie in `(0, hi]`.
pub fn positive(key: impl Display, v: f64, hi: f64, unit: &str) -> Result<()> {
    if !(v > 0.0 && v <= hi) {
        bail!(
            "{key} = {v}: allowed above 0 up to {hi}{}",
            with_space(unit)
        );
    }
    Ok(())
}

/// A count of `what` must not exceed `max`.
pub fn count(what: impl Display, n: usize, max: usize) -> Result<()> {
    if n > max {
        bail!("{n} {what}: at most {max}");
    }
    Ok(())
}

fn with_space(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// A TOML error as one line with its position: `line 4, column 13: <message>`
/// (the toml crate's own text spans several lines with a source excerpt).
pub fn toml_error(text: &str, e: &toml::de::Error) -> anyhow::Error {
    let message = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            anyhow::anyhow!("line {line}, column {column}: {message}")
        }
        None => anyhow::anyhow!("{message}"),
    }
}

/// Read a TOML file whole, refusing one above [`MAX_TOML_BYTES`].
pub fn read_toml_text(path: &std::path::Path, what: &str) -> Result<String> {
    use anyhow::Context;
    let len = std::fs::metadata(path)
        .with_context(|| format!("cannot read {what} {}", path.display()))?
        .len();
    if len > MAX_TOML_BYTES {
        bail!(
            "{what} {}: {len} bytes, at most {MAX_TOML_BYTES}",
            path.display()
        );
    }
    std::fs::read_to_string(path).with_context(|| format!("cannot read {what} {}", path.display()))
}

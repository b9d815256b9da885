//! The spindle's direction relative to the frame the linear axes (the
//! lines) define (issue 49 item 3), as `identify` reports it.
//!
//! A tilt ε = (about x, about y) of the spindle moves the tool point by
//! `ε × t` in the machine frame: a constant offset for one tool, which the
//! location errors absorb exactly (`model::Spindle`). R-test files with one
//! tool length therefore cannot tell the tilt from `XOC, YOC, YOA, ZOA`:
//! the two angles are then *undetermined* (no value is invented; the
//! location errors reported are the apparent ones at that tool). With two
//! or more tool lengths the difference between the tools' offsets is not a
//! location error, and the fit (`columns::Col::Spindle`) identifies both
//! angles with their σ like any other unknown.

use serde::Serialize;
use std::collections::BTreeSet;

use super::columns::{tools, TermValue, SPINDLE_NAMES};
use crate::rtest::RTestFile;

/// What the files say about the spindle's direction.
#[derive(Clone, Debug, Serialize)]
pub struct SpindleReport {
    /// `identified`, `undetermined` (one tool length) or `unobservable`
    /// (several tools, but the poses do not separate it).
    pub status: String,
    /// The distinct tools of the files [mm].
    pub tools_mm: Vec<[f64; 3]>,
    /// Tilts about x and y [µrad] with σ (right-handed; the tool vector
    /// becomes Rx·Ry·t); empty when undetermined.
    pub angles: Vec<TermValue>,
    /// The tool at which the model's location errors hold (the files'
    /// mean tool) when identified; the reported `location` values are
    /// relative to the lines' frame (zero tool).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_tool_mm: Option<[f64; 3]>,
    /// In words.
    pub why: String,
}

impl SpindleReport {
    /// The report from the fitted angles (`angles`: empty without a
    /// spindle column) and the unobservable terms of the fit.
    pub(crate) fn new(
        files: &[RTestFile],
        angles: Vec<TermValue>,
        unobservable: &BTreeSet<String>,
    ) -> SpindleReport {
        let tools_mm = tools(files);
        let fmt = |t: &[f64; 3]| format!("{},{},{}", t[0], t[1], t[2]);
        if angles.is_empty() {
            let t = tools_mm.first().map(fmt).unwrap_or_default();
            return SpindleReport {
                status: "undetermined".into(),
                tools_mm,
                angles,
                reference_tool_mm: None,
                why: format!(
                    "one tool length (tool_mm {t}) in every file: a tilt of the spindle is then a constant tool offset that XOC, YOC, YOA and ZOA absorb exactly, so its two angles are not identifiable; the location errors reported are the apparent ones at this tool. Measure with a second tool length to separate them"
                ),
            };
        }
        if SPINDLE_NAMES.iter().any(|n| unobservable.contains(*n)) {
            return SpindleReport {
                status: "unobservable".into(),
                tools_mm,
                angles,
                reference_tool_mm: None,
                why: "the files' tool lengths do not separate the spindle's direction from the location errors (see unobservable)".into(),
            };
        }
        let reference = mean_tool(files);
        SpindleReport {
            status: "identified".into(),
            why: format!(
                "{} tool lengths: the spindle's tilt relative to the lines' frame is fitted with the location errors; the model keeps the location errors as they appear at the files' mean tool ({}) and adds the tilt's offset ε × (t − that tool) at other tools",
                tools_mm.len(),
                fmt(&reference)
            ),
            tools_mm,
            angles,
            reference_tool_mm: Some(reference),
        }
    }
}

/// The files' mean tool [mm]: the reference tool of an identified spindle.
pub(crate) fn mean_tool(files: &[RTestFile]) -> [f64; 3] {
    let n = files.len().max(1) as f64;
    std::array::from_fn(|k| files.iter().map(|f| f.tool_mm[k]).sum::<f64>() / n)
}

#[cfg(test)]
#[path = "spindle_tests.rs"]
mod tests;

//! Row ranges of a run: chronological and time-block splits.

use std::ops::Range;

use anyhow::{bail, Result};
use serde::Serialize;

use tcomp_data::runcsv::Run;

/// Rows `[start, end)` of run `run` (an index into the runs list).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Segment {
    pub run: usize,
    pub start: usize,
    pub end: usize,
}

/// Chronological split of `n` rows at fractions `a < b`: train `[0, ⌊a·n⌋)`,
/// validation `[⌊a·n⌋, ⌊b·n⌋)` (the FL_THERMAL protocol).
pub fn chrono_split(n: usize, a: f64, b: f64) -> Result<(Range<usize>, Range<usize>)> {
    if !(0.0 < a && a < b && b <= 1.0) {
        bail!("--split-chrono a,b needs 0 < a < b ≤ 1, got {a},{b}");
    }
    let i = (a * n as f64).floor() as usize;
    let j = ((b * n as f64).floor() as usize).min(n);
    if i == 0 || j <= i {
        bail!("--split-chrono {a},{b}: an empty part on {n} rows");
    }
    Ok((0..i, i..j))
}

/// Split a training segment by time: the first `1 − frac` of its time span
/// for fitting, the last `frac` for early stopping / selection.
pub fn time_block_split(run: &Run, seg: Segment, frac: f64) -> (Segment, Segment) {
    let t = run.time_s();
    if seg.end <= seg.start + 1 {
        return (
            seg,
            Segment {
                start: seg.end,
                ..seg
            },
        );
    }
    let t0 = t[seg.start];
    let t1 = t[seg.end - 1];
    let cut_t = t0 + (1.0 - frac) * (t1 - t0);
    let cut = (seg.start..seg.end)
        .find(|&r| t[r] > cut_t)
        .unwrap_or(seg.end);
    (Segment { end: cut, ..seg }, Segment { start: cut, ..seg })
}

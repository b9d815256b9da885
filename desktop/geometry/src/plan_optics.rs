//! Plans with a straightness-optics line (issue 49: "with one
//! straightness-optics line allowed"). Straightness optics read the tool
//! point's error perpendicular to the travel (`identify::LineKind`), up to
//! an offset and a slope: along X sensed along Y such a line sees EYX and
//! the yaw ECX through its Abbe arm directly, which displacement lines only
//! see through diagonals. [`rich_optics_lines`] is the rich plan with one
//! line exchanged for one straightness line, chosen by the plan criterion
//! (`examples/optics_choice.rs` searches every axis-parallel grid line,
//! sense and reflector offset against every line of the rich plan).

use super::identify::LineKind;
use super::lines::LineSpec;
use super::plan::{rich_lines, GridLine, Offset};

/// A straightness line on the half-stroke grid: an axis-parallel
/// [`GridLine`] and the axis (0 x, 1 y, 2 z) its reading is along.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StraightnessLine {
    pub line: GridLine,
    pub sense_axis: usize,
}

impl StraightnessLine {
    /// The line's spec (`id`, the volume and reflector sizes).
    pub fn spec(&self, id: &str, stroke: [f64; 3], tool: f64, side: f64) -> LineSpec {
        let mut s = self.line.spec(id, stroke, tool, side);
        s.kind = LineKind::Straightness;
        s.sense = [0, 1, 2].map(|k| if k == self.sense_axis { 1.0 } else { 0.0 });
        s.purpose = format!(
            "straightness optics: {}, read along {}",
            s.purpose,
            ['x', 'y', 'z'][self.sense_axis]
        );
        s
    }

    /// Every axis-parallel line of the grid with each perpendicular sense
    /// and each reflector offset (the candidates of the search).
    pub fn candidates() -> Vec<StraightnessLine> {
        let mut out = Vec::new();
        for g in super::plan::pool() {
            let moving: Vec<usize> = (0..3).filter(|k| g.from[*k] != g.to[*k]).collect();
            if moving.len() != 1 {
                continue;
            }
            for sense_axis in (0..3).filter(|k| *k != moving[0]) {
                out.push(StraightnessLine {
                    line: g,
                    sense_axis,
                });
            }
        }
        out
    }
}

/// The rich plan's line the straightness line replaces (its id) …
pub const RICH_OPTICS_REPLACES: &str = "L21";

/// … and the straightness line put in its place: of every exchange of a
/// rich-plan line for a candidate, the one with the best criterion
/// (`examples/optics_choice.rs`: objective 0.627 against the rich plan's
/// 0.622 — no exchange improves the stated criterion, this one costs the
/// least; its reading along x sees EXY and the Y carriage's yaw ECY through
/// its z arm directly).
pub fn rich_optics_line() -> StraightnessLine {
    StraightnessLine {
        line: GridLine {
            from: [1, 0, 2],
            to: [1, 2, 2],
            offset: Offset::MinusY,
        },
        sense_axis: 0,
    }
}

/// The rich plan (28 lines) with [`RICH_OPTICS_REPLACES`] exchanged for
/// [`rich_optics_line`] (same id, same place in the list).
pub fn rich_optics_lines(stroke: [f64; 3], tool: f64, side: f64) -> Vec<LineSpec> {
    rich_lines(stroke, tool, side)
        .into_iter()
        .map(|l| {
            if l.id == RICH_OPTICS_REPLACES {
                let mut s = rich_optics_line().spec(&l.id, stroke, tool, side);
                s.purpose = format!(
                    "{} (in place of the rich plan's {}: the exchange the plan criterion ranks best)",
                    s.purpose, l.purpose
                );
                s
            } else {
                l
            }
        })
        .collect()
}

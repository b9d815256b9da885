//! `tcomp geometry plan --plan 14|rich|rich-optics` and `simulate --plan` (issue 49
//! item 1): which plan's lines, and the stated criterion a plan is judged
//! by (`tcomp_geometry::plan`: posterior worst-term σ under a class that is
//! not told the error shape, null directions, fewest lines without one),
//! in words with units and as JSON.

use anyhow::{bail, Result};

use tcomp_geometry::identify::LineKind;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::{plan14, LineSpec};
use tcomp_geometry::plan::{evaluate, rich_lines, Criterion, CLASS_DEGREE};
use tcomp_geometry::plan_optics::rich_optics_lines;

/// The plans `--plan` names.
pub const PLAN_NAMES: &str = "14, rich or rich-optics";

/// The lines of the plan `name` for a volume.
pub fn plan_lines(name: &str, stroke: [f64; 3], tool: f64, side: f64) -> Result<Vec<LineSpec>> {
    match name {
        "14" => Ok(plan14(stroke, tool, side)),
        "rich" => Ok(rich_lines(stroke, tool, side)),
        "rich-optics" => Ok(rich_optics_lines(stroke, tool, side)),
        n => bail!("--plan {n:?}: {PLAN_NAMES}"),
    }
}

/// The criterion of a plan at `noise_um` (σ of one reading of one run).
pub fn criterion(
    st: &Structure,
    stroke: [f64; 3],
    lines: &[LineSpec],
    noise_um: f64,
) -> Result<Criterion> {
    if !(noise_um > 0.0 && noise_um.is_finite()) {
        bail!("--noise-um must be a positive number of µm");
    }
    Ok(evaluate(st, stroke, lines, noise_um))
}

/// One line of the plan, in words: ends, reflector offset, purpose.
pub fn line_words(l: &LineSpec) -> String {
    let e = [0, 1, 2].map(|k| l.start_mm[k] + l.length_mm * l.direction[k]);
    format!(
        "{}  ({:.0},{:.0},{:.0}) → ({:.0},{:.0},{:.0}) mm  reflector ({:.0},{:.0},{:.0}) mm  {}",
        l.id,
        l.start_mm[0],
        l.start_mm[1],
        l.start_mm[2],
        e[0],
        e[1],
        e[2],
        l.tool_offset_mm[0],
        l.tool_offset_mm[1],
        l.tool_offset_mm[2],
        l.purpose
    )
}

/// A line as JSON (start, end, direction, length, reflector, purpose).
pub fn line_json(l: &LineSpec) -> serde_json::Value {
    let e = [0, 1, 2].map(|k| l.start_mm[k] + l.length_mm * l.direction[k]);
    let mut v = serde_json::json!({"line": l.id, "start_mm": l.start_mm, "end_mm": e,
        "direction": l.direction, "length_mm": l.length_mm,
        "tool_offset_mm": l.tool_offset_mm, "purpose": l.purpose});
    if l.kind == LineKind::Straightness {
        v["measures"] = serde_json::json!("straightness");
        v["sense"] = serde_json::json!(l.sense);
    }
    v
}

/// The criterion in words, labelled with units.
pub fn print_criterion(name: &str, c: &Criterion) {
    println!(
        "criterion (plan {name}, {} lines, noise {} µm per reading of one run):",
        c.lines, c.noise_um
    );
    println!(
        "  worst-term posterior σ: {:.2} µm ({}), {:.2} µrad ({}) — determined needs 2σ ≤ 1 µm / 4 µrad",
        c.worst_um, c.worst_um_error, c.worst_urad, c.worst_urad_error
    );
    println!(
        "  null directions (Legendre degree {CLASS_DEGREE} per error, each line's zero free): {}",
        c.null_directions
    );
    match c.min_lines_identifiable {
        Some(m) => println!("  fewest of these lines (in order) without a null direction: {m}"),
        None => println!(
            "  these lines leave {} combinations of the errors unseen: two machines that differ by one read the same on every line yet differ at the tool tip; measure more lines (`--plan rich`)",
            c.null_directions
        ),
    }
    println!("  assumes: {}", c.class);
}

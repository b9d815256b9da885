//! Which rich-plan line to exchange for one straightness-optics line
//! (`plan_optics::rich_optics_lines`): for every line of the rich plan,
//! the best candidate of `StraightnessLine::candidates()` in its place by
//! the plan criterion (`plan_design::design`, one line added to the other
//! 27), for the default volume (800 × 500 × 400 mm, tool 100, side 100,
//! σ 0.5 µm). Prints the best exchanges and the criterion of the rich and
//! rich-optics plans.
//! `cargo run -p tcomp-geometry --release --example optics_choice`

use tcomp_geometry::plan::{evaluate, rich_lines};
use tcomp_geometry::plan_design::design;
use tcomp_geometry::plan_optics::{rich_optics_lines, StraightnessLine};
use tcomp_geometry::Structure;

fn main() {
    let st = Structure::parse("XY/Z").expect("XY/Z");
    let (stroke, tool, side, noise) = ([800.0, 500.0, 400.0], 100.0, 100.0, 0.5);
    let rich = rich_lines(stroke, tool, side);
    let cands = StraightnessLine::candidates();
    let specs: Vec<_> = (cands.iter().enumerate())
        .map(|(i, c)| c.spec(&format!("S{i}"), stroke, tool, side))
        .collect();
    println!("{} candidates", specs.len());
    let mut best = Vec::new();
    for out in 0..rich.len() {
        let base: Vec<_> = (rich.iter().enumerate())
            .filter(|(i, _)| *i != out)
            .map(|(_, l)| l.clone())
            .collect();
        let (chosen, trace) = design(&st, stroke, &base, &specs, 1, noise);
        if let (Some(&i), Some(&j)) = (chosen.first(), trace.first()) {
            best.push((j, out, i));
        }
    }
    best.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (j, out, i) in best.iter().take(8) {
        println!(
            "replace {} by {:?}: objective {j:.3}  {}",
            rich[*out].id, cands[*i], specs[*i].purpose
        );
    }
    for (name, plan) in [
        ("rich", rich.clone()),
        ("rich-optics", rich_optics_lines(stroke, tool, side)),
    ] {
        let c = evaluate(&st, stroke, &plan, noise);
        // The design objective: worst σ in tolerance units + a hundredth of the mean.
        let r: Vec<f64> = (c.per_error.iter())
            .map(|t| t.sigma / if t.unit == "urad" { 4.0 } else { 1.0 })
            .collect();
        let obj =
            r.iter().copied().fold(0.0, f64::max) + 0.01 * r.iter().sum::<f64>() / r.len() as f64;
        println!(
            "{name}: worst {:.3} µm ({}) / {:.3} µrad ({}), nulls {}, objective {obj:.3}",
            c.worst_um, c.worst_um_error, c.worst_urad, c.worst_urad_error, c.null_directions
        );
    }
}

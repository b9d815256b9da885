//! The rich plan's design (issue 49 item 1): greedy addition then exchange
//! of 14 lines from `plan::pool()` to today's 14, on the stated criterion
//! (`plan` module docs), for the default volume (800 × 500 × 400 mm, tool
//! 100 mm, side 100 mm, σ 0.5 µm). Prints the chosen lines as the list
//! `plan::rich_additions` holds, the criterion of both plans, and the
//! smallest singular values behind the null count.
//! `cargo run -p tcomp-geometry --release --example plan_design [-- ADD]`

use tcomp_geometry::lines::plan14;
use tcomp_geometry::plan::{evaluate, null_directions, pool, rich_lines, CLASS_DEGREE};
use tcomp_geometry::plan_design::design;
use tcomp_geometry::Structure;

fn main() {
    let add: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(14);
    let st = Structure::parse("XY/Z").unwrap();
    let (stroke, tool, side, noise) = ([800.0, 500.0, 400.0], 100.0, 100.0, 0.5);
    let base = plan14(stroke, tool, side);
    let grid = pool();
    let specs: Vec<_> = grid
        .iter()
        .enumerate()
        .map(|(i, g)| g.spec(&format!("P{i}"), stroke, tool, side))
        .collect();
    let t0 = std::time::Instant::now();
    let c14 = evaluate(&st, stroke, &base, noise);
    println!(
        "plan 14: worst {:.2} µm ({}) / {:.2} µrad ({}), nulls {} [{:.1} s]",
        c14.worst_um,
        c14.worst_um_error,
        c14.worst_urad,
        c14.worst_urad_error,
        c14.null_directions,
        t0.elapsed().as_secs_f64()
    );
    println!("pool: {} candidates", specs.len());
    let t0 = std::time::Instant::now();
    let (chosen, trace) = design(&st, stroke, &base, &specs, add, noise);
    println!("design: {:.1} s", t0.elapsed().as_secs_f64());
    for (k, (i, j)) in chosen.iter().zip(&trace).enumerate() {
        println!(
            "  +{:2} {:?} objective {j:.3}  {}",
            k + 1,
            grid[*i],
            specs[*i].purpose
        );
    }
    println!("as rust:");
    for i in &chosen {
        let g = grid[*i];
        println!("        g({:?}, {:?}, {:?}),", g.from, g.to, g.offset);
    }
    if add > 0 {
        let mut plan = base.clone();
        plan.extend(chosen.iter().map(|i| specs[*i].clone()));
        let c = evaluate(&st, stroke, &plan, noise);
        println!(
            "designed plan ({} lines): worst {:.2} µm ({}) / {:.2} µrad ({}), nulls {}",
            plan.len(),
            c.worst_um,
            c.worst_um_error,
            c.worst_urad,
            c.worst_urad_error,
            c.null_directions,
        );
    }
    let r = rich_lines(stroke, tool, side);
    let c = evaluate(&st, stroke, &r, noise);
    println!(
        "plan::rich_plan ({} lines): worst {:.2} µm ({}) / {:.2} µrad ({}), nulls {}, identifiable from {:?} lines",
        r.len(),
        c.worst_um,
        c.worst_um_error,
        c.worst_urad,
        c.worst_urad_error,
        c.null_directions,
        c.min_lines_identifiable
    );
    let drop: Vec<usize> = (0..r.len())
        .map(|k| {
            let mut p = r.clone();
            p.remove(k);
            null_directions(&st, stroke, &p, CLASS_DEGREE)
        })
        .collect();
    println!("nulls with one line dropped: {drop:?}");
    for k in 0..r.len() {
        let mut p = r.clone();
        p.remove(k);
        let c = evaluate(&st, stroke, &p, noise);
        print!("-{}: {:.2}/{:.2}  ", r[k].id, c.worst_um, c.worst_urad);
    }
    println!();
}

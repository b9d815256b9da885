//! An effect that only changes design values within their tolerance is
//! not testable — the film and lever counterpart of `design_heat.rs`.
//!
//! `convection` adds h·A to every node's loss to air; `bending` adds
//! k·(T_a − T_b) to a displacement, i.e. +k and −k to the levers of nodes
//! a and b. When that change is within the file's tolerance of the
//! (calibrated) design's own loss or lever at every node it acts on, it is
//! the same as a design error the calibration is allowed to have: the
//! data cannot tell it from one. Alone, the calibration would absorb it;
//! as the partner of a pair it soaked up what a single effect's fit left
//! (seed-13 benches: `bearing_nonlinear+convection` with h ≈ 2–4 W/m²K,
//! `+bending` with k ≈ 0.8 µm/K, on cases whose single was right).
//! Such an effect is not claimed and is listed untestable with the figures.

use crate::sim::machine::tolerance;
use crate::sim::{Effect, Machine};

/// Why `e` cannot be told from design errors within tolerance, or None
/// when it can (or is not a convection or bending effect).
pub fn within_tolerance(m: &Machine, e: &Effect) -> Option<String> {
    match e {
        Effect::Convection { h_w_per_m2k } => convection(m, *h_w_per_m2k),
        Effect::Bending { k_um_per_k } => bending(m, *k_um_per_k),
        _ => None,
    }
}

fn convection(m: &Machine, h: f64) -> Option<String> {
    let acts: Vec<usize> = (0..m.n).filter(|&i| m.area[i] > 0.0).collect();
    if acts.is_empty() || !(h > 0.0) {
        return None;
    }
    let mut worst = 0.0f64;
    for &i in &acts {
        let tol = tolerance::of(
            &m.spec.tolerance,
            "film",
            m.names.get(i).map(String::as_str),
        );
        if !(m.g_amb[i] > 0.0) {
            return None; // the design has no loss there to be off
        }
        let share = h * m.area[i] / m.g_amb[i];
        if share > tol {
            return None;
        }
        worst = worst.max(share / tol);
    }
    Some(format!(
        "the loss to air it adds ({h:.2} W/m²K × area) is at most {:.0} % of the film tolerance of the design's own loss at every node with an area: it cannot be told from a design error of those film coefficients",
        100.0 * worst
    ))
}

fn bending(m: &Machine, k: f64) -> Option<String> {
    let (a, b, d) = m.bending?;
    let terms = m.dir_terms.get(d)?;
    let dir = m.spec.directions.get(d).map_or("", |x| x.name.as_str());
    let lever = |node: usize| -> f64 {
        terms
            .iter()
            .filter(|t| t.0 == node)
            .map(|t| t.1)
            .sum::<f64>()
            .abs()
    };
    let mut worst = 0.0f64;
    for node in [a, b] {
        let name = m.names.get(node).map_or("", String::as_str);
        let tol = tolerance::of(&m.spec.tolerance, "length", Some(&format!("{dir}:{name}")));
        let l = lever(node);
        if !(l > 0.0) || k.abs() > tol * l {
            return None;
        }
        worst = worst.max(k.abs() / (tol * l));
    }
    Some(format!(
        "its {:.2} µm/K on {} − {} is at most {:.0} % of the length tolerance of the design's own levers of those nodes in direction {dir}: it cannot be told from a design error of those lengths",
        k.abs(),
        m.names.get(a).map_or("", String::as_str),
        m.names.get(b).map_or("", String::as_str),
        100.0 * worst
    ))
}

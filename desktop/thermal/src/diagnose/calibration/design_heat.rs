//! A heat effect inside the design's own heat tolerance is not testable.
//!
//! Every heated node's heat is a design number with a tolerance, and the
//! calibration may move it within that tolerance (`calibrate.rs`: one
//! heat gain per heated node). A drawing that puts 50 W on the nose
//! bearing where 60 W flow leaves 10 W at that node that the data cannot
//! tell from an extra heat source there. So an extra heat at a node
//! (`bearing_nonlinear`, `ballscrew`) that, at the highest speed (feed) the
//! runs reach, adds no more than the heat tolerance of the heat the
//! calibrated design already puts at every node it acts on cannot be told
//! from a design error of that node's own heat: it is not claimed, and it
//! is listed untestable with the figures. (At its peak, not over the runs:
//! a steep speed law is small at low speed, where the design error is not
//! the question.) A heat effect where the design has no heat, or larger
//! than that share, is judged as before.
//!
//! Only the heat that follows the effect's own law counts. Where the
//! calibration gives a node's viscous bearing term (f0, ∝ n^(5/3)) a knob
//! of its own beside the rest of the node's heat (`knobs.rs`, `Terms`:
//! the load term ∝ n, sources, the motor), a steep bearing heat
//! (`bearing_nonlinear`, ∝ n^p) can be mistaken only for an error of that
//! viscous term: the rest moves along another speed law, and every
//! candidate fit already re-solves it within its tolerance (the freedom).
//! So the share is taken of the viscous heat, with its knob's own
//! tolerance. Against the node's total heat a steep heat 18 % of the total
//! but 70 % of the viscous term was barred as "within tolerance" while the
//! calibration's own release needed that term ×1.7, outside its tolerance.

use super::knobs::{apply, knobs, Knob};
use crate::diagnose::runs::Prepared;
use crate::sim::machine::tolerance;
use crate::sim::{Effect, Machine};

/// Per node the effect acts on: (node, design heat [W], added heat [W],
/// tolerance of that heat).
type PerNode = Vec<(usize, f64, f64, f64)>;
/// The effect's heat [W] at a drive level (speed or feed activity).
type Law = Box<dyn Fn(f64) -> f64>;

/// At the row where the effect's heat peaks (the highest speed or feed the
/// runs reach), per node it acts on: the calibrated design's heat of the
/// same driver there and the heat the effect adds [W].
fn at_peak(m: &Machine, ps: &[Prepared], e: &Effect) -> Option<(&'static str, PerNode)> {
    let mut q = vec![0.0; m.n];
    let (driver, at, extra): (&'static str, Vec<usize>, Law) = match e {
        Effect::BearingNonlinear { k_w, p, node } => {
            let at = match node {
                Some(n) => vec![m.names.iter().position(|x| x == n)?],
                None => m.bnl_nodes.clone(),
            };
            let (k, p, n_max) = (*k_w, *p, m.spec.n_max_rpm);
            (
                "spindle",
                at,
                Box::new(move |rpm: f64| k * (rpm / n_max).powf(p)),
            )
        }
        Effect::Ballscrew { k_w } => {
            let share = 1.0 / m.ballscrew_nodes.len().max(1) as f64;
            let k = *k_w;
            (
                "feed",
                m.ballscrew_nodes.clone(),
                Box::new(move |f: f64| k * f * share),
            )
        }
        _ => return None,
    };
    // the drive level at the peak: spindle speed or feed activity
    let top = ps
        .iter()
        .flat_map(|p| {
            if driver == "spindle" {
                p.inputs.rpm.iter()
            } else {
                p.inputs.feed.iter()
            }
        })
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if top <= 0.0 {
        return None;
    }
    if driver == "spindle" {
        m.heat_nominal(top, &mut q);
    } else {
        m.heat_feed(top, &mut q);
    }
    let tol = tolerance::of(&m.spec.tolerance, "heat", Some(driver));
    let x = extra(top);
    let ks = if driver == "spindle" {
        knobs(m)
    } else {
        Vec::new()
    };
    let per = at
        .iter()
        .map(|&i| match viscous_at(m, &ks, i, top) {
            Some((heat, t)) => (i, heat, x, t),
            None => (i, q[i], x, tol),
        })
        .collect();
    Some((driver, per))
}

/// The viscous bearing term's heat at node `i` at `rpm` [W] and its knob's
/// tolerance, when the calibration gives that term a knob of its own.
fn viscous_at(m: &Machine, ks: &[Knob], i: usize, rpm: f64) -> Option<(f64, f64)> {
    let key = format!("{}:f0", m.names[i]);
    let k = ks
        .iter()
        .find(|k| k.group == "heat" && k.element.as_deref() == Some(key.as_str()))?;
    // the knob's heat: what doubling it adds at that speed
    let doubled = apply(m, std::slice::from_ref(k), &[std::f64::consts::LN_2]);
    let (mut q0, mut q1) = (vec![0.0; m.n], vec![0.0; doubled.n]);
    m.heat_nominal(rpm, &mut q0);
    doubled.heat_nominal(rpm, &mut q1);
    let heat = q1.get(i)? - q0[i];
    (heat > 0.0).then_some((heat, k.tol))
}

/// Why `e` cannot be told from the design's heat error on these runs, or
/// None when it can (or is no heat effect).
pub fn within_tolerance(m: &Machine, ps: &[Prepared], e: &Effect) -> Option<String> {
    let (_, per) = at_peak(m, ps, e)?;
    if per.is_empty() {
        return None;
    }
    let inside = per
        .iter()
        .all(|&(_, design, extra, tol)| tol > 0.0 && design > 0.0 && extra <= tol * design);
    if !inside {
        return None;
    }
    let share = per
        .iter()
        .map(|&(i, d, x, _)| format!("{} {:.0} %", m.names[i], 100.0 * x / d))
        .collect::<Vec<_>>()
        .join(", ");
    let tol = per.iter().map(|p| p.3).fold(0.0f64, f64::max);
    Some(format!(
        "at the highest drive the runs reach, the heat it adds ({share} of the design's heat of that speed law there) is within the ±{:.0} % heat tolerance of that design heat at that node: it cannot be told from a design error of that heat",
        100.0 * tol
    ))
}

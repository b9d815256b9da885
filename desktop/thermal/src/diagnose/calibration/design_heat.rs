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

use crate::diagnose::runs::Prepared;
use crate::sim::machine::tolerance;
use crate::sim::{Effect, Machine};

/// Per node the effect acts on: (node, design heat [W], added heat [W]).
type PerNode = Vec<(usize, f64, f64)>;
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
    let x = extra(top);
    Some((driver, at.iter().map(|&i| (i, q[i], x)).collect()))
}

/// Why `e` cannot be told from the design's heat error on these runs, or
/// None when it can (or is no heat effect).
pub fn within_tolerance(m: &Machine, ps: &[Prepared], e: &Effect) -> Option<String> {
    let (driver, per) = at_peak(m, ps, e)?;
    let tol = tolerance::of(&m.spec.tolerance, "heat", Some(driver));
    if per.is_empty() || tol <= 0.0 {
        return None;
    }
    let inside = per
        .iter()
        .all(|&(_, design, extra)| design > 0.0 && extra <= tol * design);
    if !inside {
        return None;
    }
    let share = per
        .iter()
        .map(|&(i, d, x)| format!("{} {:.0} %", m.names[i], 100.0 * x / d))
        .collect::<Vec<_>>()
        .join(", ");
    Some(format!(
        "at the highest drive the runs reach, the heat it adds ({share} of the design's heat there) is within the ±{:.0} % heat tolerance of the design's own heat at that node: it cannot be told from a design error of that heat",
        100.0 * tol
    ))
}

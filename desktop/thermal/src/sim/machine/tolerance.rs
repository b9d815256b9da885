//! How far a machine file's design values may be off: the `[tolerance]`
//! table. A design value is a value with a tolerance; the diagnosis
//! calibrates the nominal within it (`diagnose/calibrate.rs`) and reports a
//! value that must leave it as a finding.
//!
//! Keys (every value a fraction: 0.25 = ±25 %, 0 = exact):
//! `default`; a group `capacity`, `film`, `link`, `jacket`, `heat`, `length`;
//! one element `"capacity:<node>"`, `"film:<node>"`, `"link:<a>-<b>"`,
//! `"jacket:<node>"`, `"heat:spindle"`, `"heat:feed"`, `"heat:<node>"` (the
//! sources, bearings and motor loss on one node), `"heat:<node>:f0"` (the
//! viscous friction term of its bearings; else the node's tolerance),
//! `"length:<direction>:<node>"` (`rod` as the node for the spindle rod).
//! The most specific key wins.

use anyhow::{bail, Result};
use std::collections::BTreeMap;

use super::spec::MachineSpec;

/// Tolerance of a design value when the file states none: ±25 %.
pub const DEFAULT_TOLERANCE: f64 = 0.25;

/// The groups of design values a tolerance may name.
pub const GROUPS: [&str; 6] = ["capacity", "film", "link", "jacket", "heat", "length"];

/// The element keys a file may name in `[tolerance]` (group:element).
fn element_keys(s: &MachineSpec) -> Vec<String> {
    let mut v = Vec::new();
    let mut nodes: Vec<&str> = s.nodes.iter().map(|n| n.name.as_str()).collect();
    if s.rod.is_some() {
        nodes.push("rod");
    }
    for n in &nodes {
        v.push(format!("capacity:{n}"));
        v.push(format!("film:{n}"));
    }
    for l in &s.links {
        v.push(format!("link:{}-{}", l.a, l.b));
        v.push(format!("link:{}-{}", l.b, l.a));
    }
    if s.rod.is_some() {
        v.push("link:rod".into());
    }
    if let Some(c) = &s.coolant {
        v.extend(c.jacket.iter().map(|j| format!("jacket:{}", j.node)));
    }
    v.push("heat:spindle".into());
    v.push("heat:feed".into());
    // one heated node: its sources, bearings and motor loss together
    v.extend(s.sources.iter().map(|x| format!("heat:{}", x.node)));
    v.extend(s.bearings.iter().map(|x| format!("heat:{}", x.node)));
    // the viscous term (f0) of the bearings on one node
    v.extend(s.bearings.iter().map(|x| format!("heat:{}:f0", x.node)));
    v.extend(s.motor_node.iter().map(|x| format!("heat:{x}")));
    for d in &s.directions {
        v.extend(
            d.terms
                .iter()
                .map(|t| format!("length:{}:{}", d.name, t.node)),
        );
    }
    v
}

/// Every key known and every value a fraction in [0, 1).
pub fn check(s: &MachineSpec) -> Result<()> {
    if s.tolerance.is_empty() {
        return Ok(());
    }
    let elements = element_keys(s);
    for (k, &t) in &s.tolerance {
        let known = k == "default" || GROUPS.contains(&k.as_str()) || elements.contains(k);
        if !known {
            bail!(
                "[tolerance] `{k}`: unknown parameter (keys: default, {}, or \"group:element\" such as \"film:<node>\", \"link:<a>-<b>\", \"length:<direction>:<node>\")",
                GROUPS.join(", ")
            );
        }
        if !t.is_finite() || !(0.0..1.0).contains(&t) {
            bail!("[tolerance] {k} = {t}: allowed 0 ≤ tolerance < 1 (a fraction: 0.25 = ±25 %)");
        }
    }
    Ok(())
}

/// The tolerance of one design value: its element key, else its group,
/// else `default`, else [`DEFAULT_TOLERANCE`].
pub fn of(tol: &BTreeMap<String, f64>, group: &str, element: Option<&str>) -> f64 {
    // a link may be named either way round
    let reversed = |e: &str| -> Option<String> {
        let (a, b) = e.split_once('-')?;
        (group == "link").then(|| format!("{group}:{b}-{a}"))
    };
    element
        .and_then(|e| {
            tol.get(&format!("{group}:{e}"))
                .or_else(|| reversed(e).and_then(|k| tol.get(&k)))
        })
        .or_else(|| tol.get(group))
        .or_else(|| tol.get("default"))
        .copied()
        .unwrap_or(DEFAULT_TOLERANCE)
}

//! Whether a parameter finding is true of the design file the bench drew
//! (issue 27). The design-error column multiplies every design number by a
//! drawn factor f (`perturb::perturb_spec`), so the calibration must scale
//! it by 1/f to reach the truth; about one number in seven needs a
//! correction outside the default ±25 %. A finding that names such a number
//! in the right direction says something true about the file, not a false
//! alarm.
//!
//! The rule: the finding's parameter (`params.parameter`, the calibration's
//! tolerance key: a group `film`, or `group:element`) is mapped to the
//! design numbers it scales; their needed correction is the geometric mean
//! of 1/f over them (one number: 1/f exactly; a group or a multi-number
//! knob such as `heat:spindle`: the common factor that best fits them in
//! log); the finding is true of the file when that correction lies outside
//! the tolerance the diagnosis used (`params.tolerance`: below 1 − tol or
//! above 1 + tol) and the fitted/design factor (`params.factor`) is on the
//! same side of 1.

use serde_json::Value;
use tcomp_thermal::sim::machine::spec::{Driver, MachineSpec};

/// How a parameter finding relates to the drawn file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileVerdict {
    /// The named value(s) were drawn outside the tolerance, and the finding
    /// moves them the right way.
    True,
    /// Drawn outside the tolerance, but the finding moves them the other way.
    WrongDirection,
    /// Drawn inside the tolerance.
    InsideTolerance,
    /// The parameter names no design number of the file (or no factor).
    Unknown,
}

impl FileVerdict {
    pub fn is_true(self) -> bool {
        self == FileVerdict::True
    }
}

/// Whether an entry of the diagnosis' ranking is a parameter finding (a
/// design value that had to leave its tolerance) rather than an effect.
pub fn is_parameter_finding(e: &Value) -> bool {
    e["evidence"]["kind"].as_str() == Some("design value outside its tolerance")
}

/// The keys (`perturb::visit_design_numbers`) of the design numbers the
/// calibration parameter `parameter` (`group` or `group:element`, as
/// `diagnose::calibrate` names its knobs) scales in `spec`.
pub fn design_keys(parameter: &str, spec: &MachineSpec) -> Vec<String> {
    let (group, element) = match parameter.split_once(':') {
        Some((g, e)) => (g, Some(e)),
        None => (parameter, None),
    };
    let all = element.is_none();
    let is = |e: &str| element == Some(e);
    let mut out = Vec::new();
    let rod = spec.rod.as_ref();
    match group {
        "capacity" | "film" => {
            let field = if group == "capacity" {
                "c_j_per_k"
            } else {
                "g_amb_w_per_k"
            };
            for n in &spec.nodes {
                if all || is(&n.name) {
                    out.push(format!("node {} {field}", n.name));
                }
            }
            if rod.is_some() && (all || is("rod")) {
                out.push(if group == "capacity" {
                    "rod cp_j_per_kgk".into()
                } else {
                    "rod g_amb_w_per_k".into()
                });
            }
        }
        "link" => {
            for l in &spec.links {
                let ab = format!("{}-{}", l.a, l.b);
                let ba = format!("{}-{}", l.b, l.a);
                if all || is(&ab) || is(&ba) {
                    out.push(format!("link {ab} g_w_per_k"));
                }
            }
            if let Some(r) = rod {
                if all || is("rod") {
                    out.push("rod k_w_per_mk".into());
                }
                let last = r.segments.saturating_sub(1);
                for (end, e, slice) in [("front", &r.front, 0), ("rear", &r.rear, last)] {
                    if let Some(e) = e {
                        if all || is(&format!("{}-rod:{slice}", e.node)) {
                            out.push(format!("rod {end} g_w_per_k"));
                        }
                    }
                }
            }
        }
        "jacket" => {
            for j in spec.coolant.iter().flat_map(|c| &c.jacket) {
                if all || is(&j.node) {
                    out.push(format!("coolant jacket {} g_w_per_k", j.node));
                }
            }
        }
        "heat" => {
            // a driver (`spindle`, `feed`), one heated node, or the
            // viscous term of a node's bearings (`<node>:f0`; the node's
            // own knob then scales the rest)
            let spindle = all || is("spindle");
            if let Some(node) = element.and_then(|e| e.strip_suffix(":f0")) {
                for b in spec.bearings.iter().filter(|b| b.node == node) {
                    out.push(format!("bearing {} f0", b.node));
                }
                return out;
            }
            if spec.motor_node.as_deref().is_some_and(|m| spindle || is(m)) {
                out.push("motor_loss_frac".into());
            }
            for b in spec.bearings.iter().filter(|b| spindle || is(&b.node)) {
                if spindle || !viscous_split(spec, &b.node) {
                    out.push(format!("bearing {} f0", b.node));
                }
                out.push(format!("bearing {} f1", b.node));
            }
            for (i, s) in spec.sources.iter().enumerate() {
                let take = is(&s.node)
                    || match s.driver {
                        Driver::Spindle => spindle,
                        Driver::Feed => all || is("feed"),
                    };
                if take {
                    out.push(format!("source {i} {} w_at_nmax", s.node));
                }
            }
        }
        "length" => {
            for d in &spec.directions {
                for (i, t) in d.terms.iter().enumerate() {
                    if all || is(&format!("{}:{}", d.name, t.node)) {
                        out.push(format!(
                            "direction {} term {i} {} length_mm",
                            d.name, t.node
                        ));
                    }
                }
            }
        }
        _ => {}
    }
    out
}

/// Whether the calibration gives the viscous term (f0) of `node`'s
/// bearings a knob of its own (`diagnose::calibrate`: when the node has
/// other heat — a load term, a source, the motor loss).
fn viscous_split(spec: &MachineSpec, node: &str) -> bool {
    let at = |b: &&tcomp_thermal::sim::machine::BearingSpec| b.node == node;
    let viscous = spec.bearings.iter().filter(at).any(|b| b.f0 > 0.0);
    let other = spec
        .bearings
        .iter()
        .filter(at)
        .any(|b| b.f1 * b.load_n > 0.0)
        || spec
            .sources
            .iter()
            .any(|s| s.node == node && s.w_at_nmax > 0.0)
        || (spec.motor_node.as_deref() == Some(node)
            && spec.motor_loss_frac * spec.rated_power_w > 0.0);
    viscous && other
}

/// The correction the drawn file needs on `parameter` (truth / design: the
/// geometric mean of 1/f over its design numbers), None when it names none.
pub fn needed_correction(
    parameter: &str,
    spec: &MachineSpec,
    factors: &[(String, f64)],
) -> Option<f64> {
    let logs: Vec<f64> = design_keys(parameter, spec)
        .iter()
        .filter_map(|k| factors.iter().find(|(fk, _)| fk == k))
        .map(|(_, f)| -f.ln())
        .collect();
    (!logs.is_empty()).then(|| (logs.iter().sum::<f64>() / logs.len() as f64).exp())
}

/// Judge the parameter finding `f` (an entry of the diagnosis' `effects`, or
/// of a `findings` list: its `params` carry `parameter`, `factor`,
/// `tolerance`) against the file drawn from `spec` with `factors`.
pub fn judge_finding(f: &Value, spec: &MachineSpec, factors: &[(String, f64)]) -> FileVerdict {
    let p = if f["params"].is_object() {
        &f["params"]
    } else {
        f
    };
    let Some(parameter) = p["parameter"].as_str() else {
        return FileVerdict::Unknown;
    };
    let Some(c) = needed_correction(parameter, spec, factors) else {
        return FileVerdict::Unknown;
    };
    let tol = p["tolerance"]
        .as_f64()
        .unwrap_or(tcomp_thermal::sim::machine::tolerance::DEFAULT_TOLERANCE);
    if (1.0 - tol..=1.0 + tol).contains(&c) {
        return FileVerdict::InsideTolerance;
    }
    let factor = p["factor"].as_f64().unwrap_or(f64::NAN);
    if (factor > 1.0) == (c > 1.0) && factor.is_finite() && factor != 1.0 {
        FileVerdict::True
    } else {
        FileVerdict::WrongDirection
    }
}

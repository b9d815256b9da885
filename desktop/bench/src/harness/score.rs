//! Scoring one diagnosis (its JSON, `Diagnosis::to_json`) against the
//! withheld truth, the issue 27 way: *named* (the top effect is right, or
//! the first parameter finding names the effect's physics while no effect
//! is named), *honest* (nothing named, and the true effect is listed under
//! `untestable`), *wrong* (something else named), *silent* (nothing named,
//! nothing listed); an ambiguous answer (`ambiguous`, nothing named) is
//! honest when it contains the true effect, wrong otherwise (issue 52).
//! Works on the JSON: parameter findings (design values
//! that had to leave their tolerance) are the `effects` entries whose
//! evidence says so, or a `findings` list; each is judged against the drawn
//! design file by `file_truth.rs`.

use serde_json::Value;

use super::file_truth::{is_parameter_finding, judge_finding};

/// What a parameter finding says physically (from its keys and words).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Physics {
    /// Film coefficients, losses to air.
    Convection,
    /// Coolant jackets, the chiller, the tank.
    Coolant,
    /// A heat source's gain (motor, bearing, screw, any `[[source]]`).
    HeatSource,
    /// A joint or link conductance.
    Joint,
    /// Lever lengths of the displacement map.
    Geometry,
    /// Heat capacities.
    Capacity,
}

/// Words that say which physics a finding is about, first match wins
/// (coolant before convection: a tank's loss to air is the coolant's).
pub const PHYSICS_WORDS: &[(Physics, &[&str])] = &[
    (Physics::Coolant, &["jacket", "coolant", "chiller", "tank"]),
    (
        Physics::Convection,
        &["film", "convection", "g_amb", "loss to air", "h_w_per_m2k"],
    ),
    (
        Physics::HeatSource,
        &[
            "source",
            "w_at_nmax",
            "heat gain",
            "heat budget",
            "bearing",
            "motor",
            "f0",
            "f1",
        ],
    ),
    (Physics::Joint, &["link", "joint"]),
    (Physics::Geometry, &["length_mm", "lever", "direction"]),
    (
        Physics::Capacity,
        &["c_j_per_k", "capacity", "cp_j_per_kgk"],
    ),
];

/// Per truth kind (the diagnosis name it should be found as): the effect
/// names that count as naming it, the parameter physics that count, and
/// the `untestable` qualifiers (in parentheses) that do NOT cover it.
pub struct KindRule {
    pub kind: &'static str,
    pub effect_names: &'static [&'static str],
    pub physics: &'static [Physics],
    pub not_covered_by: &'static [&'static str],
}

/// The scoring table. A step inside a run is not "constant over a run"; a
/// chiller's cycling is not the coolant's on/off level.
pub const KIND_RULES: &[KindRule] = &[
    KindRule {
        kind: "sensor_offset",
        effect_names: &["sensor_offset"],
        physics: &[],
        not_covered_by: &["constant over a run"],
    },
    KindRule {
        kind: "sensor_lag",
        effect_names: &["sensor_lag"],
        physics: &[],
        not_covered_by: &[],
    },
    KindRule {
        kind: "coolant",
        effect_names: &["coolant", "chiller", "periodic"],
        physics: &[Physics::Coolant],
        not_covered_by: &["on/off level"],
    },
    KindRule {
        kind: "chiller",
        effect_names: &["coolant", "chiller", "periodic"],
        physics: &[Physics::Coolant],
        not_covered_by: &["on/off level"],
    },
    KindRule {
        kind: "periodic",
        effect_names: &["periodic", "chiller", "coolant"],
        physics: &[],
        not_covered_by: &["on/off level"],
    },
    KindRule {
        kind: "bearing_nonlinear",
        effect_names: &["bearing_nonlinear"],
        physics: &[Physics::HeatSource],
        not_covered_by: &[],
    },
    KindRule {
        kind: "ballscrew",
        effect_names: &["ballscrew"],
        physics: &[Physics::HeatSource],
        not_covered_by: &[],
    },
    KindRule {
        kind: "ambient_drift",
        effect_names: &["ambient_drift"],
        physics: &[Physics::Convection],
        not_covered_by: &[],
    },
    KindRule {
        kind: "convection",
        effect_names: &["convection"],
        physics: &[Physics::Convection],
        not_covered_by: &[],
    },
    KindRule {
        kind: "bending",
        effect_names: &["bending"],
        physics: &[Physics::Geometry],
        not_covered_by: &[],
    },
];

/// The withheld truth of an effect case.
#[derive(Clone, Debug)]
pub struct Truth {
    /// Diagnosis name of the effect (`KIND_RULES`' `kind`).
    pub kind: String,
    /// The sensor column of a sensor effect (the top effect must name it).
    pub sensor: Option<String>,
    /// A lag's time constant [s] (for "shorter than X s" entries).
    pub tau_s: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Named,
    Honest,
    Wrong,
    Silent,
}

impl Outcome {
    pub fn label(self) -> &'static str {
        match self {
            Outcome::Named => "named",
            Outcome::Honest => "honest",
            Outcome::Wrong => "wrong",
            Outcome::Silent => "silent",
        }
    }
}

/// A clean case: an effect named, parameter findings true of the drawn
/// file, and findings that are not (`file_truth.rs`). A false alarm is an
/// effect named or a finding not true of the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CleanOutcome {
    pub false_alarm: bool,
    /// An effect (not a parameter finding) named.
    pub effect: bool,
    /// Parameter findings true of the drawn file.
    pub true_findings: usize,
    /// Parameter findings not true of it (every finding with the exact file).
    pub false_findings: usize,
}

/// The parameter findings of one diagnosis against the drawn file: naming
/// the effect's physics (effect cases), true of the file, neither.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct FindingCounts {
    pub names_effect: usize,
    pub true_of_file: usize,
    pub neither: usize,
}

/// The design file a column gave the diagnosis, when it was drawn: the
/// exact spec and the factors drawn on its design numbers.
#[derive(Clone, Copy)]
pub struct DrawnFile<'a> {
    pub spec: &'a tcomp_thermal::sim::machine::spec::MachineSpec,
    pub factors: &'a [(String, f64)],
}

fn rule(kind: &str) -> Option<&'static KindRule> {
    KIND_RULES.iter().find(|r| r.kind == kind)
}

fn list(d: &Value, key: &str) -> Vec<Value> {
    d.get(key)
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default()
}

/// The effects the diagnosis names: its `effects` ranking without the
/// parameter findings it carries.
pub fn effects_of(d: &Value) -> Vec<Value> {
    list(d, "effects")
        .into_iter()
        .filter(|e| !is_parameter_finding(e))
        .collect()
}

/// Its parameter findings: those in the `effects` ranking (in rank order),
/// then any `findings` list.
pub fn findings_of(d: &Value) -> Vec<Value> {
    let mut f: Vec<Value> = list(d, "effects")
        .into_iter()
        .filter(is_parameter_finding)
        .collect();
    f.extend(list(d, "findings"));
    f
}

/// Whether the finding `f` is true of the drawn file (never without one:
/// the exact file needs no number outside its tolerance).
fn true_of(f: &Value, file: Option<DrawnFile>) -> bool {
    file.is_some_and(|x| judge_finding(f, x.spec, x.factors).is_true())
}

/// The physics of a parameter finding: its `physics`, `meaning`, `kind`,
/// `group`, `parameter` or `name` field (first that classifies), else any
/// of its words.
pub fn finding_physics(f: &Value) -> Option<Physics> {
    let classify = |text: &str| {
        let t = text.to_lowercase();
        PHYSICS_WORDS
            .iter()
            .find(|(_, words)| words.iter().any(|w| t.contains(w)))
            .map(|(p, _)| *p)
    };
    // the diagnosis' own findings carry their tolerance group as
    // `params.parameter` (`group` or `group:element`): the group decides,
    // not words of a node name (a link to a node called `motor`)
    let group = f["params"]["parameter"]
        .as_str()
        .map(|p| p.split(':').next().unwrap_or(p));
    let by_group = match group {
        Some("film") => Some(Physics::Convection),
        Some("jacket") => Some(Physics::Coolant),
        Some("heat") => Some(Physics::HeatSource),
        Some("link") => Some(Physics::Joint),
        Some("length") => Some(Physics::Geometry),
        Some("capacity") => Some(Physics::Capacity),
        _ => None,
    };
    if by_group.is_some() {
        return by_group;
    }
    for key in ["physics", "meaning", "kind", "group", "parameter", "name"] {
        if let Some(p) = f.get(key).and_then(Value::as_str).and_then(classify) {
            return Some(p);
        }
    }
    classify(&f.to_string())
}

/// Whether the effect entry `e` (`effects[i]`) names the truth.
fn effect_names(e: &Value, truth: &Truth, r: &KindRule) -> bool {
    // a pair (`a+b`) does not name a single effect: it adds a partner
    let name = e["name"].as_str().unwrap_or("");
    if !r.effect_names.contains(&name) {
        return false;
    }
    truth
        .sensor
        .as_ref()
        .is_none_or(|s| e["params"]["sensor"].as_str() == Some(s.as_str()))
}

/// Whether an `untestable` entry's name covers the truth: its head word
/// (before a space, `(` or ` / `) is one of the kind's effect names, its
/// qualifier in parentheses does not exclude the case, "on A, B" lists the
/// truth's sensor, and "shorter than X s" is above the truth's lag.
pub fn untestable_covers(entry: &str, truth: &Truth) -> bool {
    let Some(r) = rule(&truth.kind) else {
        return false;
    };
    let head = entry.split([' ', '(']).next().unwrap_or("");
    if !r.effect_names.contains(&head) {
        return false;
    }
    if r.not_covered_by.iter().any(|q| entry.contains(q)) {
        return false;
    }
    if let (Some(s), Some(i)) = (&truth.sensor, entry.find(" on ")) {
        let listed = entry[i + 4..].split(',').any(|x| x.trim() == s);
        if !listed {
            return false;
        }
    }
    if let (Some(tau), Some(i)) = (truth.tau_s, entry.find("shorter than ")) {
        let rest = &entry[i + "shorter than ".len()..];
        let x: Option<f64> = rest.split_whitespace().next().and_then(|x| x.parse().ok());
        if x.is_none_or(|x| tau >= x) {
            return false;
        }
    }
    true
}

/// The explanations an ambiguous answer lists (`ambiguous`, issue 52):
/// empty when the diagnosis names a cause or says nothing.
pub fn ambiguous_of(d: &Value) -> Vec<String> {
    list(d, "ambiguous")
        .iter()
        .filter_map(|v| v.as_str().map(str::to_string))
        .collect()
}

/// An ambiguous answer (nothing named, `ambiguous` non-empty) scored on an
/// effect case: honest when it contains the true effect (an entry's head
/// word among the kind's effect names; the sensor is not checked, the
/// entries are classes), wrong otherwise. None for any other answer.
pub fn score_ambiguous(d: &Value, truth: &Truth) -> Option<Outcome> {
    let names = ambiguous_of(d);
    if names.is_empty() || !effects_of(d).is_empty() {
        return None;
    }
    let r = rule(&truth.kind);
    let holds = names.iter().any(|n| {
        let head = n.split([' ', '(']).next().unwrap_or("");
        r.is_some_and(|r| r.effect_names.contains(&head))
    });
    Some(if holds {
        Outcome::Honest
    } else {
        Outcome::Wrong
    })
}

/// Score an effect case.
pub fn score_effect(d: &Value, truth: &Truth) -> Outcome {
    if let Some(o) = score_ambiguous(d, truth) {
        return o;
    }
    let effects = effects_of(d);
    let findings = findings_of(d);
    let r = rule(&truth.kind);
    if let (Some(top), Some(r)) = (effects.first(), r) {
        if effect_names(top, truth, r) {
            return Outcome::Named;
        }
    }
    if effects.is_empty() {
        if let (Some(f), Some(r)) = (findings.first(), r) {
            if finding_physics(f).is_some_and(|p| r.physics.contains(&p)) {
                return Outcome::Named;
            }
        }
    }
    if !effects.is_empty() || !findings.is_empty() {
        return Outcome::Wrong;
    }
    let listed = list(d, "untestable").iter().any(|u| {
        u["name"]
            .as_str()
            .or(u.as_str())
            .is_some_and(|n| untestable_covers(n, truth))
    });
    if listed {
        Outcome::Honest
    } else {
        Outcome::Silent
    }
}

/// Score a clean case given the file the diagnosis had (`None`: the exact
/// file, or no file).
pub fn score_clean(d: &Value, file: Option<DrawnFile>) -> CleanOutcome {
    // an ambiguous answer says an effect is there: on a clean case it is
    // counted as one named
    let effect = !effects_of(d).is_empty() || !ambiguous_of(d).is_empty();
    let findings = findings_of(d);
    let true_findings = findings.iter().filter(|f| true_of(f, file)).count();
    let false_findings = findings.len() - true_findings;
    CleanOutcome {
        false_alarm: effect || false_findings > 0,
        effect,
        true_findings,
        false_findings,
    }
}

/// Count the parameter findings of `d`: those whose physics names the
/// truth's effect (`truth`: an effect case), those true of the drawn file,
/// and the rest.
pub fn count_findings(d: &Value, truth: Option<&Truth>, file: Option<DrawnFile>) -> FindingCounts {
    let r = truth.and_then(|t| rule(&t.kind));
    let mut c = FindingCounts::default();
    for f in findings_of(d) {
        if r.is_some_and(|r| finding_physics(&f).is_some_and(|p| r.physics.contains(&p))) {
            c.names_effect += 1;
        } else if true_of(&f, file) {
            c.true_of_file += 1;
        } else {
            c.neither += 1;
        }
    }
    c
}

/// The truth of an open-world (truth model) effect.
pub fn truth_of_open(e: &crate::truth::TruthEffect) -> Truth {
    use crate::truth::TruthEffect;
    let (sensor, tau_s) = match e {
        TruthEffect::SensorStep { sensor, .. } => (Some(format!("T_T{sensor}")), None),
        TruthEffect::SensorLag { sensor, tau_s } => (Some(format!("T_T{sensor}")), Some(*tau_s)),
        _ => (None, None),
    };
    Truth {
        kind: e.diagnosis_name().to_string(),
        sensor,
        tau_s,
    }
}

/// The truth of an effect of the first simulator (cross-model column).
pub fn truth_of_sim(e: &tcomp_thermal::sim::Effect) -> Truth {
    use tcomp_thermal::sim::Effect;
    let (sensor, tau_s) = match e {
        Effect::SensorOffset { sensor, .. } => (Some(sensor.clone()), None),
        Effect::SensorLag { sensor, tau_s } => (sensor.clone(), Some(*tau_s)),
        _ => (None, None),
    };
    Truth {
        kind: e.name().to_string(),
        sensor,
        tau_s,
    }
}

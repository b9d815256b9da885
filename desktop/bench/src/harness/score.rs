//! Scoring one diagnosis (its JSON, `Diagnosis::to_json`) against the
//! withheld truth, the issue 27 way: *named* (the top effect is right, or
//! the first parameter finding names the effect's physics while no effect
//! is named), *honest* (nothing named, and the true effect is listed under
//! `untestable`), *wrong* (something else named), *silent* (nothing named,
//! nothing listed). Works on the JSON so that fields a later diagnosis adds
//! (`findings`: design parameters that had to leave their tolerance) are
//! read when present.

use serde_json::Value;

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

/// A clean case: an effect named (a false alarm) and/or a parameter finding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CleanOutcome {
    pub false_alarm: bool,
    pub finding: bool,
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

/// Score an effect case.
pub fn score_effect(d: &Value, truth: &Truth) -> Outcome {
    let effects = list(d, "effects");
    let findings = list(d, "findings");
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

/// Score a clean case.
pub fn score_clean(d: &Value) -> CleanOutcome {
    CleanOutcome {
        false_alarm: !list(d, "effects").is_empty(),
        finding: !list(d, "findings").is_empty(),
    }
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

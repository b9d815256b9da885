//! Issue 27's bench pieces: the named / honest / wrong scorer on
//! constructed diagnoses, and the design-file perturbation (lognormal,
//! seeded, every design number changed, reproducible).
use serde_json::json;
use tcomp_bench::harness::file_truth::{design_keys, judge_finding, FileVerdict};
use tcomp_bench::harness::perturb::{
    design_numbers, design_seed, perturb_machine, perturb_spec, DESIGN_SIGMA,
};
use tcomp_bench::harness::score::{
    count_findings, finding_physics, score_clean, score_effect, untestable_covers, DrawnFile,
    Outcome, Physics, Truth,
};
use tcomp_thermal::sim::Machine;

fn truth(kind: &str, sensor: Option<&str>, tau_s: Option<f64>) -> Truth {
    Truth {
        kind: kind.into(),
        sensor: sensor.map(String::from),
        tau_s,
    }
}

fn effect(name: &str, params: serde_json::Value) -> serde_json::Value {
    json!({"effects": [{"name": name, "params": params}], "untestable": []})
}

#[test]
fn the_top_effect_names_the_truth_only_with_its_sensor() {
    let d = effect("sensor_offset", json!({"sensor": "T_T3", "offset_c": 0.5}));
    let t3 = truth("sensor_offset", Some("T_T3"), None);
    let t4 = truth("sensor_offset", Some("T_T4"), None);
    assert_eq!(score_effect(&d, &t3), Outcome::Named);
    assert_eq!(score_effect(&d, &t4), Outcome::Wrong);
    // the chiller is named as coolant, chiller or a periodic drive
    let c = truth("coolant", None, None);
    for n in ["coolant", "chiller", "periodic"] {
        assert_eq!(score_effect(&effect(n, json!({})), &c), Outcome::Named);
    }
    // a pair adds a partner: not the single effect
    let b = truth("bearing_nonlinear", None, None);
    assert_eq!(
        score_effect(&effect("bearing_nonlinear+bending", json!({})), &b),
        Outcome::Wrong
    );
    assert_eq!(
        score_effect(&effect("bearing_nonlinear", json!({})), &b),
        Outcome::Named
    );
    // the second effect does not count
    let two = json!({"effects": [{"name": "ballscrew"}, {"name": "bearing_nonlinear"}]});
    assert_eq!(score_effect(&two, &b), Outcome::Wrong);
}

#[test]
fn nothing_named_is_honest_only_when_untestable_covers_the_case() {
    let d = |names: &[&str]| json!({"effects": [], "untestable": names.iter().map(|n| json!({"name": n, "reason": "r"})).collect::<Vec<_>>()});
    let lag5 = truth("sensor_lag", Some("T_T5"), Some(300.0));
    let lag1 = truth("sensor_lag", Some("T_T1"), Some(300.0));
    let listed = d(&["convection", "sensor_lag on T_T2, T_T5"]);
    assert_eq!(score_effect(&listed, &lag5), Outcome::Honest);
    assert_eq!(score_effect(&listed, &lag1), Outcome::Silent);
    // "shorter than X s": only lags below X are covered
    let short = d(&["sensor_lag shorter than 600 s on T_T5"]);
    assert_eq!(score_effect(&short, &lag5), Outcome::Honest);
    let long5 = truth("sensor_lag", Some("T_T5"), Some(800.0));
    assert_eq!(score_effect(&short, &long5), Outcome::Silent);
    // a step inside a run is not "constant over a run"
    let step = truth("sensor_offset", Some("T_T0"), None);
    assert_eq!(
        score_effect(&d(&["sensor_offset (constant over a run)"]), &step),
        Outcome::Silent
    );
    assert!(!untestable_covers(
        "coolant (on/off level)",
        &truth("coolant", None, None)
    ));
    let speed = truth("bearing_nonlinear", None, None);
    assert_eq!(
        score_effect(&d(&["bearing_nonlinear / speed nonlinearity"]), &speed),
        Outcome::Honest
    );
    assert_eq!(
        score_effect(
            &d(&["ambient_drift (beyond T_ambient)"]),
            &truth("ambient_drift", None, None)
        ),
        Outcome::Honest
    );
    // listed but something else named: wrong, not honest
    let mut named = d(&["bearing_nonlinear / speed nonlinearity"]);
    named["effects"] = json!([{"name": "sensor_offset", "params": {"sensor": "T_T0"}}]);
    assert_eq!(score_effect(&named, &speed), Outcome::Wrong);
    // nothing at all
    assert_eq!(score_effect(&json!({}), &speed), Outcome::Silent);
}

#[test]
fn a_parameter_finding_names_the_effect_by_its_physics() {
    let film = json!({"effects": [], "findings": [
        {"parameter": "node g_amb_w_per_k (all 20)", "meaning": "film coefficients ×1.9: convection", "design": 1.6, "fitted": 3.0}
    ]});
    assert_eq!(
        finding_physics(&film["findings"][0]),
        Some(Physics::Convection)
    );
    assert_eq!(
        score_effect(&film, &truth("ambient_drift", None, None)),
        Outcome::Named
    );
    assert_eq!(
        score_effect(&film, &truth("convection", None, None)),
        Outcome::Named
    );
    assert_eq!(
        score_effect(&film, &truth("sensor_lag", Some("T_T1"), Some(300.0))),
        Outcome::Wrong
    );
    let source = json!({"effects": [], "findings": [{"parameter": "source 1 h1 w_at_nmax", "design": 75.0, "fitted": 150.0}]});
    assert_eq!(
        finding_physics(&source["findings"][0]),
        Some(Physics::HeatSource)
    );
    assert_eq!(
        score_effect(&source, &truth("bearing_nonlinear", None, None)),
        Outcome::Named
    );
    let jacket = json!({"findings": [{"group": "coolant jacket conductances", "factor": 0.4}]});
    assert_eq!(
        score_effect(&jacket, &truth("coolant", None, None)),
        Outcome::Named
    );
    assert_eq!(
        finding_physics(&json!({"parameter": "link h5-c7 g_w_per_k"})),
        Some(Physics::Joint)
    );
    // with an effect named, the effect decides
    let both = json!({"effects": [{"name": "ballscrew"}], "findings": film["findings"]});
    assert_eq!(
        score_effect(&both, &truth("ambient_drift", None, None)),
        Outcome::Wrong
    );
}

/// A parameter finding as `diagnose` ranks it among the effects.
fn finding(parameter: &str, factor: f64, tol: f64) -> serde_json::Value {
    json!({
        "name": format!("parameter:{parameter}"),
        "params": {"parameter": parameter, "factor": factor, "tolerance": tol},
        "evidence": {"kind": "design value outside its tolerance"},
    })
}

/// The factors of a drawn file: every design number of `m` ×1 except `set`.
fn factors(m: &Machine, set: &[(&str, f64)]) -> Vec<(String, f64)> {
    design_numbers(&m.spec)
        .into_iter()
        .map(|(k, _)| {
            let f = set.iter().find(|s| s.0 == k).map_or(1.0, |s| s.1);
            (k, f)
        })
        .collect()
}

#[test]
fn a_parameter_finding_is_true_of_the_file_only_outside_its_tolerance_and_the_right_way() {
    let m = truth_machine();
    // link h1-h2 drawn ×2.5: the file needs ×0.4, outside ±25 %
    let fs = factors(
        &m,
        &[("link h1-h2 g_w_per_k", 2.5), ("node h3 c_j_per_k", 1.15)],
    );
    let v = |f: &serde_json::Value| judge_finding(f, &m.spec, &fs);
    assert_eq!(v(&finding("link:h1-h2", 0.45, 0.25)), FileVerdict::True);
    // named either way round
    assert_eq!(v(&finding("link:h2-h1", 0.45, 0.25)), FileVerdict::True);
    // the finding moves it up: wrong direction
    assert_eq!(
        v(&finding("link:h1-h2", 1.8, 0.25)),
        FileVerdict::WrongDirection
    );
    // h3's capacity drawn ×1.15: needs ×0.87, inside the tolerance
    assert_eq!(
        v(&finding("capacity:h3", 0.5, 0.25)),
        FileVerdict::InsideTolerance
    );
    // the tolerance the diagnosis used decides: ±10 % leaves it outside
    assert_eq!(v(&finding("capacity:h3", 0.8, 0.10)), FileVerdict::True);
    assert_eq!(
        v(&finding("capacity:nowhere", 0.5, 0.25)),
        FileVerdict::Unknown
    );
    // a group: the geometric mean of what its members need
    let links: Vec<String> = design_numbers(&m.spec)
        .into_iter()
        .map(|(k, _)| k)
        .filter(|k| k.starts_with("link "))
        .collect();
    assert_eq!(design_keys("link", &m.spec), links);
    let half: Vec<(&str, f64)> = links.iter().map(|k| (k.as_str(), 2.0)).collect();
    let all_off = factors(&m, &half);
    assert_eq!(
        judge_finding(&finding("link", 0.55, 0.25), &m.spec, &all_off),
        FileVerdict::True
    );
    // one member far off moves the group's mean too little
    assert_eq!(
        judge_finding(&finding("link", 0.55, 0.25), &m.spec, &fs),
        FileVerdict::InsideTolerance
    );
    // the spindle's heat: its sources, bearings and motor loss together
    let heat = design_keys("heat:spindle", &m.spec);
    assert!(
        !heat.is_empty()
            && heat.iter().all(|k| k.starts_with("source ")
                || k.starts_with("bearing ")
                || k == "motor_loss_frac")
    );
    // one heated node: only what sits on it (the nose bearing seat h1)
    let node = design_keys("heat:h1", &m.spec);
    assert!(
        !node.is_empty() && node.iter().all(|k| k.ends_with(" h1 w_at_nmax")),
        "{node:?}"
    );
    assert!(node.len() < heat.len(), "{node:?} against {heat:?}");
}

#[test]
fn a_clean_case_alarms_on_an_effect_or_a_finding_untrue_of_the_file() {
    let m = truth_machine();
    let none = score_clean(
        &json!({"effects": [], "untestable": [{"name": "convection"}]}),
        None,
    );
    assert!(!none.false_alarm && none.true_findings + none.false_findings == 0);
    let eff = score_clean(&json!({"effects": [{"name": "ballscrew"}]}), None);
    assert!(eff.false_alarm && eff.effect);
    // a finding true of the drawn file is no false alarm; with the exact
    // file (no drawn factors) it is one
    let fs = factors(&m, &[("link h1-h2 g_w_per_k", 2.5)]);
    let file = Some(DrawnFile {
        spec: &m.spec,
        factors: &fs,
    });
    let d = json!({"effects": [finding("link:h1-h2", 0.45, 0.25)]});
    let c = score_clean(&d, file);
    assert!(!c.false_alarm && !c.effect && c.true_findings == 1 && c.false_findings == 0);
    assert!(score_clean(&d, None).false_alarm);
    let wrong =
        json!({"effects": [finding("link:h1-h2", 0.45, 0.25), finding("capacity:h3", 0.6, 0.25)]});
    let c = score_clean(&wrong, file);
    assert!(c.false_alarm && c.true_findings == 1 && c.false_findings == 1);
    // effect cases: a finding naming the effect's physics, one true of the
    // file, one neither
    let three = json!({"effects": [finding("film", 1.9, 0.25), finding("link:h1-h2", 0.45, 0.25), finding("capacity:h3", 0.6, 0.25)]});
    let conv = truth("convection", None, None);
    assert_eq!(score_effect(&three, &conv), Outcome::Named);
    let n = count_findings(&three, Some(&conv), file);
    assert_eq!((n.names_effect, n.true_of_file, n.neither), (1, 1, 1));
    // the group decides the physics, not a node's name
    assert_eq!(
        finding_physics(&finding("capacity:motor", 0.5, 0.25)),
        Some(Physics::Capacity)
    );
}

fn truth_machine() -> Machine {
    let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/machines/vertical-mc-truth.toml");
    Machine::load(&p).unwrap()
}

#[test]
fn the_design_perturbation_changes_every_number_by_a_seeded_lognormal_factor() {
    let m = truth_machine();
    let before = design_numbers(&m.spec);
    // 20 nodes × 3 (capacity, loss, area), 19 links, 4 sources, 2 tank,
    // 3 jackets, 31 lengths
    assert_eq!(before.len(), 60 + 19 + 4 + 2 + 3 + 31);
    let mut logs = Vec::new();
    for s in 0..20u64 {
        let seed = design_seed(7, 0, s as usize);
        let (spec, factors) = perturb_spec(&m.spec, DESIGN_SIGMA, seed);
        let after = design_numbers(&spec);
        assert_eq!(after.len(), before.len());
        for (((k, a), (k2, b)), (k3, f)) in before.iter().zip(&after).zip(&factors) {
            assert!(k == k2 && k == k3);
            assert!(b != a, "{k} unchanged");
            assert!((b / a - f).abs() < 1e-12 * f, "{k}: {b} / {a} is not {f}");
            logs.push(f.ln());
        }
        // not design numbers: temperatures, speeds, exponents, names
        assert_eq!(spec.ambient_c, m.spec.ambient_c);
        assert_eq!(spec.n_max_rpm, m.spec.n_max_rpm);
        assert_eq!(
            spec.coolant.as_ref().unwrap().supply_c,
            m.spec.coolant.as_ref().unwrap().supply_c
        );
        for (x, y) in spec.sources.iter().zip(&m.spec.sources) {
            assert_eq!(x.exponent, y.exponent);
        }
        // reproducible from the seed; another case draws another file
        let (again, _) = perturb_spec(&m.spec, DESIGN_SIGMA, seed);
        assert_eq!(design_numbers(&again), after);
        let (other, _) = perturb_spec(&m.spec, DESIGN_SIGMA, design_seed(7, 0, s as usize + 1));
        assert_ne!(design_numbers(&other), after);
        // the perturbed file passes the machine file's checks
        perturb_machine(&m, DESIGN_SIGMA, seed).unwrap();
    }
    // ln factor ~ N(0, σ²): mean and spread over 20 × 119 draws
    let n = logs.len() as f64;
    let mu = logs.iter().sum::<f64>() / n;
    let sd = (logs.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(mu.abs() < 0.012, "mean log factor {mu}");
    assert!((sd - DESIGN_SIGMA).abs() < 0.012, "σ of log factor {sd}");
    // σ = 0 leaves the file as it is
    let (same, _) = perturb_spec(&m.spec, 0.0, 1);
    assert_eq!(design_numbers(&same), before);
}

#[test]
fn the_cross_model_machines_are_perturbed_too() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/machines");
    for f in ["turning-center-16.toml", "five-axis-20.toml"] {
        let m = Machine::load(&dir.join(f)).unwrap();
        let before = design_numbers(&m.spec);
        // bearings (f0, f1) and the rotor rod are design numbers there
        assert!(before.iter().any(|(k, _)| k.ends_with(" f0")), "{f}");
        assert!(before.iter().any(|(k, _)| k == "rod k_w_per_mk"), "{f}");
        let (p, _) = perturb_machine(&m, DESIGN_SIGMA, 3).unwrap();
        let after = design_numbers(&p.spec);
        assert!(before.iter().zip(&after).all(|(a, b)| a.1 != b.1), "{f}");
        // every calibration group names design numbers of the file
        for g in ["capacity", "film", "link", "jacket", "heat", "length"] {
            let ks = design_keys(g, &m.spec);
            assert!(
                ks.iter().all(|k| before.iter().any(|b| &b.0 == k)),
                "{f} {g}"
            );
        }
        // the rod's ends are links to its first and last slice
        let r = m.spec.rod.as_ref().unwrap();
        let front = r.front.as_ref().unwrap();
        assert_eq!(
            design_keys(&format!("link:{}-rod:0", front.node), &m.spec),
            ["rod front g_w_per_k"]
        );
        assert_eq!(design_keys("capacity:rod", &m.spec), ["rod cp_j_per_kgk"]);
        // a bearing node's viscous term is its own knob: `<node>:f0` names
        // f0 only, the node's knob the rest (f1 and whatever else sits there)
        let b = &m.spec.bearings[0].node;
        assert_eq!(
            design_keys(&format!("heat:{b}:f0"), &m.spec),
            [format!("bearing {b} f0")]
        );
        let node = design_keys(&format!("heat:{b}"), &m.spec);
        assert!(node.contains(&format!("bearing {b} f1")), "{f} {node:?}");
        assert!(!node.contains(&format!("bearing {b} f0")), "{f} {node:?}");
    }
}

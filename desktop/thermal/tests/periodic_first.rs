//! Periodic first where a periodic driver is measured (issue 52 item 3):
//! a machine whose coolant tank is a node of its own, read by `T_coolant`.
//! A chiller that pulls the tank along a sawtooth (and away from the level
//! the design lets it float to) is named as the periodic driver, with its
//! period, ahead of anything that only follows the slow part; a tank whose
//! capacity is three times the design's, with no sawtooth, still gets the
//! parameter finding and no periodic claim.
use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{diagnose, Diagnosis, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

const TANK_C: &str = "c_j_per_k = 120000.0";

/// The turning centre of the examples with a 60 l oil tank as a node,
/// linked to the spindle housing (its jacket) and read by `T_coolant`;
/// `coolant_nodes` is where the `coolant` effect acts (the design: the
/// housing).
fn machine_text() -> String {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/machines/turning-center-16.toml"
    );
    let src = std::fs::read_to_string(path).unwrap();
    let tank = format!(
        "[[node]]\nname = \"coolant\"\n{TANK_C}\ng_amb_w_per_k = 6.0\narea_m2 = 0.8\n\
         [[link]]\na = \"coolant\"\nb = \"housing\"\ng_w_per_k = 6.0\n\
         [[sensor]]\nname = \"T_coolant\"\nnode = \"coolant\"\n\n"
    );
    let at = src.find("[effects]").unwrap();
    format!("{}{tank}{}", &src[..at], &src[at..])
}

/// An 8 h duty of irregular segments (no period of its own: lengths from
/// the golden ratio's multiples), the coolant pump on throughout.
fn duty(shift: usize) -> Duty {
    let speeds = [0.0, 3000.0, 8000.0, 1500.0, 11000.0, 0.0, 5000.0];
    let mut csv = String::from("time_s,spindle_rpm,feed_activity,coolant_on\n");
    let (mut t, mut k) = (0.0, shift);
    while t < 8.0 * 3600.0 {
        let rpm = speeds[k % speeds.len()];
        let feed = if rpm > 0.0 {
            0.2 + 0.1 * (k % 7) as f64
        } else {
            0.0
        };
        csv.push_str(&format!("{t},{rpm},{feed},1\n"));
        let u = (k as f64 * 0.618_033_988_75).fract();
        t += 300.0 + (u * 35.0).round() * 60.0;
        k += 1;
    }
    Duty::from_csv(&csv, "irregular").unwrap()
}

/// Two 8 h runs (10 s rows, noise) of `truth` with `effects`.
fn runs(truth: &Machine, effects: &[Effect]) -> Vec<(String, Run)> {
    (0..2)
        .map(|i| {
            let opt = SimOptions {
                effects: effects.to_vec(),
                seed: 11 + i as u64,
                hours: Some(8.0),
                sample_period_s: Some(10.0),
                noise: true,
            };
            (
                format!("run{i}"),
                sim_run(truth, &duty(3 * i), &opt).unwrap(),
            )
        })
        .collect()
}

fn names(d: &Diagnosis) -> Vec<&str> {
    d.findings.iter().map(|f| f.name.as_str()).collect()
}

#[test]
fn a_chiller_sawtooth_on_the_measured_tank_is_named_periodic_first() {
    let design = Machine::from_toml(&machine_text()).unwrap();
    // the truth: the chiller holds the tank 1 °C under the air along a
    // 30 min sawtooth of ±0.6 °C (the `coolant` effect on the tank node)
    let truth_text = machine_text().replace(
        "coolant_nodes = [\"housing\"]",
        "coolant_nodes = [\"coolant\"]",
    );
    let truth = Machine::from_toml(&truth_text).unwrap();
    let saw = Effect::parse("coolant=g_w_per_k:150,offset_c:-1.0,amp_c:1.2,period_s:1800").unwrap();
    let d = diagnose(&design, &runs(&truth, &[saw]), &Options::default()).unwrap();
    let top = d
        .findings
        .first()
        .unwrap_or_else(|| panic!("nothing named"));
    assert_eq!(top.name, "periodic", "{:?}", names(&d));
    let p = top.params_json();
    assert_eq!(p["channel"], "T_coolant", "{p}");
    let period = p["period_s"].as_f64().unwrap();
    assert!((period / 1800.0 - 1.0).abs() <= 0.05, "period {period}");
    assert!(
        d.ranking_rule.contains("parameter finding named first"),
        "the rule is stated"
    );
}

#[test]
fn a_genuine_tank_capacity_error_still_gets_the_parameter_finding() {
    let design = Machine::from_toml(&machine_text()).unwrap();
    let truth =
        Machine::from_toml(&machine_text().replace(TANK_C, "c_j_per_k = 360000.0")).unwrap();
    let d = diagnose(&design, &runs(&truth, &[]), &Options::default()).unwrap();
    let top = d
        .findings
        .first()
        .unwrap_or_else(|| panic!("nothing named"));
    assert_eq!(top.name, "parameter:capacity:coolant", "{:?}", names(&d));
    let factor = top.params_json()["factor"].as_f64().unwrap();
    assert!(
        factor > 1.25,
        "factor {factor}: outside the +25 % tolerance"
    );
    assert!(
        d.findings.iter().all(|f| f.name != "periodic"),
        "{:?}",
        names(&d)
    );
}

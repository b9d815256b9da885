//! `diagnose fit` names `sensor_lag` only where the lag is the sensor's
//! own (`effects::lag_specific`, issue 52 item 2): a true lag on one
//! sensor of the simulator's vertical machine is still named; an air drift
//! and ball-screw heat on machines read by a few sensors only (the
//! displacement then leads the sensors, as a lag would make it) is not
//! named a lag — before the signature test it was (`T_T3`).
//!
//! Left out, and why: ball-screw heat on the turning centre read by seven
//! sensors (`Effect::Ballscrew { k_w: 49.8 }`, sensors T01 T04 T06 T11 T13
//! T15 T16, seed 1002) is still named a lag of `T13`. There the sensor sits
//! one conduction step downstream of the heated, unsensed node the
//! displacement follows, so its reading *is* a first-order lag of that
//! body: the implied lag is 496–535 s in every band and run. Displacement
//! and sensors alone cannot tell it from a lagging sensor (a sensor on the
//! nut, or a run with feed and no spindle, would); the bench keeps counting
//! such cases as wrong.
use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{fitmode::diagnose_fit, Diagnosis, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

fn machine(name: &str) -> Machine {
    let p = std::path::PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/machines"
    ));
    Machine::load(&p.join(format!("{name}.toml"))).unwrap()
}

/// Two 4 h runs at 10 s of `m` under the two duties (`t,rpm,feed,coolant;…`),
/// noise seeds `seed` and `seed + 1`, with `effect`, keeping only the
/// sensors `keep` (all when empty).
fn runs(
    m: &Machine,
    duties: [&str; 2],
    seed: u64,
    effect: Effect,
    keep: &[&str],
) -> Vec<(String, Run)> {
    duties
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let csv = format!(
                "time_s,spindle_rpm,feed_activity,coolant_on\n{}",
                d.replace(';', "\n")
            );
            let duty = Duty::from_csv(&csv, "test").unwrap();
            let mut run = sim_run(
                m,
                &duty,
                &SimOptions {
                    effects: vec![effect.clone()],
                    seed: seed + i as u64,
                    hours: Some(4.0),
                    sample_period_s: Some(10.0),
                    noise: true,
                },
            )
            .unwrap();
            if !keep.is_empty() {
                let drop: Vec<usize> = (0..run.columns.len())
                    .filter(|&c| {
                        let n = &run.columns[c];
                        n.starts_with('T') && n != "T_ambient" && !keep.contains(&n.as_str())
                    })
                    .rev()
                    .collect();
                for c in drop {
                    run.columns.remove(c);
                    run.data.remove(c);
                }
            }
            (format!("run{i}"), run)
        })
        .collect()
}

/// The lag test alone (the other candidates are left out to keep the
/// debug-build test short).
fn lag_only(runs: &[(String, Run)]) -> Diagnosis {
    let opt = Options {
        only: vec!["sensor_lag".into()],
        ..Options::default()
    };
    diagnose_fit(runs, &opt).unwrap()
}

fn named_lags(d: &Diagnosis) -> Vec<String> {
    d.findings
        .iter()
        .filter(|f| f.name == "sensor_lag")
        .map(|f| {
            f.params_json()["sensor"]
                .as_str()
                .unwrap_or("?")
                .to_string()
        })
        .collect()
}

#[test]
fn a_true_lag_is_still_named_with_its_sensor() {
    let m = machine("vertical-mc-truth");
    let r = runs(
        &m,
        [
            "0,0,0,0;842,3453,0.69,1;2649,4896,0.50,1;3563,2304,0.65,1;4933,5259,0.84,1;6270,5716,0.92,1;8182,3173,0.20,1;9453,0,0.00,0;12212,5241,0.17,1;13219,2637,0.80,1",
            "0,0,0,0;1054,0,0.00,0;2346,11510,0.86,1;3742,11113,0.98,1;6414,9233,0.68,1;8062,9182,0.43,1;9071,0,0.00,0;10378,6872,0.14,1;11531,7561,0.34,1;13521,11045,0.79,1",
        ],
        1024,
        Effect::SensorLag {
            tau_s: 404.0,
            sensor: Some("T_T1".into()),
        },
        &[],
    );
    let d = lag_only(&r);
    let top = d.findings.first().expect("nothing named");
    assert_eq!(top.name, "sensor_lag");
    assert_eq!(top.params_json()["sensor"], "T_T1");
    let own = &top.evidence["own_reading"];
    assert_eq!(own["specific"], true, "{own}");
    // the lag its transient implies is a delay in every band and run, and
    // near the injected one (the noise on the reading can only lower it)
    let implied = own["implied_tau_s"].as_f64().unwrap();
    assert!((404.0 / 2.0..=404.0 * 2.0).contains(&implied), "{own}");
    for b in own["bands"].as_array().unwrap() {
        for v in b["implied_tau_s_per_run"].as_array().unwrap() {
            assert!(v.as_f64().unwrap() > 0.0, "{own}");
        }
    }
}

#[test]
fn an_air_drift_read_by_the_spindle_sensors_is_not_a_lag() {
    let m = machine("vertical-mc-truth");
    let r = runs(
        &m,
        [
            "0,0,0,0;845,3763,0.20,1;3449,3833,0.75,1;6254,0,0.00,0;8512,4667,0.41,1;9616,3667,0.89,1;11343,0,0.00,0;12569,6434,0.98,1",
            "0,0,0,0;665,7651,0.85,1;3309,11778,0.73,1;6201,0,0.00,0;8009,0,0.00,0;9744,7967,0.17,1;10785,7214,0.70,1;12553,0,0.00,0",
        ],
        1042,
        Effect::AmbientDrift {
            amp_c: 1.83,
            phase_h: 1.5,
            rate_c_per_h: -0.32,
            period_h: 8.2,
        },
        &["T_T1", "T_T2", "T_T3"],
    );
    let d = lag_only(&r);
    assert!(named_lags(&d).is_empty(), "{:?}", named_lags(&d));
    // the lag that fits the displacement is listed, with why, not named
    assert!(
        d.untestable
            .iter()
            .any(|(n, why)| n.starts_with("sensor_lag (not specific) on ")
                && (why.contains("a lead of") || why.contains("faster with frequency"))),
        "{:?}",
        d.untestable
    );
}

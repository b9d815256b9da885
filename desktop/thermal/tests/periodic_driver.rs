//! Periodic drivers in both diagnosis modes: a chiller's sawtooth on the
//! coolant is named `periodic` with its period and amplitude (not a sensor
//! step), clean runs carry no periodic claim, and a single sensor step is
//! still a step.
use tcomp_data::runcsv::Run;
use tcomp_thermal::diagnose::{diagnose, fitmode::diagnose_fit, Diagnosis, Options};
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

fn examples() -> std::path::PathBuf {
    std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"))
}

/// Two clean 4 h runs of the truth machine's design (coolant tank sensor
/// `T_T9`), 10 s rows, different duties and noise seeds.
fn runs() -> (Machine, Vec<(String, Run)>) {
    let m = Machine::load(&examples().join("machines/vertical-mc-truth.toml")).unwrap();
    let mut out = Vec::new();
    for (i, duty) in ["production-mixed.toml", "heldout-varied.toml"]
        .iter()
        .enumerate()
    {
        let d = Duty::load(&examples().join("duty").join(duty)).unwrap();
        let run = sim_run(
            &m,
            &d,
            &SimOptions {
                effects: Vec::<Effect>::new(),
                seed: 11 + i as u64,
                hours: Some(4.0),
                sample_period_s: Some(10.0),
                noise: true,
            },
        )
        .unwrap();
        out.push((format!("run{i}"), run));
    }
    (m, out)
}

/// Add `f(t)` to column `col` of a run (re-quantised to 1/16 °C as the
/// DS18B20 reads).
fn add(run: &mut Run, col: &str, f: &dyn Fn(f64) -> f64) {
    let ti = run.columns.iter().position(|c| c == "time_s").unwrap();
    let ci = run.columns.iter().position(|c| c == col).unwrap();
    let times: Vec<Option<f64>> = run.data[ti].clone();
    for (v, t) in run.data[ci].iter_mut().zip(times) {
        if let (Some(x), Some(t)) = (v.as_mut(), t) {
            *x = ((*x + f(t)) * 16.0).round() / 16.0;
        }
    }
}

/// Slow rise over 80 % of the period, fast pull-down, ± `amp`.
fn sawtooth(t: f64, period: f64, amp: f64) -> f64 {
    let u = (t / period).rem_euclid(1.0);
    amp * if u < 0.8 {
        -1.0 + 2.0 * u / 0.8
    } else {
        1.0 - 2.0 * (u - 0.8) / 0.2
    }
}

/// The competitors the periodic line must beat (a step, the fit mode's
/// chiller drive) and the periodic scan itself; the other candidates are
/// left out to keep the debug-build test short.
fn opt() -> Options {
    Options {
        only: vec!["sensor_offset".into(), "coolant".into(), "periodic".into()],
        ..Options::default()
    }
}

fn both(m: &Machine, runs: &[(String, Run)]) -> [(&'static str, Diagnosis); 2] {
    [
        ("machine file", diagnose(m, runs, &opt()).unwrap()),
        ("fit", diagnose_fit(runs, &opt()).unwrap()),
    ]
}

#[test]
fn a_chiller_sawtooth_on_the_coolant_is_named_periodic_with_period_and_amplitude() {
    let (m, mut runs) = runs();
    let (period, amp) = (1500.0, 0.5);
    for (_, r) in runs.iter_mut() {
        add(r, "T_T9", &|t| sawtooth(t, period, amp));
    }
    for (mode, d) in both(&m, &runs) {
        let top = d
            .findings
            .first()
            .unwrap_or_else(|| panic!("{mode}: nothing named"));
        assert_eq!(top.name, "periodic", "{mode}: {:?}", d.findings);
        let p = top.params_json();
        assert_eq!(p["channel"], "T_T9", "{mode}: {p}");
        let got_period = p["period_s"].as_f64().unwrap();
        assert!(
            (got_period / period - 1.0).abs() <= 0.1,
            "{mode}: period {got_period}"
        );
        // with a machine file the residual carries the whole sawtooth; an
        // identified nominal absorbs part of it (its amplitude is what the
        // nominal leaves: checked as a lower bound there)
        let got_amp = p["amplitude_c"].as_f64().unwrap();
        if mode == "machine file" {
            assert!(
                (got_amp / amp - 1.0).abs() <= 0.25,
                "{mode}: amplitude {got_amp}"
            );
        } else {
            assert!(
                got_amp > 0.5 * amp && got_amp <= 1.25 * amp,
                "{mode}: amplitude {got_amp}"
            );
        }
        assert!(top.evidence["p_value_corrected"].as_f64().unwrap() < 1e-3);
        assert!(d.ranking_rule.contains("periodic"));
    }
}

#[test]
fn clean_runs_carry_no_periodic_claim() {
    let (m, runs) = runs();
    for (mode, d) in both(&m, &runs) {
        assert!(
            d.findings.iter().all(|f| f.name != "periodic"),
            "{mode}: {:?}",
            d.findings
        );
        // the scan ran and reported its strongest line (in `diagnose fit`
        // a line of the identified nominal's misfit can pass the spectral
        // test; the held-out gate keeps it unclaimed)
        let tried = d.tried.iter().find(|f| f.name == "periodic");
        let tried = tried.unwrap_or_else(|| panic!("{mode}: periodic scan not run"));
        assert!(tried.evidence["p_value_corrected"].is_number(), "{mode}");
    }
}

#[test]
fn a_single_sensor_step_is_still_a_step() {
    let (m, mut runs) = runs();
    add(&mut runs[1].1, "T_T3", &|t| {
        if t >= 9000.0 {
            0.8
        } else {
            0.0
        }
    });
    for (mode, d) in both(&m, &runs) {
        let top = d
            .findings
            .first()
            .unwrap_or_else(|| panic!("{mode}: nothing named"));
        assert_eq!(top.name, "sensor_offset", "{mode}: {:?}", d.findings);
        assert_eq!(top.params_json()["sensor"], "T_T3", "{mode}");
        assert!(
            d.findings.iter().all(|f| f.name != "periodic"),
            "{mode}: {:?}",
            d.findings
        );
    }
}

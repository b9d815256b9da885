//! Two fit-time choices on synthetic runs written from the physics:
//! - the output low-pass (`fit/output_lag.rs`): an error that follows a
//!   sensor through a 600 s first-order lag, fitted without input lags,
//!   gets a low-pass within a factor of two of 600 s; an undelayed error
//!   gets none;
//! - the envelope policy (`fit/envelope.rs`): a linear expansion whose
//!   sensor keeps warming past every earlier block's range is continued
//!   (`extrapolate`); an expansion that stops at a stop (the part sits on
//!   its locator) beyond the early range is held (`hold`).

use tcomp_data::runcsv::Run;
use tcomp_model::fit::pipeline::{fit_plan, FitConfig, Plan};

fn lagged(x: &[f64], tau: f64, dt: f64) -> Vec<f64> {
    if tau <= 0.0 {
        return x.to_vec();
    }
    let a = (-dt / tau).exp();
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            y = v + a * (y - v);
            y
        })
        .collect()
}

fn run(t: Vec<f64>, a: Vec<f64>, b: Vec<f64>, y: Vec<f64>) -> Run {
    let cols: Vec<(&str, Vec<f64>)> = vec![("time_s", t), ("T_a", a), ("T_b", b), ("dx_um", y)];
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.to_string()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

/// 40 h at 30 s: sensor `a` steps every 50–110 min, `b` drifts slowly;
/// the error is 4 µm/K of `a` lagged `tau` s.
fn stepping_run(tau: f64) -> Run {
    let dt = 30.0;
    let t: Vec<f64> = (0..4800).map(|k| k as f64 * dt).collect();
    let (mut level, mut next) = (0.0, 0.0);
    let a: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(k, &tk)| {
            if tk >= next {
                level = ((k as f64 * 0.618_033_988_7).fract() - 0.5) * 6.0;
                next = tk + 3000.0 + 3600.0 * ((k as f64 * 0.414_213_562).fract());
            }
            20.0 + level + 1.5 * (tk / 86_400.0 * std::f64::consts::TAU).sin()
        })
        .collect();
    let b = t
        .iter()
        .map(|tk| 21.0 + 0.8 * (tk / 30_000.0).sin())
        .collect();
    let la = lagged(&a, tau, dt);
    let y = la
        .iter()
        .zip(&t)
        .map(|(v, tk)| 4.0 * (v - la[0]) + 0.05 * (tk / 700.0).sin())
        .collect();
    run(t, a, b, y)
}

/// 30 h at 60 s: sensor `a` warms by 0.4 K/h with a ±1 K daily swing (every
/// later block reaches past the earlier ones); the error is 3 µm/K of `a`
/// up to `stop_k` above its start, flat beyond (`f64::INFINITY`: linear).
fn warming_run(stop_k: f64) -> Run {
    let dt = 60.0;
    let t: Vec<f64> = (0..1800).map(|k| k as f64 * dt).collect();
    let a: Vec<f64> = t
        .iter()
        .map(|tk| {
            20.0 + 0.4 * tk / 3600.0
                + (tk / 86_400.0 * std::f64::consts::TAU).sin()
                + 0.3 * (tk / 2_900.0).sin()
        })
        .collect();
    let b = t
        .iter()
        .map(|tk| 21.0 + 0.5 * (tk / 17_000.0).sin())
        .collect();
    let y = a
        .iter()
        .zip(&t)
        .map(|(v, tk)| 3.0 * (v - a[0]).min(stop_k) + 0.05 * (tk / 700.0).sin())
        .collect();
    run(t, a, b, y)
}

fn fit(r: Run) -> tcomp_model::fit::pipeline::FitReport {
    let plan = Plan::new(vec![r], vec!["synthetic".into()], 1, Some((0.7, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        lags: vec![0.0],
        max_inputs: 1,
        skip_net: true,
        fallbacks: false,
        sensors: Some(vec!["T_a".into(), "T_b".into()]),
        ..FitConfig::default()
    };
    fit_plan(&plan, &cfg).unwrap()
}

#[test]
fn a_delayed_response_gets_an_output_low_pass_near_its_delay() {
    let rep = fit(stepping_run(600.0));
    let tau = rep.model_file.output_lag_s.get("dx_um").copied();
    let note = rep.notes.iter().find(|n| n.contains("output low-pass"));
    assert!(
        matches!(tau, Some(t) if (300.0..=1200.0).contains(&t)),
        "{tau:?} {note:?}"
    );
}

#[test]
fn an_undelayed_response_gets_no_output_low_pass() {
    let rep = fit(stepping_run(0.0));
    assert!(
        rep.model_file.output_lag_s.is_empty(),
        "{:?} {:?}",
        rep.model_file.output_lag_s,
        rep.notes
    );
    assert!(rep
        .notes
        .iter()
        .any(|n| n.starts_with("dx_um: output low-pass none")));
}

#[test]
fn a_linear_expansion_beyond_the_range_is_continued_and_a_stop_is_held() {
    let lin = fit(warming_run(f64::INFINITY));
    let ev = &lin.model_file.envelope["dx_um"];
    assert_eq!(ev.policy, "extrapolate", "{}", ev.why());
    assert!(ev.extrapolate_mae_um.unwrap() < ev.hold_mae_um.unwrap());

    // The stop is reached inside the first block: every later fold sees
    // the error flat past its fit rows' range, and continuing overshoots.
    let stop = fit(warming_run(1.5));
    let ev = &stop.model_file.envelope["dx_um"];
    assert_eq!(ev.policy, "hold", "{}", ev.why());
    assert!(ev.extrapolate_mae_um.unwrap() > ev.hold_mae_um.unwrap());
    // Held for a stated reason: the folds' evidence, or the prior because
    // the stop moves the slope between folds (the stability guard) — not
    // the tie-break of a linear, stable model.
    let stable = stop.inputs[0].stability[&stop.chosen["dx_um"]].stable;
    assert!(ev.by_evidence || !stable, "{}", ev.why());
    assert!(!ev.why().contains("held across the folds"), "{}", ev.why());
}

#[test]
fn without_evidence_a_stable_linear_model_continues_by_the_prior() {
    // Sensor `a` swings inside the same range in every block: no fold row
    // leaves the earlier blocks' range, so the prior decides.
    let dt = 60.0;
    let t: Vec<f64> = (0..1800).map(|k| k as f64 * dt).collect();
    let a: Vec<f64> = t
        .iter()
        .map(|tk| 20.0 + 2.0 * (tk / 7_200.0 * std::f64::consts::TAU).sin())
        .collect();
    let b = t
        .iter()
        .map(|tk| 21.0 + 0.5 * (tk / 17_000.0).sin())
        .collect();
    let y = a.iter().map(|v| 3.0 * (v - a[0])).collect();
    let rep = fit(run(t, a, b, y));
    let ev = &rep.model_file.envelope["dx_um"];
    assert_eq!(ev.policy, "extrapolate", "{}", ev.why());
    assert!(!ev.by_evidence, "{}", ev.why());
    assert!(ev.why().contains("the prior"), "{}", ev.why());
}

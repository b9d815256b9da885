//! The lag per input chosen by forward-chaining CV (`fit/lags.rs`,
//! `FitConfig::lag_grid`): a synthetic run whose error follows one sensor
//! through a first-order lag gets that lag within one step of the geometric
//! grid (a factor of 2), from a greedy grid that does not hold it; an error
//! that follows the sensor without delay keeps lag 0 (no move); without a
//! grid the lags stay.

use tcomp_data::runcsv::Run;
use tcomp_model::fit::lags::LAG_GRID;
use tcomp_model::fit::pipeline::{fit_plan, FitConfig, Plan};

/// First-order response of `x` with time constant `tau` (s), rows `dt`
/// apart; `x` itself for `tau` 0.
fn lagged(x: &[f64], tau: f64, dt: f64) -> Vec<f64> {
    if tau <= 0.0 {
        return x.to_vec();
    }
    let a = (-dt / tau).exp();
    let mut out = Vec::with_capacity(x.len());
    let mut y = x[0];
    for &v in x {
        y = v + a * (y - v);
        out.push(y);
    }
    out
}

/// 40 h at 30 s: a sensor that moves over minutes to hours (steps every
/// 50–110 min and a slow daily swing), a second, unrelated sensor, and an
/// error that is 4 µm/K of the first sensor lagged `tau` s, plus a small
/// deterministic ripple.
fn lagged_run(tau: f64) -> Run {
    let dt = 30.0;
    let n = 4800;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let mut level = 0.0;
    let mut next = 0.0;
    let mut a = Vec::with_capacity(n);
    for (k, &tk) in t.iter().enumerate() {
        if tk >= next {
            // Pseudo-random steps of a few kelvin (deterministic).
            level = ((k as f64 * 0.618_033_988_7).fract() - 0.5) * 6.0;
            next = tk + 3000.0 + 3600.0 * ((k as f64 * 0.414_213_562).fract());
        }
        a.push(20.0 + level + 1.5 * (tk / 86_400.0 * std::f64::consts::TAU).sin());
    }
    let a = lagged(&a, 120.0, dt); // the sensor's own housing
    let b: Vec<f64> = t
        .iter()
        .map(|tk| 21.0 + 0.8 * (tk / 30_000.0).sin())
        .collect();
    let la = lagged(&a, tau, dt);
    let y: Vec<f64> = la
        .iter()
        .zip(&t)
        .map(|(v, tk)| 4.0 * (v - la[0]) + 0.05 * (tk / 700.0).sin())
        .collect();
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

fn fit(tau: f64, lag_grid: Vec<f64>) -> tcomp_model::fit::pipeline::FitReport {
    let plan = Plan::new(
        vec![lagged_run(tau)],
        vec!["lag".into()],
        1,
        Some((0.7, 1.0)),
    )
    .unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        // The greedy grid lacks the true lag: only the lag choice can find it.
        lags: vec![0.0, 7200.0],
        lag_grid,
        max_inputs: 1,
        skip_net: true,
        fallbacks: false,
        sensors: Some(vec!["T_a".into(), "T_b".into()]),
        ..FitConfig::default()
    };
    fit_plan(&plan, &cfg).unwrap()
}

/// The lag (s) of the channel's only input, from its feature name.
fn only_lag(rep: &tcomp_model::fit::pipeline::FitReport) -> (String, f64) {
    let f = &rep.inputs[0].features;
    assert_eq!(f.len(), 1, "{f:?}");
    let (name, lag) = match f[0].split_once('@') {
        Some((n, l)) => (n.to_string(), l.parse().unwrap()),
        None => (f[0].clone(), 0.0),
    };
    (name, lag)
}

#[test]
fn a_lagged_response_gets_its_lag_within_a_factor_of_two() {
    for tau in [900.0, 2400.0] {
        let rep = fit(tau, LAG_GRID.to_vec());
        let (name, lag) = only_lag(&rep);
        assert_eq!(name, "T_a", "{:?}", rep.inputs[0].features);
        assert!(
            lag >= tau / 2.0 && lag <= tau * 2.0,
            "tau {tau}: chose {lag} s ({:?})",
            rep.notes
        );
        assert!(
            rep.notes
                .iter()
                .any(|n| n.contains("input lags chosen by forward-chaining CV")),
            "{:?}",
            rep.notes
        );
    }
}

#[test]
fn without_a_grid_the_greedy_lags_stay() {
    let rep = fit(900.0, vec![]);
    let (_, lag) = only_lag(&rep);
    assert!(lag == 0.0 || lag == 7200.0, "{lag}");
    assert!(
        !rep.notes.iter().any(|n| n.contains("input lags chosen")),
        "{:?}",
        rep.notes
    );
}

#[test]
fn an_undelayed_response_gets_no_lag() {
    let rep = fit(0.0, LAG_GRID.to_vec());
    let (name, lag) = only_lag(&rep);
    assert_eq!(name, "T_a", "{:?}", rep.inputs[0].features);
    assert_eq!(lag, 0.0, "{:?}", rep.notes);
    assert!(
        !rep.notes.iter().any(|n| n.contains("input lags chosen")),
        "{:?}",
        rep.notes
    );
}

//! Model choice by blocked time cross-validation on the training rows:
//! it never reads the validation rows, the hybrid (lagged MLR + networks on
//! its residual) wins where a drift and a bounded nonlinearity add up, and
//! dropping a network candidate early never changes the choice.

use tcomp::fit::net::NetOpts;
use tcomp::fit::run::{fit_plan, FeatureChoice, FitConfig, FitReport, Plan};
use tcomp::fit::*;
use tcomp::runcsv::Run;

fn run_from(cols: Vec<(&str, Vec<f64>)>) -> Run {
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.to_string()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

/// First-order response (time constant `tau` s) of a sensor to `drive`.
fn respond(t: &[f64], drive: &[f64], tau: f64) -> Vec<f64> {
    let mut out = vec![drive[0]];
    for k in 1..t.len() {
        let prev = out[k - 1];
        out.push(drive[k] + (-(t[k] - t[k - 1]) / tau).exp() * (prev - drive[k]));
    }
    out
}

/// A spindle schedule of repeating speed steps; `T_a` drifts up by `drift`
/// °C over the run (ambient) plus a wiggle, `T_b` follows the spindle
/// (bounded, every regime in every time block). `dx_um` = 3·rise(T_a) +
/// 20·tanh((rise(T_b) − 3)/1.5), or 3·rise(T_a) − 2·rise(T_b) when
/// `nonlinear` is false, plus ±0.3 µm of probe noise.
fn drift_and_cycles(nonlinear: bool, drift: f64) -> Run {
    let n = 3000;
    let dt = 20.0;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let rpm: Vec<f64> = (0..n)
        .map(|k| [3000.0, 0.0, 6000.0, 1500.0][(k / 120) % 4])
        .collect();
    let drive_b: Vec<f64> = rpm.iter().map(|s| 20.0 + s / 800.0).collect();
    let tb = respond(&t, &drive_b, 1200.0);
    let ta: Vec<f64> = t
        .iter()
        .map(|s| {
            if drift > 0.0 {
                20.0 + drift * s / t[n - 1] + 0.2 * (s / 3000.0).sin()
            } else {
                // Fast enough that every time block spans its whole range.
                20.0 + (s / 600.0).sin()
            }
        })
        .collect();
    // The board's 1/16 °C reading (the DS18B20 LSB).
    let q = |t: f64| (t * 16.0).round() / 16.0;
    let y: Vec<f64> = ta
        .iter()
        .zip(&tb)
        .map(|(a, b)| {
            let (ra, rb) = (q(*a) - q(ta[0]), q(*b) - q(tb[0]));
            if nonlinear {
                3.0 * ra + 20.0 * ((rb - 3.0) / 1.5).tanh()
            } else {
                3.0 * ra - 2.0 * rb
            }
        })
        .enumerate()
        // Probe noise, ±0.3 µm, pseudo-random in the row (no input explains it).
        .map(|(k, v)| v + 0.3 * (((k * 7919) % 101) as f64 / 50.0 - 1.0))
        .collect();
    run_from(vec![
        ("time_s", t),
        ("spindle_rpm", rpm),
        ("T_a", ta),
        ("T_b", tb),
        ("dx_um", y),
    ])
}

fn quick_net() -> NetOpts {
    NetOpts {
        hidden: 4,
        population: 12,
        generations: 8,
        lm_iters: 60,
        ensemble: 2,
        ..NetOpts::default()
    }
}

fn inputs() -> FeatureChoice {
    FeatureChoice::List(vec![
        (FeatureKind::SensorRise("T_a".into()), None),
        (FeatureKind::SensorRise("T_b".into()), None),
    ])
}

/// Fit on one worker thread: the parallel sums then add in a fixed order,
/// so two fits on the same training rows agree bit for bit.
fn fit_1thread(plan: &Plan, cfg: &FitConfig) -> FitReport {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| fit_plan(plan, cfg).unwrap())
}

#[test]
fn the_choice_never_reads_the_validation_rows() {
    let a = drift_and_cycles(true, 8.0);
    // Same training rows (the first 60 %), everything after them replaced:
    // other temperatures and a target of the opposite sign.
    let mut b = a.clone();
    let n = b.rows();
    let cut = (0.6 * n as f64).floor() as usize;
    for name in ["T_a", "T_b", "dx_um"] {
        let c = b.col_index(name).unwrap();
        for r in cut..n {
            let v = b.data[c][r].unwrap();
            b.data[c][r] = Some(if name == "dx_um" {
                -3.0 * v + 40.0
            } else {
                v + 5.0 + (r as f64 * 0.37).sin()
            });
        }
    }
    let cfg = FitConfig {
        split_chrono: Some((0.6, 0.8)),
        features: inputs(),
        net: quick_net(),
        hybrid: true,
        ..FitConfig::default()
    };
    let fit = |run: Run| {
        let plan = Plan::new(vec![run], vec!["r".into()], 1, Some((0.6, 0.8))).unwrap();
        fit_1thread(&plan, &cfg)
    };
    let (ra, rb) = (fit(a), fit(b));
    // The validation figures differ (the rows differ) ...
    let val = |r: &FitReport| r.models.iter().find(|m| m.name == "mlr").unwrap().channels["dx_um"];
    assert!(
        (val(&ra).rms_um - val(&rb).rms_um).abs() > 1.0,
        "{:?} {:?}",
        val(&ra),
        val(&rb)
    );
    // ... but every cross-validation figure, the choice and every fitted
    // parameter are the same to the bit.
    for (ia, ib) in ra.inputs.iter().zip(&rb.inputs) {
        assert_eq!(ia.cv.len(), ib.cv.len());
        for (name, s) in &ia.cv {
            let t = &ib.cv[name];
            assert_eq!(s.rms_um.to_bits(), t.rms_um.to_bits(), "{name}");
            assert_eq!(s.fold_rms_um, t.fold_rms_um, "{name}");
        }
    }
    assert_eq!(ra.chosen, rb.chosen);
    assert_eq!(ra.model_file, rb.model_file);
    assert!(!ra.model_file.nets.is_empty() && !ra.model_file.hybrid_nets.is_empty());
}

#[test]
fn the_hybrid_wins_where_a_drift_and_a_bounded_nonlinearity_add_up() {
    let run = drift_and_cycles(true, 8.0);
    let plan = Plan::new(vec![run], vec!["syn".into()], 1, Some((0.7, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        features: inputs(),
        net: quick_net(),
        hybrid: true,
        cv_drop: false,
        ..FitConfig::default()
    };
    let rep = fit_plan(&plan, &cfg).unwrap();
    let cv = &rep.inputs[0].cv;
    let rms = |n: &str| cv[n].rms_um;
    // The MLR cannot bend to the tanh; the hybrid keeps the MLR's linear
    // part (the drift) and bends on T_b, closer than the free network.
    assert!(rms("hybrid") < 0.6 * rms("mlr"), "{cv:?}");
    assert!(rms("hybrid") < rms("ga-bpn"), "{cv:?}");
    assert_eq!(rep.chosen["dx_um"], "hybrid", "{cv:?}");
    // On the later, unseen 30 % the hybrid also beats the lagged MLR.
    let val = |n: &str| rep.models.iter().find(|m| m.name == n).unwrap().channels["dx_um"].rms_um;
    assert!(
        val("hybrid") < val("mlr"),
        "{} vs {}",
        val("hybrid"),
        val("mlr")
    );
    // It ships as the MLR's table plus the residual networks, summed on the
    // board: the exported float model predicts what was validated.
    let columns = vec!["T_a".to_string(), "T_b".to_string()];
    let fm = tcomp::export::float_model_from_fit(
        &rep.model_file,
        &columns,
        &tcomp::export::ExportOptions::default(),
    )
    .unwrap();
    assert_eq!(fm.tables.len(), 1);
    assert_eq!(fm.nets.len(), quick_net().ensemble);
    assert!(fm
        .nets
        .iter()
        .all(|n| n.direction == fm.tables[0].direction));
}

#[test]
fn dropping_a_network_that_cannot_win_keeps_the_choice() {
    // A target linear in two inputs whose ranges every time block covers:
    // the MLR is exact up to the probe noise; a one-unit network barely
    // trained cannot follow two directions, so it cannot win.
    let run = drift_and_cycles(false, 0.0);
    let plan = Plan::new(vec![run], vec!["lin".into()], 1, Some((0.7, 1.0))).unwrap();
    let base = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        features: inputs(),
        net: NetOpts {
            hidden: 1,
            population: 4,
            generations: 1,
            lm_iters: 2,
            ..quick_net()
        },
        hybrid: true,
        ..FitConfig::default()
    };
    let full = fit_1thread(
        &plan,
        &FitConfig {
            cv_drop: false,
            ..base.clone()
        },
    );
    let fast = fit_1thread(&plan, &base);
    assert_eq!(full.chosen, fast.chosen);
    assert_eq!(full.chosen["dx_um"], "mlr");
    let (cf, cd) = (&full.inputs[0].cv, &fast.inputs[0].cv);
    let mut dropped = 0;
    for name in ["hybrid", "ga-bpn"] {
        assert_eq!(cf[name].fold_rms_um.len(), 5, "{cf:?}");
        assert!(!cf[name].dropped);
        if cd[name].dropped {
            dropped += 1;
            // Stopped early, on the latest folds: those figures are the
            // full run's last ones.
            let k = cd[name].fold_rms_um.len();
            assert!(k < 5);
            assert_eq!(cd[name].fold_rms_um[..], cf[name].fold_rms_um[5 - k..]);
        }
    }
    assert!(dropped > 0, "{cd:?}");
    // The linear figures do not depend on it.
    assert_eq!(cf["mlr"].rms_um.to_bits(), cd["mlr"].rms_um.to_bits());
}

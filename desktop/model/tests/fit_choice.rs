//! Model choice by blocked time cross-validation on the training rows:
//! it never reads the validation rows, the hybrid (lagged MLR + networks on
//! its residual) wins where a drift and a bounded nonlinearity add up,
//! dropping a network candidate early never changes the choice, the blend's
//! weight comes from the out-of-fold predictions (and its export replays on
//! the board's fixed point as validated), and a network that fails the
//! latest block is not admissible.

use tcomp_data::runcsv::Run;
use tcomp_model::fit::net::NetOpts;
use tcomp_model::fit::pipeline::{
    choose_model, fit_plan, FeatureChoice, FitConfig, FitReport, Plan,
};
use tcomp_model::fit::*;

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
        blend: true,
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
    assert!(ra.model_file.blend.contains_key("dx_um"));
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
    let fm = tcomp_model::export::float_model_from_fit(
        &rep.model_file,
        &columns,
        &tcomp_model::export::ExportOptions::default(),
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

#[test]
fn the_blend_weight_is_the_least_squares_mixture() {
    let a: Vec<f64> = (0..200).map(|k| (k as f64 * 0.37).sin() * 5.0).collect();
    let b: Vec<f64> = (0..200)
        .map(|k| (k as f64 * 0.11).cos() * 3.0 + 1.0)
        .collect();
    let w_of = |y: &[f64]| blend_weight(y.iter().zip(&a).zip(&b).map(|((y, a), b)| (y, a, b)));
    let mix = |w: f64| -> Vec<f64> {
        a.iter()
            .zip(&b)
            .map(|(a, b)| w * a + (1.0 - w) * b)
            .collect()
    };
    assert!((w_of(&mix(0.3)) - 0.3).abs() < 1e-12);
    assert!((w_of(&mix(0.85)) - 0.85).abs() < 1e-12);
    assert_eq!(w_of(&a), 1.0);
    assert_eq!(w_of(&b), 0.0);
    // Outside [0, 1] it is clamped (the board's table and networks are
    // never extrapolated past either model).
    assert_eq!(w_of(&mix(1.7)), 1.0);
    assert_eq!(w_of(&mix(-0.4)), 0.0);
    // Noise that neither model explains does not move it far.
    let noisy: Vec<f64> = mix(0.6)
        .iter()
        .enumerate()
        .map(|(k, v)| v + 0.2 * (((k * 7919) % 101) as f64 / 50.0 - 1.0))
        .collect();
    assert!((w_of(&noisy) - 0.6).abs() < 0.02, "{}", w_of(&noisy));
    // Two models that never differ: all weight on the first (the table).
    let same = blend_weight(a.iter().zip(&a).zip(&a).map(|((y, a), b)| (y, a, b)));
    assert_eq!(same, 1.0);
}

fn blend_fit(nonlinear: bool) -> (Run, FitReport) {
    let run = drift_and_cycles(nonlinear, 0.0);
    let plan = Plan::new(vec![run.clone()], vec!["syn".into()], 1, Some((0.7, 1.0))).unwrap();
    let cfg = FitConfig {
        split_chrono: Some((0.7, 1.0)),
        features: inputs(),
        net: quick_net(),
        blend: true,
        ..FitConfig::default()
    };
    (run, fit_1thread(&plan, &cfg))
}

#[test]
fn the_blend_leans_on_the_model_the_folds_favour() {
    // Every regime in every time block. A bounded nonlinearity (tanh of
    // T_b): the network follows it, the MLR cannot, so the out-of-fold
    // weight leans on the network and the nested blend beats the MLR.
    let (_, rep) = blend_fit(true);
    let cv = &rep.inputs[0].cv;
    let w = cv["blend"].weight.unwrap();
    assert!(cv["ga-bpn"].rms_um < cv["mlr"].rms_um, "{cv:?}");
    assert!(w < 0.5, "{cv:?}");
    assert_eq!(cv["blend"].fold_rms_um.len(), 5);
    assert_eq!(cv["ga-bpn"].fold_rms_um.len(), 5);
    assert!(!cv["ga-bpn"].dropped);
    assert!(cv["blend"].rms_um < cv["mlr"].rms_um, "{cv:?}");
    assert_eq!(rep.model_file.blend["dx_um"], w);
    // A linear target: the MLR is exact up to the probe noise, the weight
    // leans on it.
    let (_, lin) = blend_fit(false);
    let cv = &lin.inputs[0].cv;
    assert!(cv["blend"].weight.unwrap() > 0.5, "{cv:?}");
    assert_eq!(lin.chosen["dx_um"], "mlr", "{cv:?}");
}

#[test]
fn an_exported_blend_replays_on_the_board_as_validated() {
    let (run, rep) = blend_fit(true);
    let mut file = rep.model_file.clone();
    // A weight well inside (0, 1), so both the table and the networks count.
    file.blend.insert("dx_um".into(), 0.4);
    let opts = tcomp_model::export::ExportOptions {
        choices: tcomp_model::export::parse_choices("dx_um=blend").unwrap(),
        ..tcomp_model::export::ExportOptions::default()
    };
    let columns = vec!["T_a".to_string(), "T_b".to_string()];
    let float = tcomp_model::export::float_model_from_fit(&file, &columns, &opts).unwrap();
    // One direction: the MLR's table (terms × 0.4) and the networks
    // (output layers × 0.6 / k), which the board sums.
    assert_eq!(float.tables.len(), 1);
    assert_eq!(float.nets.len(), quick_net().ensemble);
    let plain = tcomp_model::export::float_model_from_fit(
        &file,
        &columns,
        &tcomp_model::export::ExportOptions {
            choices: tcomp_model::export::parse_choices("dx_um=mlr").unwrap(),
            ..tcomp_model::export::ExportOptions::default()
        },
    )
    .unwrap();
    for (t, p) in float.tables[0].terms.iter().zip(&plain.tables[0].terms) {
        assert!((t.coef_um - 0.4 * p.coef_um).abs() <= 1e-12 * p.coef_um.abs().max(1.0));
    }
    let (model, _) = float.quantize().unwrap();
    let mut csv = Vec::new();
    run.write_to(&mut csv).unwrap();
    let csv = String::from_utf8(csv).unwrap();
    let rows = tcomp_model::replay::replay(&csv, model).unwrap();
    let blend = Blend::of(&file, "dx_um").unwrap();
    assert_eq!(blend.w, 0.4);
    // The fit's own rows and features; the board's prediction per row.
    let plan = Plan::new(vec![run], vec!["syn".into()], 1, Some((0.7, 1.0))).unwrap();
    let kinds: Vec<_> = blend
        .features()
        .iter()
        .map(|f| (f.kind.clone(), f.tau_s))
        .collect();
    let cache = SeriesCache::new(&plan.runs, kinds).unwrap();
    let idx: Vec<usize> = (0..blend.features().len()).collect();
    let mut worst = 0.0f64;
    let mut n = 0;
    for segs in [&plan.train, &plan.val] {
        let s = cache.samples(&plan.runs, segs, &idx, "dx_um").unwrap();
        for (x, &(_, r)) in s.x.iter().zip(&s.rows) {
            let out = rows[r].out;
            assert!(out.status & thermocomp_core::compensator::status::VALID != 0);
            let board = f64::from(out.predicted[0]) / 10.0;
            worst = worst.max((board - blend.predict_raw(x)).abs());
            n += 1;
        }
    }
    assert!(n > 2500, "{n}");
    // 0.05 µm: the board rounds to 0.1 µm; the rest is the Q8/Q24/Q16
    // quantisation of the weights and the sigmoid table (≤ 0.02 µm here).
    eprintln!("blend: worst |board − fit| {worst:.4} µm over {n} rows");
    assert!(worst <= 0.07, "worst |board − fit| {worst:.4} µm");
}

#[test]
fn a_network_that_fails_the_latest_block_is_not_admissible() {
    use std::collections::BTreeMap;
    use tcomp_model::fit::pipeline::{latest_block_rule, CvScore};
    let sc = |folds: &[f64]| {
        let rms = (folds.iter().map(|f| f * f).sum::<f64>() / folds.len() as f64).sqrt();
        CvScore {
            rms_um: rms,
            fold_rms_um: folds.to_vec(),
            ..CvScore::default()
        }
    };
    let mut cv: BTreeMap<String, CvScore> = BTreeMap::new();
    cv.insert("mlr-static".into(), sc(&[3.0, 3.0, 3.0, 3.0, 9.0]));
    cv.insert("mlr".into(), sc(&[4.0, 4.0, 4.0, 4.0, 4.0]));
    // Better pooled, much worse on the latest block: out.
    cv.insert("ga-bpn".into(), sc(&[1.0, 1.0, 1.0, 1.0, 6.0]));
    // Within the margin on the latest block: stays.
    cv.insert("blend".into(), sc(&[2.0, 2.0, 2.0, 2.0, 4.05]));
    let out = latest_block_rule(&mut cv, 0.02);
    assert_eq!(out, vec![("ga-bpn".to_string(), 6.0, 4.0)]);
    assert!(cv.contains_key("blend") && !cv.contains_key("ga-bpn"));
    assert_eq!(choose_model(&cv, 0.02).as_deref(), Some("blend"));
    // A hair over the margin is out too.
    cv.insert("blend".into(), sc(&[2.0, 2.0, 2.0, 2.0, 4.09]));
    assert_eq!(latest_block_rule(&mut cv, 0.02).len(), 1);
    assert_eq!(choose_model(&cv, 0.02).as_deref(), Some("mlr"));
}

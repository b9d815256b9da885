//! The ridge on all inputs (`ridge-all`, issue 50) as a candidate of the
//! automatic choice: where the error is spread over many collinear
//! sensors, more than the forward selection's few inputs can carry, it wins
//! the training CV and is chosen (and ships); where two sensors carry
//! everything it does not displace the MLR by more than noise; beyond the
//! board's inputs it reads the subset the forward-chaining CV keeps, and
//! says so.

use tcomp_data::runcsv::Run;
use tcomp_model::export::{float_model_from_fit, ExportOptions};
use tcomp_model::fit::pipeline::{fit_runs, FitConfig, FitReport, Silent};
use thermocomp_core::float::FloatModel;
use thermocomp_core::limits::MAX_INPUTS;

fn run_from(cols: Vec<(String, Vec<f64>)>) -> Run {
    Run {
        meta: vec![],
        columns: cols.iter().map(|c| c.0.clone()).collect(),
        data: cols
            .into_iter()
            .map(|c| c.1.into_iter().map(Some).collect())
            .collect(),
    }
}

/// `k` sensors over 3,000 rows of 20 s: a common slow warm-up (5 °C) plus
/// each sensor's own oscillation (0.6 °C, its own period between 25 and
/// 80 min, every time block spans several), so the sensors are strongly
/// collinear but each carries something of its own. `dx_um` =
/// Σ `weights[i]`·rise(T_i) plus ±0.3 µm of probe noise.
fn collinear_run(k: usize, weights: &[f64]) -> Run {
    let n = 3000;
    let t: Vec<f64> = (0..n).map(|r| r as f64 * 20.0).collect();
    let q = |v: f64| (v * 16.0).round() / 16.0;
    let common: Vec<f64> = t
        .iter()
        .map(|s| 5.0 * (1.0 - (-s / 20_000.0).exp()))
        .collect();
    let sensors: Vec<Vec<f64>> = (0..k)
        .map(|i| {
            let period = 1500.0 + 330.0 * i as f64;
            let phase = 0.7 * i as f64;
            t.iter()
                .zip(&common)
                .map(|(s, c)| 20.0 + c + 0.6 * (s / period * std::f64::consts::TAU + phase).sin())
                .collect()
        })
        .collect();
    let y: Vec<f64> = (0..n)
        .map(|r| {
            let s: f64 = sensors
                .iter()
                .zip(weights)
                .map(|(x, w)| w * (q(x[r]) - q(x[0])))
                .sum();
            s + 0.3 * (((r * 7919) % 101) as f64 / 50.0 - 1.0)
        })
        .collect();
    let mut cols = vec![("time_s".to_string(), t)];
    for (i, s) in sensors.into_iter().enumerate() {
        cols.push((format!("T_{i:02}"), s));
    }
    cols.push(("dx_um".to_string(), y));
    run_from(cols)
}

/// `tcomp fit`'s defaults (no network, no fallbacks: the linear choice is
/// under test), trained on the first 60 %, validated on the rest.
fn fit(run: &Run) -> FitReport {
    let cfg = FitConfig {
        split_chrono: Some((0.6, 1.0)),
        skip_net: true,
        fallbacks: false,
        ..FitConfig::default()
    };
    fit_runs(vec![("run".into(), run.clone())], 1, &cfg, &Silent).unwrap()
}

/// What `export` puts on the board by default (the fit's choice).
fn board_model(r: &FitReport, run: &Run) -> FloatModel {
    let columns: Vec<String> = run
        .temperature_columns()
        .iter()
        .map(|c| c.to_string())
        .collect();
    float_model_from_fit(&r.model_file, &columns, &ExportOptions::default()).unwrap()
}

fn val_mae(r: &FitReport, model: &str) -> f64 {
    r.models
        .iter()
        .find(|m| m.name == model)
        .and_then(|m| m.channels.get("dx_um"))
        .map(|m| m.mae_um)
        .unwrap_or_else(|| panic!("no {model} figures"))
}

fn cv_rms(r: &FitReport, model: &str) -> f64 {
    r.inputs[0].cv[model].rms_um
}

#[test]
fn many_collinear_sensors_choose_the_ridge_on_all_inputs_and_it_ships() {
    // Ten sensors, each weighing in: the forward selection's five inputs
    // (of five selected sensors) cannot carry the other five's own parts.
    let run = collinear_run(10, &[1.0; 10]);
    let r = fit(&run);
    let chosen = r.chosen["dx_um"].as_str();
    let info = r.inputs[0].ridge_all.as_ref().expect("ridge-all offered");
    assert_eq!(info.inputs.len(), 10, "{info:?}");
    assert!(info.dropped.is_empty());
    let best_other = ["mlr", "mlr-static", "ridge"]
        .iter()
        .filter(|m| r.inputs[0].cv.contains_key(**m))
        .map(|m| cv_rms(&r, m))
        .fold(f64::INFINITY, f64::min);
    assert!(
        cv_rms(&r, "ridge-all") < best_other / 1.02,
        "ridge-all CV {} against {best_other}",
        cv_rms(&r, "ridge-all")
    );
    assert_eq!(chosen, "ridge-all", "{:?}", r.notes);
    // The choice holds on the rows it never saw.
    assert!(val_mae(&r, "ridge-all") < val_mae(&r, "mlr"));
    // It ships: one linear table of its ten inputs, within the board's.
    let m = board_model(&r, &run);
    assert_eq!(m.tables.len(), 1);
    assert_eq!(m.tables[0].terms.len(), 11);
    assert!(m.inputs.len() <= MAX_INPUTS);
    assert!(m.nets.is_empty());
    let (_, q) = m.quantize().unwrap();
    assert!(q.max_deviation_um.iter().all(|d| *d <= 0.1), "{q:?}");
}

#[test]
fn two_sensors_carrying_everything_keep_the_mlr() {
    // Only T_00 and T_05 matter; the other eight are collinear passengers.
    let mut w = [0.0; 10];
    w[0] = 3.0;
    w[5] = -2.0;
    let run = collinear_run(10, &w);
    let r = fit(&run);
    let chosen = r.chosen["dx_um"].as_str();
    assert!(r.inputs[0].cv.contains_key("ridge-all"));
    // Not displaced: the simpler model is chosen, or ridge-all only by more
    // than noise on the rows it never saw.
    if chosen == "ridge-all" {
        assert!(val_mae(&r, "ridge-all") <= val_mae(&r, "mlr") * 1.02);
    } else {
        assert!(["mlr", "mlr-static", "ridge"].contains(&chosen), "{chosen}");
    }
    assert!(val_mae(&r, chosen) <= val_mae(&r, "ridge-all") * 1.05);
}

#[test]
fn beyond_the_boards_inputs_it_reads_the_subset_the_cv_keeps_and_says_so() {
    let k = MAX_INPUTS + 3;
    let run = collinear_run(k, &vec![1.0; k]);
    let r = fit(&run);
    let info = r.inputs[0].ridge_all.as_ref().expect("ridge-all offered");
    assert_eq!(info.candidates, k);
    assert_eq!(info.inputs.len(), MAX_INPUTS);
    assert_eq!(info.dropped.len(), 3);
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("ridge-all") && n.contains(&info.dropped[0])),
        "{:?}",
        r.notes
    );
    if r.chosen["dx_um"] == "ridge-all" {
        let m = board_model(&r, &run);
        assert!(m.inputs.len() <= MAX_INPUTS);
        m.quantize().unwrap();
    }
}

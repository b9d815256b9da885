//! The output low-pass on the desktop side (issue 51 item 1): a fit file's
//! `output_lag_s` → `export` writes section kind 6 (format v5) → `replay`
//! (the core's compensator) serves the low-passed prediction and names the
//! time constant; without it the image and the replay are as before.

use tcomp_model::export::output_filter::{decay_q30, tau_s};
use tcomp_model::fit::{FeatureKind, FeatureSpec, MlrParams, ModelFile};
use tcomp_model::replay::{replay, residuals, ReplayRow};

const TAU_S: f64 = 600.0;

/// dx = 100 µm per unit of T_a's normalised rise (trained over 0 … 5 °C),
/// with the fit's output low-pass on dx when `lag` is given.
fn fit_file(lag: Option<f64>) -> ModelFile {
    let mut file = ModelFile {
        mlr: vec![MlrParams {
            features: vec![FeatureSpec {
                kind: FeatureKind::SensorRise("T_a".into()),
                tau_s: None,
                min: 0.0,
                max: 5.0,
            }],
            c0: 0.0,
            coef: vec![100.0],
            channel: "dx_um".into(),
        }],
        ..Default::default()
    };
    if let Some(t) = lag {
        file.output_lag_s.insert("dx_um".into(), t);
    }
    file
}

/// Export `file` as `tcomp export` does (envelope and output sections from
/// the file) and return the image's bytes and the report lines.
fn export(file: &ModelFile, name: &str, dir: &std::path::Path) -> (Vec<u8>, Vec<String>) {
    let opts = tcomp_model::export::ExportOptions {
        max_rate_um_per_s: 1000.0,
        ..Default::default()
    };
    let float =
        tcomp_model::export::float_model_from_fit(file, &["T_a".to_string()], &opts).unwrap();
    let (envelope, _) = tcomp_model::export::policies(file, &float);
    let (output, lines) = tcomp_model::export::decays(file, &float);
    let path = dir.join(name);
    tcomp_model::export::export_sections(&float, (None, None), (envelope, output), &path, None)
        .unwrap();
    (std::fs::read(&path).unwrap(), lines)
}

/// 20 °C for a minute, then 24 °C (a step inside the envelope), a row
/// every 15 s for two hours; dx measured 0.
fn trace() -> String {
    let mut csv = String::from("time_s,spindle_rpm,T_a,dx_um\n");
    for i in 0..480u32 {
        let t = if i < 4 { 20.0 } else { 24.0 };
        csv += &format!("{},0,{t:.4},0\n", i * 15);
    }
    csv
}

fn version(b: &[u8]) -> u16 {
    u16::from_le_bytes([b[4], b[5]])
}

#[test]
fn decay_and_time_constant_convert_both_ways() {
    let d = decay_q30(1000, TAU_S).unwrap();
    assert_eq!(
        d,
        ((-1.0f64 / TAU_S).exp() * 1_073_741_824.0).round() as u32
    );
    assert!((tau_s(1000, d).unwrap() - TAU_S).abs() < 1e-3);
    assert_eq!(tau_s(1000, 0), None);
    assert_eq!(decay_q30(1000, 0.0), None);
    assert_eq!(decay_q30(1000, -5.0), None);
    assert_eq!(decay_q30(1000, f64::NAN), None);
    // A τ so long its decay rounds to 2^30 is kept below it (the parser's bound).
    assert_eq!(decay_q30(1000, 1e12), Some((1 << 30) - 1));
}

#[test]
fn a_fit_files_output_lag_is_exported_and_replay_serves_the_low_passed_output() {
    let dir = tempfile::tempdir().unwrap();
    let (filtered, lines) = export(&fit_file(Some(TAU_S)), "f.img", dir.path());
    let (plain, plain_lines) = export(&fit_file(None), "p.img", dir.path());
    assert_eq!(lines, vec!["output low-pass dx_um: 600 s".to_string()]);
    assert_eq!(plain_lines, vec!["output low-pass dx_um: none".to_string()]);
    assert_eq!(version(&filtered), 5);
    assert!(version(&plain) < 5);
    let fm = thermocomp_core::Model::parse(&filtered).unwrap();
    let pm = thermocomp_core::Model::parse(&plain).unwrap();
    let d = decay_q30(fm.step_ms, TAU_S).unwrap();
    assert_eq!(fm.output_decay_q30.unwrap()[0], d);
    assert_eq!(pm.output_decay_q30, None);

    let csv = trace();
    let rows_f = replay(&csv, fm.clone()).unwrap();
    let rows_p = replay(&csv, pm).unwrap();
    // The plain prediction u per row; the filtered one follows
    // y ← u + dⁿ (y − u) over each row's 15 whole steps, from y = u.
    let df = f64::from(d) / f64::from(1u32 << 30);
    let mut y = f64::from(rows_p[0].out.predicted[0]);
    let mut lagging = 0;
    for (i, (f, p)) in rows_f.iter().zip(&rows_p).enumerate() {
        let u = f64::from(p.out.predicted[0]);
        if i > 0 {
            y = u + df.powi(15) * (y - u);
        }
        let got = f64::from(f.out.predicted[0]);
        assert!((got - y).abs() <= 1.0, "row {i}: {got} vs {y:.2}");
        if i > 0 {
            // (Row 0's served value ramps from 0, as every first one does.)
            assert_eq!(f.out.corrections[0], f.out.predicted[0], "row {i}");
        }
        lagging += usize::from(f.out.predicted[0] != p.out.predicted[0]);
    }
    // The step (0 → 4 °C of a 0 … 5 °C range at 100 µm per unit: −100 →
    // +60 µm) is 1 − 1/e of the way a τ after it.
    let (u_end, at_tau) = (
        rows_p[479].out.predicted[0],
        rows_f[4 + 40].out.predicted[0],
    );
    let start = rows_p[0].out.predicted[0];
    assert_eq!((start, u_end), (-1000, 600));
    let share = f64::from(at_tau - start) / f64::from(u_end - start);
    assert!((share - (1.0 - (-1.0f64).exp())).abs() < 0.02, "{share}");
    assert!(lagging > 100, "{lagging}");

    let run = tcomp_data::runcsv::Run::from_reader(csv.as_bytes()).unwrap();
    let res = residuals(&run, &rows_f, &fm, 0, rows_f.len());
    assert!((res[0].output_lag_s.unwrap() - TAU_S).abs() < 0.01);
    let json = serde_json::to_value(&res[0]).unwrap();
    assert!((json["output_lag_s"].as_f64().unwrap() - TAU_S).abs() < 0.01);
}

#[test]
fn without_output_lag_the_image_and_the_replay_are_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let (now, _) = export(&fit_file(None), "now.img", dir.path());
    // The export path before the output filter existed.
    let opts = tcomp_model::export::ExportOptions {
        max_rate_um_per_s: 1000.0,
        ..Default::default()
    };
    let file = fit_file(None);
    let float =
        tcomp_model::export::float_model_from_fit(&file, &["T_a".to_string()], &opts).unwrap();
    let before = dir.path().join("before.img");
    tcomp_model::export::export_enveloped(
        &float,
        (None, None),
        tcomp_model::export::policies(&file, &float).0,
        &before,
        None,
    )
    .unwrap();
    assert_eq!(now, std::fs::read(&before).unwrap());
    // A channel the fit gave no lag (another channel's entry) is not filtered either.
    let mut other = fit_file(None);
    other.output_lag_s.insert("dy_um".into(), TAU_S);
    let (other_img, _) = export(&other, "other.img", dir.path());
    assert_eq!(other_img, now);
    let csv = trace();
    let m = thermocomp_core::Model::parse(&now).unwrap();
    let rows: Vec<ReplayRow> = replay(&csv, m.clone()).unwrap();
    let run = tcomp_data::runcsv::Run::from_reader(csv.as_bytes()).unwrap();
    assert_eq!(
        residuals(&run, &rows, &m, 0, rows.len())[0].output_lag_s,
        None
    );
}

//! `bench-extrapolation` on one tiny simulated case (a coarse run, a tiny
//! network budget, no real run): the JSON carries every model per case and
//! every figure is finite.

use std::process::Command;

#[test]
fn one_tiny_case_reports_every_model_with_finite_figures() {
    let out = Command::new(env!("CARGO_BIN_EXE_bench-extrapolation"))
        .args([
            "--json",
            "--no-real",
            "--scenarios",
            "speed",
            "--seeds",
            "1",
            "--sample-period",
            "300",
            "--ensemble",
            "1",
            "--population",
            "4",
            "--generations",
            "2",
            "--lm-iters",
            "5",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let cases = v["cases"].as_array().unwrap();
    // The turning centre has two directions: one case each.
    assert_eq!(cases.len(), 2, "{v}");
    assert_eq!(v["headline"]["cases"], 2);
    assert_eq!(v["network_budget"]["tcomp_fit_default"], false);
    for c in cases {
        for m in [
            "default",
            "default_float",
            "default_rezero",
            "ridge",
            "ridge_all",
            "mlr",
            "ga_bpn",
            "raw_rezero",
        ] {
            for k in ["mae_um", "rms_um"] {
                let x = c["models"][m][k].as_f64();
                assert!(
                    x.is_some_and(|x| x.is_finite() && x >= 0.0),
                    "{} {m} {k}: {x:?}",
                    c["case"]
                );
            }
        }
        assert!(c["models"]["ridge"]["penalty"].as_f64().is_some(), "{c}");
        for k in ["default_inputs", "all_inputs"] {
            let p = c["outside_envelope_pct"][k].as_f64().unwrap();
            assert!((0.0..=100.0).contains(&p), "{k}: {p}");
        }
        // A spindle speed above every training speed leaves the envelope.
        assert!(c["outside_envelope_pct"]["all_inputs"].as_f64().unwrap() > 0.0);
        assert!(c["default_worse_than_raw_rezero"]["mae"].is_boolean());
        assert!(c["served_rows"].as_u64().unwrap() > 0);
        // A re-zero at each steady block: counts within the blocks, figures finite.
        let p = &c["rezero_promise"];
        let blocks = p["steady_blocks"].as_array().unwrap();
        assert_eq!(p["blocks"].as_u64(), Some(blocks.len() as u64), "{p}");
        assert!(
            p["worse_mae"].as_u64().unwrap() <= blocks.len() as u64,
            "{p}"
        );
        for b in blocks {
            for k in ["mae_um", "rms_um", "raw_mae_um", "raw_rms_um"] {
                assert!(b[k].as_f64().is_some_and(f64::is_finite), "{k}: {b}");
            }
            assert!(b["hours"].as_f64().unwrap() >= 0.5, "{b}");
        }
    }
}

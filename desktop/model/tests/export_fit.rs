//! `tcomp fit` parameters exported to a board image compute what the fitted
//! float model computes (envelope widened to whole 1/16 °C, folded into the
//! weights), within 0.1 µm, on the board's own fixed-point core.
use tcomp_model::export::{float_model_from_fit, ExportOptions};
use tcomp_model::fit::{FeatureKind, FeatureSpec, MlrParams, ModelFile, NetParams};

fn xn(v: f64, min: f64, max: f64) -> f64 {
    2.0 * (v.clamp(min, max) - min) / (max - min) - 1.0
}

#[test]
fn exported_mlr_and_net_match_the_fitted_formulas() {
    let rise = FeatureSpec {
        kind: FeatureKind::SensorRise("T_b".into()),
        tau_s: None,
        min: -0.3,
        max: 10.23,
    };
    let diff = FeatureSpec {
        kind: FeatureKind::SensorDiff("T_a".into(), "T_b".into()),
        tau_s: None,
        min: -2.01,
        max: 3.3,
    };
    let file = ModelFile {
        mlr: vec![MlrParams {
            features: vec![rise.clone(), diff.clone()],
            c0: 1.5,
            coef: vec![5.0, -2.0],
            channel: "dz_um".into(),
        }],
        nets: vec![NetParams {
            features: vec![rise.clone(), diff.clone()],
            w1: vec![vec![1.5, -0.7], vec![-2.0, 0.4], vec![0.3, 0.9]],
            b1: vec![0.1, -0.2, 0.05],
            w2: vec![12.0, -7.5, 3.0],
            b2: -1.0,
            channel: "dx_um".into(),
        }],
        chosen: [("dx_um", "ga-bpn"), ("dz_um", "mlr")]
            .iter()
            .map(|(c, m)| (c.to_string(), m.to_string()))
            .collect(),
        ..Default::default()
    };
    let columns: Vec<String> = vec!["T_a".into(), "T_b".into()];
    let fm = float_model_from_fit(&file, &columns, &ExportOptions::default()).unwrap();
    let (model, report) = fm.quantize().unwrap();
    assert!(
        report.max_deviation_um.iter().all(|d| *d <= 0.1),
        "{report:?}"
    );
    assert_eq!(model.direction_name(0), "x");
    assert_eq!(model.direction_name(1), "z");
    // A trace on the board's channel order: T_a, T_b.
    let mut csv = String::from("time_s,spindle_rpm,T_a,T_b\n");
    let mut truth = vec![];
    for i in 0..120 {
        let tb = 20.0 + f64::from(i) * 0.09; // rises 10.7 °C: past the envelope at the end
        let ta = tb + 1.0 - f64::from(i) * 0.03;
        csv += &format!("{},0,{:.4},{:.4}\n", i * 15, ta, tb);
        // The board sees 1/16 °C values.
        let q = |t: f64| (t * 16.0).round() / 16.0;
        let r = q(tb) - q(20.0);
        let d = q(ta) - q(tb);
        let x = [xn(r, rise.min, rise.max), xn(d, diff.min, diff.max)];
        let z = 1.5 + 5.0 * x[0] - 2.0 * x[1];
        let net = &file.nets[0];
        let xh: f64 = net.b2
            + (0..3)
                .map(|j| {
                    net.w2[j]
                        * (1.0
                            / (1.0
                                + (-(net.b1[j] + net.w1[j][0] * x[0] + net.w1[j][1] * x[1])).exp()))
                })
                .sum::<f64>();
        truth.push((xh, z, r > rise.max));
    }
    let mut model = model;
    let mut img = vec![0u8; model.encoded_len()];
    model.encode(&mut img).unwrap();
    let rows =
        tcomp_model::replay::replay(&csv, thermocomp_core::Model::parse(&img).unwrap()).unwrap();
    let mut outside = 0;
    for (row, (x, z, beyond)) in rows.iter().zip(&truth) {
        // Between the fitted edge and the widened one the board extrapolates
        // by at most 1/16 °C; compare inside the fitted envelope.
        if *beyond {
            outside += 1;
            continue;
        }
        assert!(
            (f64::from(row.out.predicted[0]) / 10.0 - x).abs() <= 0.1,
            "x {} vs {x}",
            row.out.predicted[0]
        );
        assert!(
            (f64::from(row.out.predicted[1]) / 10.0 - z).abs() <= 0.1,
            "z {} vs {z}",
            row.out.predicted[1]
        );
    }
    assert!(outside > 0 && outside < 20, "{outside}");
}

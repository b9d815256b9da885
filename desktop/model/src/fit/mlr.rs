//! The linear baseline every channel fits (least-squares MLR on normalized
//! inputs) and the validation figures every model is reported by.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::model::{FeatureSpec, MlrParams};
use super::samples::{normalize_rows, Samples};

/// Least-squares MLR on normalized inputs.
pub fn fit_mlr(specs: Vec<FeatureSpec>, train: &Samples, channel: &str) -> Result<MlrParams> {
    let xn = normalize_rows(&specs, &train.x);
    let c = tcomp_numerics::linalg::least_squares(&xn, &train.y, true, 1e-9 * train.y.len() as f64)
        .with_context(|| format!("channel {channel}: linear fit"))?;
    Ok(MlrParams {
        features: specs,
        c0: c[0],
        coef: c[1..].to_vec(),
        channel: channel.to_string(),
    })
}

/// Validation figures of one channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub mae_um: f64,
    pub rms_um: f64,
    pub peak_um: f64,
    /// 100·(1 − RMS residual / RMS raw error).
    pub reduction_pct: f64,
    pub raw_rms_um: f64,
    pub n: usize,
}

pub fn metrics(y: &[f64], pred: &[f64]) -> Metrics {
    let n = y.len();
    if n == 0 {
        return Metrics::default();
    }
    let (mut sa, mut s2, mut peak, mut r2) = (0.0, 0.0, 0.0f64, 0.0);
    for (&t, &p) in y.iter().zip(pred) {
        let e = t - p;
        sa += e.abs();
        s2 += e * e;
        peak = peak.max(e.abs());
        r2 += t * t;
    }
    let rms = (s2 / n as f64).sqrt();
    let raw = (r2 / n as f64).sqrt();
    Metrics {
        mae_um: sa / n as f64,
        rms_um: rms,
        peak_um: peak,
        reduction_pct: if raw > 0.0 {
            100.0 * (1.0 - rms / raw)
        } else {
            0.0
        },
        raw_rms_um: raw,
        n,
    }
}

//! Ridge regression per channel on the lagged MLR's inputs (model name
//! `ridge`): the inputs normalised as the MLR's (the board's features,
//! clamped to the training range and mapped to [−1, 1]), then standardised
//! on the fit rows; the intercept is not penalised. Its penalty is chosen
//! by forward-chaining cross-validation over time blocks of the training
//! rows only ([`forward_folds`]: the later blocks validated as the "future"
//! of the blocks before them). A ridge model is linear: it is stored and
//! exported as an [`MlrParams`] table with its own coefficients.

use anyhow::{Context, Result};

use super::greedy::SELECT_ROWS;
use super::model::{FeatureSpec, MlrParams, Model};
use super::samples::{normalize_rows, ranged_specs, Samples, SeriesCache};
use super::split::Segment;
use tcomp_data::runcsv::Run;

/// The penalties tried, half decades: `λ` weighs `|β|²` (β on standardised
/// inputs) against the mean squared residual, so `λ = 1` shrinks
/// uncorrelated inputs to half their least-squares coefficient and `1e-5`
/// leaves any input with a tenth of a percent of its own variance unique to
/// it (a correlation of 0.9995 with the others) nearly untouched.
pub const PENALTIES: [f64; 13] = [
    1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0, 10.0,
];

/// The sufficient statistics of one fit part: inputs normalised by `specs`
/// and standardised (mean, standard deviation), their Gram matrix and the
/// centred target's projection, so any penalty solves a p×p system.
pub struct Standardised {
    pub specs: Vec<FeatureSpec>,
    pub mean: Vec<f64>,
    pub sd: Vec<f64>,
    /// `Z'Z / n` (row-major p×p): the inputs' correlation matrix.
    pub gram: Vec<f64>,
    /// `Z'(y − ȳ) / n`.
    pub zy: Vec<f64>,
    pub y_mean: f64,
}

impl Standardised {
    pub fn new(specs: Vec<FeatureSpec>, train: &Samples) -> Standardised {
        let xn = normalize_rows(&specs, &train.x);
        let p = specs.len();
        let n = xn.len().max(1) as f64;
        let y_mean = train.y.iter().sum::<f64>() / n;
        let mut mean = vec![0.0; p];
        for r in &xn {
            for (m, v) in mean.iter_mut().zip(r) {
                *m += v / n;
            }
        }
        let mut sd = vec![0.0; p];
        for r in &xn {
            for j in 0..p {
                sd[j] += (r[j] - mean[j]).powi(2) / n;
            }
        }
        for s in &mut sd {
            *s = s.sqrt();
        }
        let (mut gram, mut zy) = (vec![0.0; p * p], vec![0.0; p]);
        let z = |r: &[f64], j: usize| {
            if sd[j] > 0.0 {
                (r[j] - mean[j]) / sd[j]
            } else {
                0.0
            }
        };
        for (r, y) in xn.iter().zip(&train.y) {
            let zr: Vec<f64> = (0..p).map(|j| z(r, j)).collect();
            for a in 0..p {
                zy[a] += zr[a] * (y - y_mean) / n;
                for b in 0..p {
                    gram[a * p + b] += zr[a] * zr[b] / n;
                }
            }
        }
        Standardised {
            specs,
            mean,
            sd,
            gram,
            zy,
            y_mean,
        }
    }

    /// The ridge model with penalty `lambda`, as a table on the normalised
    /// inputs (`y = c0 + Σ c_i·xn_i`, what `export` ships).
    pub fn solve(&self, lambda: f64, channel: &str) -> Result<MlrParams> {
        let p = self.specs.len();
        let mut a = self.gram.clone();
        for j in 0..p {
            // A constant input (sd 0) has a zero row: its coefficient is 0.
            a[j * p + j] += lambda.max(1e-12) + if self.sd[j] > 0.0 { 0.0 } else { 1.0 };
        }
        let beta = tcomp_numerics::linalg::solve_spd(&a, &self.zy, p)
            .with_context(|| format!("channel {channel}: ridge fit"))?;
        let coef: Vec<f64> = beta
            .iter()
            .zip(&self.sd)
            .map(|(b, s)| if *s > 0.0 { b / s } else { 0.0 })
            .collect();
        let c0 = self.y_mean - coef.iter().zip(&self.mean).map(|(c, m)| c * m).sum::<f64>();
        Ok(MlrParams {
            features: self.specs.clone(),
            c0,
            coef,
            channel: channel.to_string(),
        })
    }
}

/// Ridge with penalty `lambda` on the rows `train`.
pub fn fit_ridge(
    specs: Vec<FeatureSpec>,
    train: &Samples,
    lambda: f64,
    channel: &str,
) -> Result<MlrParams> {
    Standardised::new(specs, train).solve(lambda, channel)
}

/// A linear model's coefficients in standardised units: µm per standard
/// deviation of each input over the rows `rows` (what the stability rule
/// compares across folds: independent of each input's unit and range).
pub fn standardised_coefs(m: &MlrParams, rows: &Samples) -> Vec<f64> {
    let xn = normalize_rows(&m.features, &rows.x);
    let n = xn.len().max(1) as f64;
    (0..m.coef.len())
        .map(|j| {
            let mean = xn.iter().map(|r| r[j]).sum::<f64>() / n;
            let var = xn.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>() / n;
            m.coef[j] * var.sqrt()
        })
        .collect()
}

/// Forward-chaining folds over time blocks (each a [`Segment`] of one
/// run's training rows, as [`super::greedy::blocked_folds`] cuts them):
/// per run the blocks in time order; fold `j` validates on block `j` of
/// every run and fits on the blocks before it, for the later half of the
/// blocks (`j ≥ ⌊m/2⌋` of `m`), so every fold forecasts forward from at
/// least half the training span. Returns `(fit, validate)` per fold.
pub fn forward_folds(blocks: &[Segment]) -> Vec<(Vec<Segment>, Vec<Segment>)> {
    let mut runs: Vec<usize> = blocks.iter().map(|s| s.run).collect();
    runs.sort_unstable();
    runs.dedup();
    let per_run: Vec<Vec<Segment>> = runs
        .iter()
        .map(|&r| {
            let mut b: Vec<Segment> = blocks
                .iter()
                .filter(|s| s.run == r && s.end > s.start)
                .copied()
                .collect();
            b.sort_by_key(|s| s.start);
            b
        })
        .collect();
    let m = per_run.iter().map(Vec::len).max().unwrap_or(0);
    let mut out = Vec::new();
    for j in (m / 2).max(1)..m {
        let (mut fit, mut val) = (Vec::new(), Vec::new());
        for b in &per_run {
            if let Some(v) = b.get(j) {
                val.push(*v);
                fit.extend_from_slice(&b[..j]);
            }
        }
        if !fit.is_empty() && !val.is_empty() {
            out.push((fit, val));
        }
    }
    out
}

/// The penalty with the lowest pooled squared error over the
/// forward-chaining folds of `blocks` (ties: the larger penalty); `None`
/// when no fold has rows enough to fit.
pub fn choose_penalty(
    cache: &SeriesCache,
    runs: &[Run],
    blocks: &[Segment],
    idx: &[usize],
    channel: &str,
) -> Result<Option<f64>> {
    let kinds: Vec<_> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
    let mut sse = [0.0; PENALTIES.len()];
    let mut used = false;
    for (fit, val) in forward_folds(blocks) {
        let tr = cache.samples_capped(runs, &fit, idx, channel, SELECT_ROWS)?;
        let va = cache.samples_capped(runs, &val, idx, channel, SELECT_ROWS)?;
        if tr.y.len() < 2 * idx.len() + 2 || va.y.is_empty() {
            continue;
        }
        let st = Standardised::new(ranged_specs(&kinds, &tr), &tr);
        for (k, &lambda) in PENALTIES.iter().enumerate() {
            let m = st.solve(lambda, channel)?;
            sse[k] +=
                va.x.iter()
                    .zip(&va.y)
                    .map(|(r, y)| (y - m.predict_raw(r)).powi(2))
                    .sum::<f64>();
        }
        used = true;
    }
    if !used {
        return Ok(None);
    }
    let mut best = PENALTIES.len() - 1;
    for k in (0..PENALTIES.len()).rev() {
        if sse[k] < sse[best] {
            best = k;
        }
    }
    Ok(Some(PENALTIES[best]))
}

/// Every block of the training rows the folds cut (each fold validates on
/// one block of every segment; a single fold is its fit part and its
/// time block): the blocks [`choose_penalty`] chains over when it chooses
/// on all the training rows.
pub fn all_blocks(folds: &[(Vec<Segment>, Vec<Segment>)]) -> Vec<Segment> {
    match folds {
        [(fit, val)] => fit.iter().chain(val).copied().collect(),
        _ => folds.iter().flat_map(|(_, v)| v.iter().copied()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::model::FeatureKind;

    fn spec(name: &str, min: f64, max: f64) -> FeatureSpec {
        FeatureSpec {
            kind: FeatureKind::SensorRise(name.into()),
            tau_s: None,
            min,
            max,
        }
    }

    #[test]
    fn a_tiny_penalty_is_least_squares_and_a_large_one_shrinks_to_the_mean() {
        let mut s = Samples::default();
        for i in 0..200 {
            let a = (i as f64 * 0.37).sin() * 3.0;
            let b = (i as f64 * 0.11).cos() * 2.0;
            s.x.push(vec![a, b]);
            s.y.push(4.0 + 1.5 * a - 2.0 * b);
        }
        let specs = vec![spec("a", -3.0, 3.0), spec("b", -2.0, 2.0)];
        let m = fit_ridge(specs.clone(), &s, 1e-9, "y").unwrap();
        for (r, y) in s.x.iter().zip(&s.y) {
            assert!((m.predict_raw(r) - y).abs() < 1e-5);
        }
        let flat = fit_ridge(specs, &s, 1e9, "y").unwrap();
        let mean = s.y.iter().sum::<f64>() / s.y.len() as f64;
        assert!(flat.coef.iter().all(|c| c.abs() < 1e-6));
        assert!(
            (flat.c0 - mean).abs() < 1e-6,
            "the intercept is not penalised"
        );
    }

    #[test]
    fn forward_folds_fit_only_on_earlier_blocks() {
        let seg = |run, start, end| Segment { run, start, end };
        let blocks: Vec<Segment> = (0..5).map(|k| seg(0, 10 * k, 10 * k + 10)).collect();
        let folds = forward_folds(&blocks);
        assert_eq!(folds.len(), 3);
        for (fit, val) in &folds {
            assert!(fit.iter().all(|f| f.end <= val[0].start));
        }
        assert_eq!(folds.last().unwrap().0.len(), 4);
    }
}

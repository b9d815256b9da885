//! A fit's rows: each candidate input's series over the runs, as the board
//! computes it ([`features`]), gathered into samples (raw inputs, target,
//! where each row came from) from run segments, with the training ranges
//! that normalize every input to [−1, 1].

use anyhow::{Context, Result};

use super::features;
use super::model::{FeatureKind, FeatureSpec, Model};
use super::split::Segment;
use tcomp_data::runcsv::Run;

/// The raw (un-normalized) input series of one feature over a whole run, as
/// the board computes it ([`features::board_series`]): °C or rpm, NaN on rows
/// where the board computes no feature.
pub fn feature_series(run: &Run, kind: &FeatureKind, tau_s: Option<f64>) -> Result<Vec<f64>> {
    let mut s = features::board_series(run, &[(kind.clone(), tau_s)])?;
    Ok(s.pop().unwrap_or_default())
}

/// Several features' series over a run: `out[feature][row]`.
pub fn feature_columns(run: &Run, kinds: &[(FeatureKind, Option<f64>)]) -> Result<Vec<Vec<f64>>> {
    features::board_series(run, kinds)
}

/// Predict a whole run on the board's features (NaN on rows with a sensor gap).
pub fn predict_run<M: Model + ?Sized>(m: &M, run: &Run) -> Result<Vec<f64>> {
    let kinds: Vec<_> = m
        .features()
        .iter()
        .map(|f| (f.kind.clone(), f.tau_s))
        .collect();
    let cols = feature_columns(run, &kinds)?;
    Ok((0..run.rows())
        .map(|r| {
            let x: Vec<f64> = cols.iter().map(|c| c[r]).collect();
            m.predict_raw(&x)
        })
        .collect())
}

/// Rows gathered from segments: raw inputs, target (µm) and where they came from.
#[derive(Clone, Debug, Default)]
pub struct Samples {
    pub x: Vec<Vec<f64>>,
    pub y: Vec<f64>,
    /// (run index, row index) of each sample.
    pub rows: Vec<(usize, usize)>,
}

/// Precomputed input series: `series[feature][run][row]`.
pub struct SeriesCache {
    pub kinds: Vec<(FeatureKind, Option<f64>)>,
    pub series: Vec<Vec<Vec<f64>>>,
}

impl SeriesCache {
    pub fn new(runs: &[Run], kinds: Vec<(FeatureKind, Option<f64>)>) -> Result<SeriesCache> {
        let mut series = vec![Vec::with_capacity(runs.len()); kinds.len()];
        for run in runs {
            for (f, col) in feature_columns(run, &kinds)?.into_iter().enumerate() {
                series[f].push(col);
            }
        }
        Ok(SeriesCache { kinds, series })
    }

    /// The board computes features `idx` at row `r` of run `run` (no gap).
    #[inline]
    fn usable(&self, idx: &[usize], run: usize, r: usize) -> bool {
        idx.iter().all(|&f| self.series[f][run][r].is_finite())
    }

    /// Samples of features `idx` over the segments; rows without a target or
    /// where the board computes no feature (a sensor gap) are skipped.
    pub fn samples(
        &self,
        runs: &[Run],
        segs: &[Segment],
        idx: &[usize],
        channel: &str,
    ) -> Result<Samples> {
        self.samples_capped(runs, segs, idx, channel, usize::MAX)
    }

    /// As [`SeriesCache::samples`], but every k-th row with a target so that
    /// at most `max_rows` are gathered (selection and cross-validation on a
    /// densely sampled run: the rows are far closer than any time constant).
    pub fn samples_capped(
        &self,
        runs: &[Run],
        segs: &[Segment],
        idx: &[usize],
        channel: &str,
        max_rows: usize,
    ) -> Result<Samples> {
        // One pass finds the usable rows (every feature computed, a target
        // present); the stride then picks from them without testing again.
        let mut usable: Vec<(usize, usize, f64)> = Vec::new();
        for seg in segs {
            let y = runs[seg.run]
                .col(channel)
                .with_context(|| format!("run {} has no column `{channel}`", seg.run + 1))?;
            usable.extend((seg.start..seg.end).filter_map(|r| {
                let t = y[r]?;
                self.usable(idx, seg.run, r).then_some((seg.run, r, t))
            }));
        }
        let stride = usable.len().div_ceil(max_rows.max(1)).max(1);
        let mut s = Samples::default();
        for &(run, r, t) in usable.iter().step_by(stride) {
            s.x.push(idx.iter().map(|&f| self.series[f][run][r]).collect());
            s.y.push(t);
            s.rows.push((run, r));
        }
        Ok(s)
    }
}

impl Samples {
    /// Every k-th row so that at most `max_rows` remain (thermal runs are
    /// sampled far faster than their time constants: an evenly strided
    /// subset carries nearly all the information at a fraction of the cost).
    pub fn strided(&self, max_rows: usize) -> Samples {
        let stride = self.y.len().div_ceil(max_rows.max(1)).max(1);
        if stride == 1 {
            return self.clone();
        }
        Samples {
            x: self.x.iter().step_by(stride).cloned().collect(),
            y: self.y.iter().step_by(stride).copied().collect(),
            rows: self.rows.iter().step_by(stride).copied().collect(),
        }
    }
}

/// Feature specs with ranges from the training samples.
pub fn ranged_specs(kinds: &[(FeatureKind, Option<f64>)], train: &Samples) -> Vec<FeatureSpec> {
    kinds
        .iter()
        .enumerate()
        .map(|(i, (k, t))| {
            let mut min = f64::INFINITY;
            let mut max = f64::NEG_INFINITY;
            for r in &train.x {
                min = min.min(r[i]);
                max = max.max(r[i]);
            }
            if !min.is_finite() {
                (min, max) = (0.0, 1.0);
            }
            FeatureSpec {
                kind: k.clone(),
                tau_s: *t,
                min,
                max,
            }
        })
        .collect()
}

pub fn normalize_rows(specs: &[FeatureSpec], x: &[Vec<f64>]) -> Vec<Vec<f64>> {
    x.iter()
        .map(|r| specs.iter().zip(r).map(|(f, &v)| f.normalize(v)).collect())
        .collect()
}

//! The calibration's freedom, left to every candidate: the nominal is the
//! machine file calibrated within its tolerances (`calibrate.rs`), and an
//! effect is judged against it with the SAME freedom — each design value may
//! still move, but only inside its tolerance. Re-calibrating the ≈100
//! design values for every trial of every candidate would cost ≈100
//! simulations each, so the freedom is linearised at the calibrated values
//! (the sensitivity of every channel to every design value, one simulation
//! per value, computed once) and, for every trial, the design values'
//! correction is a box-constrained least-squares fit on the fit rows
//! (projected Gauss–Seidel) whose box is the tolerance: a candidate can
//! absorb no more of a wrong design than the null hypothesis could.

use anyhow::Result;
use nalgebra::{DMatrix, DVector};

use super::boxqp::box_qp;
use super::calibrate::{apply, Knob};
use super::effect_fit::{par_map, Evaluator, Projection};
use super::prep::Prepared;
use crate::sim::Machine;

/// The linearised, bounded calibration freedom on the full grid.
pub struct Freedom {
    /// ∂(simulated channel)/∂θ: one row per (run, channel, row) in order,
    /// one column per knob.
    sens: DMatrix<f64>,
    /// Weight per flattened row: the channel's on fit rows, 0 on held-out.
    wf: Vec<f64>,
    /// Calibrated θ, its bounds and prior precision per knob.
    theta: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    prec: Vec<f64>,
    /// SᵀWS over the fit rows plus the prior precision.
    a: DMatrix<f64>,
}

impl Freedom {
    /// Sensitivities at the calibrated θ (one simulation per knob).
    pub(crate) fn new(
        m: &Machine,
        ks: &[Knob],
        theta: &[f64],
        ps: &[Prepared],
        threads: usize,
    ) -> Result<Freedom> {
        let cal = apply(m, ks, theta);
        let ev = Evaluator::new(&cal, ps)?;
        let r0 = ev.residuals(&[])?;
        let st = ev.stats_of(&r0);
        let w: Vec<f64> = st
            .ch
            .iter()
            .map(|c| 1.0 / (c.sse_fit / c.n_fit.max(1) as f64 + (0.1 * c.s).powi(2)))
            .collect();
        let h = 0.02;
        let idx: Vec<usize> = (0..ks.len()).collect();
        let cols = par_map(&idx, threads, |&i| -> Result<Vec<Vec<Vec<f64>>>> {
            let mut t = theta.to_vec();
            t[i] += h;
            let mi = apply(m, ks, &t);
            let ri = Evaluator::new(&mi, ps)?.residuals(&[])?;
            // residual = measured − simulated: ∂sim = −∂residual
            Ok(r0
                .iter()
                .zip(&ri)
                .map(|(a, b)| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| {
                            x.iter()
                                .zip(y)
                                .map(|(p, q)| {
                                    let d = (p - q) / h;
                                    if d.is_finite() {
                                        d
                                    } else {
                                        0.0
                                    }
                                })
                                .collect()
                        })
                        .collect()
                })
                .collect())
        })
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
        let nk = ks.len();
        let prec: Vec<f64> = ks.iter().map(|k| 1.0 / k.sigma().powi(2)).collect();
        let mut wf = Vec::new();
        let mut ci = 0;
        for (p, rr) in ps.iter().zip(&r0) {
            for ch in rr {
                wf.extend((0..ch.len()).map(|k| if p.is_fit(k) { w[ci] } else { 0.0 }));
                ci += 1;
            }
        }
        let n_all = wf.len();
        let sens = DMatrix::from_fn(n_all, nk, |_, _| 0.0);
        let mut sens = sens;
        for (i, col) in cols.iter().enumerate() {
            let flat: Vec<f64> = col.iter().flatten().flatten().copied().collect();
            sens.column_mut(i).copy_from_slice(&flat);
        }
        let ws = DMatrix::from_fn(n_all, nk, |r, c| sens[(r, c)] * wf[r]);
        let mut a = sens.transpose() * ws;
        for i in 0..nk {
            a[(i, i)] += prec[i];
        }
        let (lo, hi): (Vec<f64>, Vec<f64>) = ks.iter().map(Knob::bounds).unzip();
        Ok(Freedom {
            sens,
            wf,
            theta: theta.to_vec(),
            lo,
            hi,
            prec,
            a,
        })
    }

    /// Number of design values that may move.
    pub fn len(&self) -> usize {
        self.theta.len()
    }

    pub fn is_empty(&self) -> bool {
        self.theta.is_empty()
    }

    /// The bounded correction δ of the design values that best explains
    /// `res` on the fit rows (with the prior), and `res` with it removed
    /// (every row).
    pub fn correct(&self, res: &mut [Vec<Vec<f64>>]) -> Vec<f64> {
        let nk = self.len();
        if nk == 0 {
            return Vec::new();
        }
        let b = self.pull_of(res);
        let lo: Vec<f64> = (0..nk).map(|i| self.lo[i] - self.theta[i]).collect();
        let hi: Vec<f64> = (0..nk).map(|i| self.hi[i] - self.theta[i]).collect();
        let d = box_qp(&self.a, &b, &lo, &hi);
        let corr = &self.sens * DVector::from_column_slice(&d);
        let mut k = 0;
        for rr in res.iter_mut() {
            for r in rr.iter_mut() {
                for v in r.iter_mut() {
                    *v -= corr[k];
                    k += 1;
                }
            }
        }
        d
    }

    /// Sᵀ W r − prior: the data's pull on every knob at the calibrated θ.
    fn pull_of(&self, res: &[Vec<Vec<f64>>]) -> Vec<f64> {
        let wr: Vec<f64> = res
            .iter()
            .flatten()
            .flatten()
            .zip(&self.wf)
            .map(|(r, w)| if r.is_finite() { r * w } else { 0.0 })
            .collect();
        let g = self.sens.tr_mul(&DVector::from_vec(wr));
        (0..self.len())
            .map(|i| g[i] - self.prec[i] * self.theta[i])
            .collect()
    }

    /// Where each knob would go with its bound released: the data's pull
    /// at the calibrated θ (positive: wants a larger value).
    pub fn pull(&self, _ps: &[Prepared], res: &[Vec<Vec<f64>>]) -> Vec<f64> {
        self.pull_of(res)
    }

    pub fn theta(&self) -> &[f64] {
        &self.theta
    }

    pub fn bounds(&self, i: usize) -> (f64, f64) {
        (self.lo[i], self.hi[i])
    }
}

impl Projection for Freedom {
    fn project(&self, res: &mut [Vec<Vec<f64>>]) {
        self.correct(res);
    }
}

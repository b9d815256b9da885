//! The least squares of `ident`: every output of the nominal model fitted
//! for one structure (ridge, fit blocks only), jointly when the outputs
//! share one design, else one by one, with optional extra columns of a
//! candidate effect, a sensor lag, and the sign constraint of the switched
//! conductance inputs. `ident` chooses the structure with these fits.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::model::{Columns, Extra, ModelFit, OutFit, Problem, Structure, RIDGE};
use crate::diagnose::signal::lag_signal;
use tcomp_numerics::linalg::{ridge, ridge_multi};

impl Problem<'_> {
    /// Fit every output for a structure, with optional extra columns and a
    /// sensor lag `(output, tau)` applied to that output's model.
    pub fn fit(
        &self,
        st: &Structure,
        extra: Option<Extra>,
        lagged: Option<(usize, f64)>,
    ) -> ModelFit {
        if extra.is_none() && lagged.is_none() && !self.cross() {
            if let Some((mut f, coef)) = self.fit_shared(st) {
                if self.conductance_constrained() {
                    // the sign constraint of `fit_output`, on the shared fit:
                    // a temperature output whose steady gain from the
                    // conductance inputs is positive is fitted without them
                    let cols = self.conductance_columns(st);
                    let redo: Vec<usize> = (0..self.outputs.len())
                        .filter(|&o| {
                            !self.outputs[o].is_disp
                                && cols.clone().map(|j| coef[(j, o)]).sum::<f64>() > 0.0
                        })
                        .collect();
                    let refits: Vec<(usize, OutFit)> = redo
                        .into_par_iter()
                        .map(|o| {
                            (
                                o,
                                self.fit_output_without(st, o, None, None, cols.clone()).0,
                            )
                        })
                        .collect();
                    for (o, r) in refits {
                        f.outs[o] = r;
                    }
                }
                return f;
            }
        }
        let outs = (0..self.outputs.len())
            .into_par_iter()
            .map(|o| self.fit_output(st, o, extra, lagged.filter(|l| l.0 == o).map(|l| l.1)))
            .collect();
        ModelFit { outs }
    }

    /// Input-driven outputs share one design: one Gram matrix and one
    /// factorisation for all of them (`None` when their missing rows differ).
    /// Also returns the coefficients (shared columns first, one column per
    /// output).
    fn fit_shared(&self, st: &Structure) -> Option<(ModelFit, DMatrix<f64>)> {
        let nr = self.ds.runs.len();
        let no = self.outputs.len();
        let blocks: Vec<Columns> = (0..nr).map(|r| self.columns(st, 0, r)).collect();
        let n_shared = blocks.first().map_or(0, |b| b.0.len());
        let n_own = blocks.first().map_or(0, |b| b.1.len());
        if blocks.iter().any(|b| b.1.len() != n_own) {
            return None;
        }
        let p = n_shared + nr * n_own;
        let mut rows = Vec::new();
        for (r, run) in self.ds.runs.iter().enumerate() {
            for k in 0..run.rows() {
                let finite = (0..no).filter(|&o| self.meas[r][o][k].is_finite()).count();
                if finite != 0 && finite != no {
                    return None;
                }
                if !run.held[k] && finite == no {
                    rows.push((r, k));
                }
            }
        }
        if rows.len() <= p + 2 {
            return None;
        }
        let value = |r: usize, k: usize, j: usize| -> f64 {
            if j < n_shared {
                blocks[r].0[j][k]
            } else {
                let jj = j - n_shared;
                if jj / n_own == r {
                    blocks[r].1[jj % n_own][k]
                } else {
                    0.0
                }
            }
        };
        let x = DMatrix::from_fn(rows.len(), p, |i, j| value(rows[i].0, rows[i].1, j));
        let y = DMatrix::from_fn(rows.len(), no, |i, o| self.meas[rows[i].0][o][rows[i].1]);
        let coef = ridge_multi(&x, &y, RIDGE)?;
        let mut outs: Vec<OutFit> = (0..no)
            .map(|_| OutFit {
                resid: Vec::with_capacity(nr),
                k: p,
                ..Default::default()
            })
            .collect();
        for (r, run) in self.ds.runs.iter().enumerate() {
            let xa = DMatrix::from_fn(run.rows(), p, |k, j| value(r, k, j));
            let pred = xa * &coef;
            for (o, f) in outs.iter_mut().enumerate() {
                f.push_run(&self.meas[r][o], &run.held, |k| pred[(k, o)]);
            }
        }
        Some((ModelFit { outs }, coef))
    }

    /// Fit with extra columns, keeping them only in the outputs whose
    /// fit-row BIC they improve (an effect enters a channel's model only
    /// where the fit data supports it). Returns the fit and the outputs
    /// that took the effect.
    pub fn fit_where_supported(
        &self,
        st: &Structure,
        extra: Extra,
        nominal: &ModelFit,
    ) -> (ModelFit, Vec<usize>) {
        let n_total = nominal.n_fit().max(2) as f64;
        let with: Vec<OutFit> = (0..self.outputs.len())
            .into_par_iter()
            .map(|o| self.fit_output(st, o, Some(extra), None))
            .collect();
        let mut out = nominal.clone();
        let mut took = Vec::new();
        for (o, f) in with.into_iter().enumerate() {
            let b = &nominal.outs[o];
            let floor = (0.1 * self.outputs[o].noise).powi(2);
            let crit = |x: &OutFit| {
                let n = x.n_fit.max(1) as f64;
                n * (x.sse_fit / n + floor).ln() + x.k as f64 * n_total.ln()
            };
            if f.n_fit > 0 && crit(&f) < crit(b) {
                out.outs[o] = f;
                took.push(o);
            }
        }
        (out, took)
    }

    /// Shared-column indices of the switched conductance inputs (every
    /// switched input after the running state), in `columns`' order.
    fn conductance_columns(&self, st: &Structure) -> std::ops::Range<usize> {
        let names: Vec<&str> = self
            .inputs(0, st.exponent)
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        let nm = st.modes.len();
        let first = names.iter().position(|&n| n == "switched");
        let count = names.iter().filter(|&&n| n == "switched").count();
        match first {
            Some(i) if count > 1 => (i + 1) * nm..(i + count) * nm,
            _ => 0..0,
        }
    }

    /// Fit one output (see `fit`).
    pub fn fit_output(
        &self,
        st: &Structure,
        o: usize,
        extra: Option<Extra>,
        lag_tau: Option<f64>,
    ) -> OutFit {
        if !self.conductance_constrained() || self.outputs[o].is_disp {
            return self.fit_output_without(st, o, extra, lag_tau, 0..0).0;
        }
        let cols = self.conductance_columns(st);
        let (fit, coef) = self.fit_output_without(st, o, extra, lag_tau, 0..0);
        // each modal column has unit steady gain: their sum is the steady gain
        let gain: f64 = coef.map_or(0.0, |c| cols.clone().map(|j| c[j]).sum());
        if gain > 0.0 {
            self.fit_output_without(st, o, extra, lag_tau, cols).0
        } else {
            fit
        }
    }

    /// Fit one output without the shared columns `drop`; also returns the
    /// coefficients (`None` when the fit failed).
    fn fit_output_without(
        &self,
        st: &Structure,
        o: usize,
        extra: Option<Extra>,
        lag_tau: Option<f64>,
        drop: std::ops::Range<usize>,
    ) -> (OutFit, Option<DVector<f64>>) {
        let nr = self.ds.runs.len();
        // per run: shared columns, own columns, extra columns
        let mut blocks = Vec::with_capacity(nr);
        for r in 0..nr {
            let (mut shared, mut own) = self.columns(st, o, r);
            if !drop.is_empty() && drop.end <= shared.len() {
                shared.drain(drop.clone());
            }
            let mut ex = extra.map(|f| f(o, r)).unwrap_or_default();
            if let Some(tau) = lag_tau {
                let dt = self.ds.runs[r].dt;
                for c in shared.iter_mut().chain(own.iter_mut()).chain(ex.iter_mut()) {
                    *c = lag_signal(c, dt, tau);
                }
            }
            blocks.push((shared, own, ex));
        }
        let n_shared = blocks.first().map_or(0, |b| b.0.len());
        // Each run's own columns (level, free decays) are its own: their
        // number follows the run's span, so runs of different lengths differ.
        let own_len: Vec<usize> = blocks.iter().map(|b| b.1.len()).collect();
        let own_off: Vec<usize> = own_len
            .iter()
            .scan(0, |acc, &l| {
                let at = *acc;
                *acc += l;
                Some(at)
            })
            .collect();
        let n_own_all: usize = own_len.iter().sum();
        let n_extra = blocks.iter().map(|b| b.2.len()).max().unwrap_or(0);
        let p = n_shared + n_own_all + n_extra;
        // fit rows
        let mut rows = Vec::new();
        for (r, run) in self.ds.runs.iter().enumerate() {
            for k in 0..run.rows() {
                if !run.held[k] && self.meas[r][o][k].is_finite() {
                    rows.push((r, k));
                }
            }
        }
        let value = |r: usize, k: usize, j: usize| -> f64 {
            let b = &blocks[r];
            if j < n_shared {
                b.0.get(j).map_or(0.0, |c| c[k])
            } else if j < n_shared + n_own_all {
                let jj = j - n_shared;
                if (own_off[r]..own_off[r] + own_len[r]).contains(&jj) {
                    b.1[jj - own_off[r]][k]
                } else {
                    0.0
                }
            } else {
                b.2.get(j - n_shared - n_own_all).map_or(0.0, |c| c[k])
            }
        };
        let mut fit = OutFit {
            resid: Vec::with_capacity(nr),
            k: p,
            ..Default::default()
        };
        let coef = if rows.len() > p + 2 {
            let x = DMatrix::from_fn(rows.len(), p, |i, j| value(rows[i].0, rows[i].1, j));
            let y =
                DVector::from_iterator(rows.len(), rows.iter().map(|&(r, k)| self.meas[r][o][k]));
            ridge(&x, &y, RIDGE)
        } else {
            None
        };
        let Some(coef) = coef else {
            let held = (0..nr)
                .map(|r| {
                    let run = &self.ds.runs[r];
                    (0..run.rows())
                        .filter(|&k| run.held[k] && self.meas[r][o][k].is_finite())
                        .count()
                })
                .sum();
            let sizes: Vec<usize> = self.ds.runs.iter().map(|r| r.rows()).collect();
            return (OutFit::failed(p, &sizes, rows.len(), held), None);
        };
        fit.extra_coef = (0..n_extra)
            .map(|j| coef[n_shared + n_own_all + j])
            .collect();
        for (r, run) in self.ds.runs.iter().enumerate() {
            fit.push_run(&self.meas[r][o], &run.held, |k| {
                (0..p).map(|j| coef[j] * value(r, k, j)).sum()
            });
        }
        (fit, Some(coef))
    }
}

#[cfg(test)]
mod tests {
    use super::super::model::TAU_GRID;
    use super::*;
    use tcomp_data::runcsv::Run;

    /// A design the solver cannot use (more coefficients than fit rows) is a
    /// failed fit with NaN residuals and infinite figures, never zero
    /// coefficients that would pass the raw measurement off as a residual.
    #[test]
    fn a_fit_the_solver_gives_up_on_is_failed_not_zero() {
        let n = 40;
        let mut run = Run::default();
        let col = |v: Vec<f64>| v.into_iter().map(Some).collect::<Vec<_>>();
        run.push_column("time_s", col((0..n).map(|k| k as f64 * 30.0).collect()))
            .unwrap();
        run.push_column("spindle_rpm", col(vec![3000.0; n]))
            .unwrap();
        run.push_column("T_a", col((0..n).map(|k| 20.0 + k as f64 * 0.1).collect()))
            .unwrap();
        let ds = crate::diagnose::runs::load(&[("tiny".into(), run)], 1500).unwrap();
        let p = Problem::new(&ds);
        // Far more modes than the few fit rows can carry.
        let st = Structure {
            modes: TAU_GRID.to_vec(),
            exponent: 1.0,
        };
        let extra = |_: usize, _: usize| -> Vec<Vec<f64>> { vec![vec![1.0; n]; 3 * n] };
        let f = p.fit_output(&st, 0, Some(&extra), None);
        assert!(f.failed);
        assert!(f.sse_fit.is_infinite() && f.extra_coef.is_empty());
        assert!(f.resid.iter().flatten().all(|e| e.is_nan()));
        let m = ModelFit { outs: vec![f] };
        assert!(m.bic(&p.outputs).is_infinite());
    }
}

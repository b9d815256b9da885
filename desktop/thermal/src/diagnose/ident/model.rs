//! The nominal model `diagnose fit` identifies from the runs themselves.
//!
//! A linear thermal network (nodes, conductances, capacities, heat inputs)
//! has, from every input to every node, the transfer function
//! `Σ_m r_m / (1 + s τ_m)` over the network's own time constants `τ_m`,
//! shared by all nodes. The model is that network in modal coordinates: the
//! inputs (spindle heat `n/n_max` and `(n/n_max)^e`, `feed_activity`, `coolant_on`, the
//! rise of `T_ambient`) pass through first-order lags with shared time
//! constants (exact zero-order-hold discretisation); each sensor is a
//! linear combination of these modal states plus a level and the free
//! decay of each mode per run (the run need not start at rest); each
//! displacement is a linear map of the same states (node rises are linear
//! in them). Coefficients come from ridge least squares on the fit blocks;
//! the speed exponent and the number of modes (the network's order: one
//! per sensed or hidden node the data supports) are chosen by BIC on the
//! fit blocks, so the held-out blocks stay unseen until scoring.
//!
//! Without `spindle_rpm` the heat input is not observed; then temperatures
//! drive the model: each sensor is predicted from the leading principal
//! components of the other sensors (their rises, direct and through the
//! same lags), each displacement from those of all sensors.
//!
//! The least squares of one structure are in `least_squares.rs`.

use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::diagnose::runs::Dataset;
use crate::diagnose::signal::{held_rise, lag};

/// Candidate time constants [s] (2 min … 5.3 h).
pub const TAU_GRID: [f64; 8] = [120.0, 300.0, 600.0, 1200.0, 2400.0, 4800.0, 9600.0, 19200.0];
/// Candidate exponents of the friction part of the spindle heat
/// `a·(n/n_max) + b·(n/n_max)^e` (motor losses ∝ n, bearing friction
/// ∝ n^1.5…2 after Palmgren).
pub const EXPONENTS: [f64; 2] = [1.5, 2.0];
/// At most this many modes.
pub const MAX_MODES: usize = 9;
/// Relative ridge of the least squares (the lagged inputs are strongly
/// collinear; without it held-out rows between fit blocks blow up).
pub const RIDGE: f64 = 1e-6;
/// Principal components of the other sensors that drive a sensor (no rpm).
const DRIVER_PCS: usize = 3;

/// One modelled output channel.
#[derive(Clone, Debug)]
pub struct Output {
    pub name: String,
    pub is_disp: bool,
    /// Noise scale (°C or µm).
    pub noise: f64,
}

/// The structure of a nominal model.
#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    pub modes: Vec<f64>,
    pub exponent: f64,
}

/// Regressor columns of one run: (shared by runs, the run's own).
pub type Columns = (Vec<Vec<f64>>, Vec<Vec<f64>>);

/// Extra regressor columns an effect adds, per (output, run).
pub type Extra<'a> = &'a (dyn Fn(usize, usize) -> Vec<Vec<f64>> + Sync);

/// Fit of one output: residual per run, fit and held-out sums.
#[derive(Clone, Debug, Default)]
pub struct OutFit {
    /// run → row: measured − model (NaN where not measured).
    pub resid: Vec<Vec<f64>>,
    pub sse_fit: f64,
    pub n_fit: usize,
    pub sse_held: f64,
    pub n_held: usize,
    pub peak_held: f64,
    /// Number of fitted coefficients.
    pub k: usize,
    /// Coefficients of the extra columns (in their order).
    pub extra_coef: Vec<f64>,
    /// The least-squares solver gave up (singular, or too few rows): no
    /// prediction, residuals NaN, fit and held-out sums infinite, so the
    /// structure search never picks it and `diagnose fit` refuses it.
    pub failed: bool,
}

/// A fitted model over all outputs.
#[derive(Clone, Debug)]
pub struct ModelFit {
    pub outs: Vec<OutFit>,
}

impl OutFit {
    /// The fit of an output whose solver gave up (never zeros as coefficients):
    /// `rows[r]` rows per run, `n_fit` / `n_held` of them measured.
    pub fn failed(k: usize, rows: &[usize], n_fit: usize, n_held: usize) -> OutFit {
        OutFit {
            resid: rows.iter().map(|&n| vec![f64::NAN; n]).collect(),
            sse_fit: f64::INFINITY,
            n_fit: n_fit.max(1),
            sse_held: f64::INFINITY,
            n_held,
            peak_held: f64::INFINITY,
            k,
            extra_coef: vec![],
            failed: true,
        }
    }

    /// Book one residual `e` of a row: into the held-out or the fit sums.
    pub fn add_residual(&mut self, e: f64, held: bool) {
        if held {
            self.sse_held += e * e;
            self.n_held += 1;
            self.peak_held = self.peak_held.max(e.abs());
        } else {
            self.sse_fit += e * e;
            self.n_fit += 1;
        }
    }

    /// Book one run's residuals, measurement − `pred(row)` (asked only
    /// where the measurement is finite; a gap stays NaN), and keep them.
    pub fn push_run(&mut self, meas: &[f64], held: &[bool], pred: impl Fn(usize) -> f64) {
        let res = meas
            .iter()
            .zip(held)
            .enumerate()
            .map(|(k, (&m, &h))| {
                if !m.is_finite() {
                    return f64::NAN;
                }
                let e = m - pred(k);
                self.add_residual(e, h);
                e
            })
            .collect();
        self.resid.push(res);
    }
}

impl ModelFit {
    /// −2 log-likelihood of the fit rows with an unknown variance per
    /// channel, floored at a tenth of its noise.
    pub fn j_fit(&self, outputs: &[Output]) -> f64 {
        self.outs
            .iter()
            .zip(outputs)
            .filter(|(f, _)| f.n_fit > 0)
            .map(|(f, o)| {
                let n = f.n_fit as f64;
                n * (f.sse_fit / n + (0.1 * o.noise).powi(2)).ln()
            })
            .sum()
    }

    pub fn k(&self) -> usize {
        self.outs.iter().map(|f| f.k).sum()
    }

    pub fn n_fit(&self) -> usize {
        self.outs.iter().map(|f| f.n_fit).sum()
    }

    pub fn bic(&self, outputs: &[Output]) -> f64 {
        self.j_fit(outputs) + self.k() as f64 * (self.n_fit().max(2) as f64).ln()
    }

    /// Held-out RMS and peak over displacement (`true`) or temperature outputs.
    pub fn gap_held(&self, outputs: &[Output], disp: bool) -> Option<(f64, f64)> {
        let (mut sse, mut n, mut pk) = (0.0, 0usize, 0.0f64);
        for (f, o) in self.outs.iter().zip(outputs) {
            if o.is_disp == disp && f.n_held > 0 {
                sse += f.sse_held;
                n += f.n_held;
                pk = pk.max(f.peak_held);
            }
        }
        (n > 0).then(|| ((sse / n as f64).sqrt(), pk))
    }

    /// Held-out mean square in noise units per output (1 ≈ noise only).
    pub fn m_held_of(&self, outputs: &[Output], which: &[usize]) -> f64 {
        let v: Vec<f64> = which
            .iter()
            .filter(|&&i| self.outs[i].n_held > 0)
            .map(|&i| self.outs[i].sse_held / self.outs[i].n_held as f64 / outputs[i].noise.powi(2))
            .collect();
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    }
}

/// The identification problem: dataset, outputs and the driving signals.
pub struct Problem<'a> {
    pub ds: &'a Dataset,
    pub outputs: Vec<Output>,
    /// run → output → measured values (NaN where missing).
    pub meas: Vec<Vec<Vec<f64>>>,
    /// Maximum speed over all runs (rpm), for `(n/n_max)^e`.
    pub n_max: f64,
    /// Without rpm: run → output → driver signals (rises, before lags).
    drivers: Vec<Vec<Vec<Vec<f64>>>>,
    /// With rpm: run → inputs switched with the spindle (before lags;
    /// empty for the nominal, see `switch_with_spindle`).
    switched: Vec<Vec<Vec<f64>>>,
    /// Candidate exponents of the friction heat (`EXPONENTS` for the
    /// nominal).
    pub exponents: Vec<f64>,
    /// A third spindle heat input `(n/n_max)^steep` (the speed-law test's
    /// alternative; `None` for the nominal).
    pub steep: Option<f64>,
    /// The switched conductance inputs (running × sensor-rise components)
    /// may only remove heat: a temperature output whose fitted steady gain
    /// from them is positive is fitted again without them (an active-set
    /// step for the sign constraint; otherwise the term soaks up any extra
    /// heat that grows with the body's rise while the spindle runs).
    pub removes_heat: bool,
}

impl<'a> Problem<'a> {
    pub fn new(ds: &'a Dataset) -> Problem<'a> {
        let mut outputs = Vec::new();
        for s in &ds.sensors {
            outputs.push(Output {
                name: s.clone(),
                is_disp: false,
                noise: ds.noise(s),
            });
        }
        for d in &ds.disps {
            outputs.push(Output {
                name: d.clone(),
                is_disp: true,
                noise: ds.noise(d),
            });
        }
        let meas: Vec<Vec<Vec<f64>>> = ds
            .runs
            .iter()
            .map(|r| {
                outputs
                    .iter()
                    .map(|o| {
                        r.sensors
                            .iter()
                            .chain(&r.disps)
                            .find(|s| s.name == o.name)
                            .map_or_else(|| vec![f64::NAN; r.rows()], |s| s.values.clone())
                    })
                    .collect()
            })
            .collect();
        let n_max = ds
            .runs
            .iter()
            .filter_map(|r| r.rpm.as_ref())
            .flatten()
            .fold(0.0f64, |a, &b| a.max(b.abs()))
            .max(1.0);
        let mut p = Problem {
            ds,
            outputs,
            meas,
            n_max,
            drivers: Vec::new(),
            switched: Vec::new(),
            exponents: EXPONENTS.to_vec(),
            steep: None,
            removes_heat: false,
        };
        if !ds.has_rpm {
            p.drivers = p.temperature_drivers();
        }
        p
    }

    /// Add inputs that switch with the spindle (used by the speed-law
    /// test's reference, not by the nominal): the running state, and the
    /// running state times the `pcs` leading principal components (fit
    /// rows) of the sensor rises — a conductance that acts only while the
    /// spindle runs (a coolant jacket fed by the spindle's pump) removes
    /// heat in proportion to how far its node stands above the coolant,
    /// which no linear network with fixed conductances carries.
    pub fn switch_with_spindle(&mut self, pcs: usize) {
        self.switched = Vec::new();
        if !self.ds.has_rpm {
            return;
        }
        let nr = self.ds.runs.len();
        let ns = self.ds.sensors.len();
        let rises: Vec<Vec<Vec<f64>>> = (0..nr).map(|r| self.rises(r)).collect();
        let mut basis: Vec<Vec<f64>> = Vec::new();
        if pcs > 0 && ns > 0 {
            let rows = self.fit_rows();
            let x = DMatrix::from_fn(rows.len(), ns, |i, j| rises[rows[i].0][j][rows[i].1]);
            let svd = x.svd(false, true);
            if let Some(vt) = svd.v_t {
                let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
                idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
                // each component oriented so that the machine warming up
                // (rises > 0) reads positive: a conductance to the coolant
                // then removes heat with a negative gain (`removes_heat`)
                basis = idx
                    .iter()
                    .take(pcs)
                    .map(|&i| {
                        let w: Vec<f64> = vt.row(i).iter().copied().collect();
                        let sign = if w.iter().sum::<f64>() < 0.0 {
                            -1.0
                        } else {
                            1.0
                        };
                        w.iter().map(|x| sign * x).collect()
                    })
                    .collect();
            }
        }
        self.switched = (0..nr)
            .map(|r| {
                let run = &self.ds.runs[r];
                let on: Vec<f64> = run
                    .rpm
                    .as_ref()
                    .map(|v| v.iter().map(|n| (n.abs() > 0.0) as u8 as f64).collect())
                    .unwrap_or_else(|| vec![0.0; run.rows()]);
                let mut v = vec![on.clone()];
                for w in &basis {
                    v.push(
                        (0..run.rows())
                            .map(|k| on[k] * (0..ns).map(|i| w[i] * rises[r][i][k]).sum::<f64>())
                            .collect(),
                    );
                }
                v
            })
            .collect();
    }

    pub fn cross(&self) -> bool {
        !self.ds.has_rpm
    }

    /// Whether the switched conductance's sign constraint is in force.
    pub(super) fn conductance_constrained(&self) -> bool {
        self.removes_heat && !self.cross() && self.switched.iter().any(|s| s.len() > 1)
    }

    /// Sensor rises (from each run's first valid value, gaps held).
    fn rises(&self, r: usize) -> Vec<Vec<f64>> {
        let ns = self.ds.sensors.len();
        (0..ns).map(|i| held_rise(&self.meas[r][i])).collect()
    }

    /// (run, row) of every fit row (not held out) of every run.
    fn fit_rows(&self) -> Vec<(usize, usize)> {
        self.ds
            .runs
            .iter()
            .enumerate()
            .flat_map(|(r, run)| {
                (0..run.rows())
                    .filter(|&k| !run.held[k])
                    .map(move |k| (r, k))
            })
            .collect()
    }

    /// For each output, the leading principal components (fit rows of all
    /// runs) of the sensors other than itself.
    fn temperature_drivers(&self) -> Vec<Vec<Vec<Vec<f64>>>> {
        let ns = self.ds.sensors.len();
        let rises: Vec<Vec<Vec<f64>>> = (0..self.ds.runs.len()).map(|r| self.rises(r)).collect();
        let no = self.outputs.len();
        let per_output: Vec<Vec<Vec<Vec<f64>>>> = (0..no)
            .into_par_iter()
            .map(|o| {
                let src: Vec<usize> = (0..ns).filter(|&i| i != o).collect();
                if src.is_empty() {
                    return vec![Vec::new(); self.ds.runs.len()];
                }
                let rows = self.fit_rows();
                let x = DMatrix::from_fn(rows.len(), src.len(), |i, j| {
                    rises[rows[i].0][src[j]][rows[i].1]
                });
                let pcs = DRIVER_PCS.min(src.len());
                let basis: Vec<Vec<f64>> = if src.len() <= pcs {
                    (0..src.len())
                        .map(|j| (0..src.len()).map(|i| (i == j) as u8 as f64).collect())
                        .collect()
                } else {
                    let svd = x.svd(false, true);
                    match svd.v_t {
                        Some(vt) => {
                            let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
                            idx.sort_by(|&a, &b| {
                                svd.singular_values[b].total_cmp(&svd.singular_values[a])
                            });
                            idx.iter()
                                .take(pcs)
                                .map(|&i| vt.row(i).iter().copied().collect())
                                .collect()
                        }
                        None => Vec::new(),
                    }
                };
                self.ds
                    .runs
                    .iter()
                    .enumerate()
                    .map(|(r, run)| {
                        basis
                            .iter()
                            .map(|w| {
                                (0..run.rows())
                                    .map(|k| {
                                        src.iter().zip(w).map(|(&i, wi)| wi * rises[r][i][k]).sum()
                                    })
                                    .collect()
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        // reorder to run → output → drivers
        (0..self.ds.runs.len())
            .map(|r| per_output.iter().map(|d| d[r].clone()).collect())
            .collect()
    }

    /// The input signals of run `r` (before the modal lags), with names.
    pub fn inputs(&self, r: usize, exponent: f64) -> Vec<(&'static str, Vec<f64>)> {
        let run = &self.ds.runs[r];
        let mut v = Vec::new();
        if let Some(rpm) = &run.rpm {
            v.push((
                "spindle",
                rpm.iter().map(|n| n.abs() / self.n_max).collect(),
            ));
            v.push((
                "spindle_friction",
                rpm.iter()
                    .map(|n| (n.abs() / self.n_max).powf(exponent))
                    .collect(),
            ));
        }
        if let (Some(rpm), Some(pw)) = (&run.rpm, self.steep) {
            v.push((
                "spindle_steep",
                rpm.iter()
                    .map(|n| (n.abs() / self.n_max).powf(pw))
                    .collect(),
            ));
        }
        if let Some(sw) = self.switched.get(r) {
            for u in sw {
                v.push(("switched", u.clone()));
            }
        }
        if let Some(f) = &run.feed {
            v.push(("feed", f.clone()));
        }
        if let Some(c) = &run.coolant {
            v.push(("coolant", c.clone()));
        }
        if let Some(a) = &run.ambient {
            let z = a.first().copied().unwrap_or(0.0);
            v.push(("ambient", a.iter().map(|x| x - z).collect()));
        }
        v
    }

    /// Regressor columns of output `o` in run `r` (all rows): the modal
    /// states of every input (plus, without rpm, the drivers directly), the
    /// run's level and free decays. Columns of other runs are zero there, so
    /// the caller lays runs out block-wise.
    pub fn columns(&self, st: &Structure, o: usize, r: usize) -> Columns {
        let run = &self.ds.runs[r];
        let dt = run.dt;
        let mut shared = Vec::new();
        let mut sigs = self.inputs(r, st.exponent);
        if self.cross() {
            for d in &self.drivers[r][o] {
                shared.push(d.clone());
                sigs.push(("driver", d.clone()));
            }
        }
        for (_, u) in &sigs {
            for &tau in &st.modes {
                shared.push(lag(u, dt, tau, 0.0));
            }
        }
        let t0 = run.time.first().copied().unwrap_or(0.0);
        let mut own = vec![vec![1.0; run.rows()]];
        // free decays only of modes that decay within the run: slower ones
        // would absorb any slow drift (and a run that starts far from rest
        // still has its faster modes)
        let span = run.time.last().copied().unwrap_or(t0) - t0;
        for &tau in st.modes.iter().filter(|&&tau| tau <= span / 3.0) {
            own.push(run.time.iter().map(|t| (-(t - t0) / tau).exp()).collect());
        }
        (shared, own)
    }

    /// Choose the speed exponent and the modes by BIC on the fit blocks
    /// (exponent first with two modes, then modes by forward selection).
    pub fn identify(&self) -> (Structure, ModelFit) {
        let dt_min = self
            .ds
            .runs
            .iter()
            .map(|r| r.dt)
            .fold(f64::INFINITY, f64::min);
        let grid: Vec<f64> = TAU_GRID
            .iter()
            .copied()
            .filter(|t| *t >= 2.0 * dt_min)
            .collect();
        let bic = |st: &Structure| -> (f64, ModelFit) {
            let f = self.fit(st, None, None);
            (f.bic(&self.outputs), f)
        };
        let exps: Vec<f64> = if self.ds.has_rpm {
            self.exponents.clone()
        } else {
            vec![1.0]
        };
        let pair = vec![
            grid.get(grid.len() / 3).copied().unwrap_or(1200.0),
            grid.last().copied().unwrap_or(9600.0),
        ];
        let exponent = exps
            .iter()
            .map(|&e| {
                (
                    e,
                    bic(&Structure {
                        modes: pair.clone(),
                        exponent: e,
                    })
                    .0,
                )
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(1.0, |x| x.0);
        let mut modes: Vec<f64> = Vec::new();
        let mut best: Option<(f64, ModelFit)> = None;
        while modes.len() < MAX_MODES {
            let tries: Vec<(f64, f64, ModelFit)> = grid
                .par_iter()
                .filter(|t| !modes.contains(t))
                .map(|&t| {
                    let mut m = modes.clone();
                    m.push(t);
                    m.sort_by(|a, b| a.total_cmp(b));
                    let (b, f) = bic(&Structure { modes: m, exponent });
                    (t, b, f)
                })
                .collect();
            let Some(top) = tries.into_iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                break;
            };
            if best.as_ref().is_some_and(|b| top.1 >= b.0) {
                break;
            }
            modes.push(top.0);
            modes.sort_by(|a, b| a.total_cmp(b));
            best = Some((top.1, top.2));
        }
        let st = Structure { modes, exponent };
        let fit = match best {
            Some((_, f)) => f,
            None => self.fit(&st, None, None),
        };
        (st, fit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tcomp_data::runcsv::Run;

    /// A two-node system (time constants 600 s and 4800 s) driven by speed
    /// steps, with white sensor noise: the identified model must find that
    /// order and leave noise-level held-out residuals.
    #[test]
    fn identifies_a_two_mode_network_to_noise_level() {
        let mut g = tcomp_numerics::rng::Rng::paired(9);
        let dt = 30.0;
        let n = 960; // 8 h
        let rpm: Vec<f64> = (0..n)
            .map(|k| [0.0, 6000.0, 3000.0, 9000.0, 0.0, 4500.0][(k / 80) % 6])
            .collect();
        let u: Vec<f64> = rpm.iter().map(|r| r / 9000.0).collect();
        let fast = lag(&u, dt, 600.0, 0.0);
        let slow = lag(&u, dt, 4800.0, 0.0);
        let mut run = Run::default();
        let col = |v: Vec<f64>| v.into_iter().map(Some).collect::<Vec<_>>();
        run.push_column("time_s", col((0..n).map(|k| k as f64 * dt).collect()))
            .unwrap();
        run.push_column("spindle_rpm", col(rpm.clone())).unwrap();
        let noise = 0.02;
        for (name, a, b) in [("T_a", 6.0, 2.0), ("T_b", 1.0, 4.0)] {
            let v = (0..n)
                .map(|k| 20.0 + a * fast[k] + b * slow[k] + noise * g.normal())
                .collect();
            run.push_column(name, col(v)).unwrap();
        }
        let ds = crate::diagnose::runs::load(&[("syn".into(), run)], 1500).unwrap();
        let p = Problem::new(&ds);
        let (st, fit) = p.identify();
        assert!(
            st.modes.len() >= 2 && st.modes.len() <= 4,
            "order {:?}",
            st.modes
        );
        assert!(
            st.modes.contains(&600.0) && st.modes.contains(&4800.0),
            "{:?}",
            st.modes
        );
        let (rms, _) = fit.gap_held(&p.outputs, false).unwrap();
        assert!(rms < 1.3 * noise, "held-out RMS {rms}");
    }
}

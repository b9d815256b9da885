//! Residual statistics, the candidate effects' parameterisations and
//! their fits (a grid, then Nelder–Mead or Brent from `optim.rs`).

use anyhow::Result;
use nalgebra::DVector;

use super::optim::{brent_in_cell, nelder_mead};
use crate::diagnose::runs::{Kind, Prepared};
use crate::sim::{apply_sensor_effects, simulate, Effect, Machine, SimOut};

/// Per (run, channel) sums on the fit rows and the held-out rows.
#[derive(Clone, Debug)]
pub struct ChStats {
    pub run: usize,
    pub ch: usize,
    pub is_disp: bool,
    pub s: f64,
    pub sse_fit: f64,
    pub n_fit: usize,
    pub sse_held: f64,
    pub n_held: usize,
    pub peak_held: f64,
}

#[derive(Clone, Debug)]
pub struct Stats {
    pub ch: Vec<ChStats>,
}

impl Stats {
    /// −2·log-likelihood (up to a constant) of the fit rows with an unknown
    /// variance per channel: Σ n·ln(SSE/n + (0.1·s)²).
    pub fn j_fit(&self) -> f64 {
        self.ch
            .iter()
            .filter(|c| c.n_fit > 0)
            .map(|c| {
                let n = c.n_fit as f64;
                n * (c.sse_fit / n + (0.1 * c.s).powi(2)).ln()
            })
            .sum()
    }

    pub fn n_fit(&self) -> usize {
        self.ch.iter().map(|c| c.n_fit).sum()
    }

    /// Held-out mean square gap in units of each channel's noise variance
    /// (≈ 1 when only noise is left).
    pub fn m_held(&self) -> f64 {
        let v: Vec<f64> = self
            .ch
            .iter()
            .filter(|c| c.n_held > 0)
            .map(|c| c.sse_held / c.n_held as f64 / (c.s * c.s))
            .collect();
        if v.is_empty() {
            return f64::NAN;
        }
        v.iter().sum::<f64>() / v.len() as f64
    }

    /// Held-out RMS and peak over the displacement (`true`) or temperature channels.
    pub fn gap_held(&self, disp: bool) -> Option<(f64, f64)> {
        let cs: Vec<&ChStats> = self
            .ch
            .iter()
            .filter(|c| c.is_disp == disp && c.n_held > 0)
            .collect();
        if cs.is_empty() {
            return None;
        }
        let sse: f64 = cs.iter().map(|c| c.sse_held).sum();
        let n: usize = cs.iter().map(|c| c.n_held).sum();
        let peak = cs.iter().map(|c| c.peak_held).fold(0.0, f64::max);
        Some(((sse / n as f64).sqrt(), peak))
    }
}

/// Residuals: run → channel → row.
pub(crate) type Residuals = Vec<Vec<Vec<f64>>>;

/// Which design values ended on which bound in a fit's last projection
/// (−1 lo, +1 hi, 0 free; empty: the calibrated nominal's): the next box
/// QP starts there. Same optimum, fewer steps (a drift pair: 13 instead
/// of 68); each fit keeps its own, so no answer depends on the threads.
pub type ActiveSet = Vec<i8>;

/// A correction every evaluation's residuals get: the calibration's
/// bounded freedom (`freedom.rs`), left to the null and every candidate.
pub trait Projection: Sync {
    fn project(&self, res: &mut [Vec<Vec<f64>>]);
    /// The fit-row SSE per channel (in `stats_of`'s order) the projected
    /// residuals would have, without forming them (a fit's criterion needs
    /// no held-out row); None: project and sum instead.
    fn fit_sse(&self, _res: &[Vec<Vec<f64>>]) -> Option<Vec<f64>> {
        None
    }
    /// `fit_sse` of several residual sets at once (a projection that reads
    /// a large matrix per set can read it once for all), each solve
    /// starting from the last one's `start`.
    fn fit_sse_many(
        &self,
        sets: &[&[Vec<Vec<f64>>]],
        _start: &mut ActiveSet,
    ) -> Vec<Option<Vec<f64>>> {
        sets.iter().map(|r| self.fit_sse(r)).collect()
    }
    /// Per set and channel the sums the fit SSE is computed from (B̃ᵀr),
    /// linear in the residuals: a family of trials that are linear
    /// combinations of a few sets (`drift_family.rs`) combines them
    /// instead of passing over B̃ per trial. None: not available.
    fn pull_products(&self, _sets: &[&[Vec<Vec<f64>>]]) -> Option<Vec<Vec<DVector<f64>>>> {
        None
    }
    /// `fit_sse` from a set's B̃ᵀr per channel and its Σ r² per channel.
    fn fit_sse_from(
        &self,
        _h: &[DVector<f64>],
        _rr: &[f64],
        _start: &mut ActiveSet,
    ) -> Option<Vec<f64>> {
        None
    }
}

/// Simulates the prepared runs with a set of effects.
pub struct Evaluator<'a> {
    pub m: &'a Machine,
    pub runs: &'a [Prepared],
    /// The nominal output per run (sensor effects are applied to it
    /// without re-simulating the network).
    pub nominal: Vec<SimOut>,
    /// The calibration's bounded freedom, left to every evaluation (None:
    /// the machine file taken as exact).
    pub freedom: Option<&'a dyn Projection>,
}

impl<'a> Evaluator<'a> {
    pub fn new(m: &'a Machine, runs: &'a [Prepared]) -> Result<Evaluator<'a>> {
        let nominal = runs
            .iter()
            .map(|p| simulate(m, &p.inputs, &[], 1))
            .collect::<Result<Vec<_>>>()?;
        Ok(Evaluator {
            m,
            runs,
            nominal,
            freedom: None,
        })
    }

    /// The same evaluator with the calibration's freedom left to every fit.
    pub fn with_freedom(mut self, f: Option<&'a dyn Projection>) -> Evaluator<'a> {
        self.freedom = f;
        self
    }

    /// Residuals measured − simulated: run → channel → row (NaN where missing).
    pub fn residuals(&self, effects: &[Effect]) -> Result<Vec<Vec<Vec<f64>>>> {
        let mut all = self.raw_residuals(effects)?;
        if let Some(f) = self.freedom {
            f.project(&mut all);
        }
        Ok(all)
    }

    /// The residuals before the calibration's freedom and after it (where
    /// an effect acts, and what it leaves), from one simulation.
    pub(crate) fn raw_and_residuals(&self, effects: &[Effect]) -> Result<(Residuals, Residuals)> {
        let raw = self.raw_residuals(effects)?;
        let mut all = raw.clone();
        if let Some(f) = self.freedom {
            f.project(&mut all);
        }
        Ok((raw, all))
    }

    /// The fit-rows criterion of a set of effects (`stats(..).j_fit()`),
    /// without projecting the held-out rows when the freedom can say the
    /// fit rows' SSE directly: the fits' objective, evaluated ≈ 1000 times
    /// per diagnosis.
    pub fn j_fit(&self, effects: &[Effect]) -> Result<f64> {
        let raw = self.raw_residuals(effects)?;
        let fresh = &mut ActiveSet::new();
        Ok(j_fit_of_raws(self.runs, self.freedom, vec![Some(raw)], fresh)[0])
    }

    /// `j_fit` of several sets of effects (∞ where one cannot be
    /// simulated): a grid's trials share the freedom's pass, `BATCH` at a
    /// time (their residual sets, ≈ 0.5 MB each, are held at once).
    pub fn j_fit_many(&self, sets: &[Vec<Effect>], start: &mut ActiveSet) -> Vec<f64> {
        sets.chunks(BATCH)
            .flat_map(|chunk| {
                let raws = chunk.iter().map(|e| self.raw_residuals(e).ok()).collect();
                j_fit_of_raws(self.runs, self.freedom, raws, start)
            })
            .collect()
    }

    /// Residuals before the calibration's freedom.
    pub(crate) fn raw_residuals(&self, effects: &[Effect]) -> Result<Vec<Vec<Vec<f64>>>> {
        let mut all = Vec::with_capacity(self.runs.len());
        for p in self.runs {
            // an effect located in one run (a sensor step) acts there only
            let mine: Vec<Effect> = effects
                .iter()
                .filter(|e| match e {
                    Effect::SensorOffset { run: Some(r), .. } => *r == p.name,
                    _ => true,
                })
                .cloned()
                .collect();
            let out = if mine.iter().all(Effect::is_sensor_only) {
                let mut o = self.nominal[all.len()].clone();
                apply_sensor_effects(self.m, &mine, &mut o, p.inputs.dt)?;
                o
            } else {
                simulate(self.m, &p.inputs, &mine, 1)?
            };
            let mut rr = Vec::with_capacity(p.channels.len());
            for c in &p.channels {
                let sim = match c.kind {
                    Kind::Temp(i) => &out.temps[i],
                    Kind::Disp(i) => &out.disp[i],
                };
                rr.push(c.meas.iter().zip(sim).map(|(a, b)| a - b).collect());
            }
            all.push(rr);
        }
        Ok(all)
    }

    pub fn stats_of(&self, res: &[Vec<Vec<f64>>]) -> Stats {
        stats_of(self.runs, res)
    }

    pub fn stats(&self, effects: &[Effect]) -> Result<Stats> {
        Ok(self.stats_of(&self.residuals(effects)?))
    }
}

/// Per-channel sums of residuals of `runs` on the fit and held-out rows.
pub(crate) fn stats_of(runs: &[Prepared], res: &[Vec<Vec<f64>>]) -> Stats {
    let mut ch = Vec::new();
    for (ri, (p, rr)) in runs.iter().zip(res).enumerate() {
        for (ci, (c, r)) in p.channels.iter().zip(rr).enumerate() {
            let mut s = ChStats {
                run: ri,
                ch: ci,
                is_disp: matches!(c.kind, Kind::Disp(_)),
                s: c.s,
                sse_fit: 0.0,
                n_fit: 0,
                sse_held: 0.0,
                n_held: 0,
                peak_held: 0.0,
            };
            for (k, v) in r.iter().enumerate() {
                if !v.is_finite() {
                    continue;
                }
                if p.is_fit(k) {
                    s.sse_fit += v * v;
                    s.n_fit += 1;
                } else {
                    s.sse_held += v * v;
                    s.n_held += 1;
                    s.peak_held = s.peak_held.max(v.abs());
                }
            }
            ch.push(s);
        }
    }
    Stats { ch }
}

/// `stats_of` with only what `Stats::j_fit` reads besides the SSE (fit
/// rows counted, noise): when the freedom gives the fit rows' SSE, the
/// criterion needs no sums of squares (a row pass per trial, ≈ 5 % of a
/// diagnosis).
fn fit_counts(runs: &[Prepared], res: &[Vec<Vec<f64>>]) -> Stats {
    let mut ch = Vec::new();
    for (ri, (p, rr)) in runs.iter().zip(res).enumerate() {
        for (ci, (c, r)) in p.channels.iter().zip(rr).enumerate() {
            let n_fit = r
                .iter()
                .zip(&p.held)
                .filter(|(v, held)| !**held && v.is_finite())
                .count();
            ch.push(ChStats {
                run: ri,
                ch: ci,
                is_disp: matches!(c.kind, Kind::Disp(_)),
                s: c.s,
                sse_fit: 0.0,
                n_fit,
                sse_held: 0.0,
                n_held: 0,
                peak_held: 0.0,
            });
        }
    }
    Stats { ch }
}

/// The fit criterion of residual sets of `runs` before the freedom `f`
/// (another machine's residuals too, as a release's line search has
/// them; ∞ for a set that could not be simulated); the freedom's pass
/// over B̃ shared by all of them.
pub(crate) fn j_fit_of_raws(
    runs: &[Prepared],
    f: Option<&dyn Projection>,
    raws: Vec<Option<Residuals>>,
    start: &mut ActiveSet,
) -> Vec<f64> {
    let simulated: Vec<bool> = raws.iter().map(Option::is_some).collect();
    let mut raws: Vec<Residuals> = raws.into_iter().flatten().collect();
    let js: Vec<f64> = match f {
        None => raws.iter().map(|r| stats_of(runs, r).j_fit()).collect(),
        Some(f) => {
            let refs: Vec<&[Vec<Vec<f64>>]> = raws.iter().map(|r| r.as_slice()).collect();
            let sses = f.fit_sse_many(&refs, start);
            raws.iter_mut()
                .zip(sses)
                .map(|(raw, sse)| match sse {
                    Some(sse) => {
                        let mut st = fit_counts(runs, raw);
                        for (c, s) in st.ch.iter_mut().zip(sse) {
                            c.sse_fit = s;
                        }
                        st.j_fit()
                    }
                    None => {
                        f.project(raw);
                        stats_of(runs, raw).j_fit()
                    }
                })
                .collect()
        }
    };
    let mut js = js.into_iter();
    simulated
        .into_iter()
        .map(|s| {
            if s {
                js.next().unwrap_or(f64::INFINITY)
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// One fitted parameter: physical bounds, log or linear mapping from u ∈ [0, 1].
#[derive(Clone, Copy, Debug)]
pub struct Param {
    // Read by nobody since `effect_fit` left the public API (issue 48):
    // kept, moves only.
    #[allow(dead_code)]
    pub name: &'static str,
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
}

// Names kept from when `effect_fit` was public API (clippy's naming rule
// spared exported items); renaming is not part of issue 48's moves.
#[allow(clippy::wrong_self_convention)]
impl Param {
    pub fn from_u(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        if self.log {
            (self.lo.ln() + u * (self.hi.ln() - self.lo.ln())).exp()
        } else {
            self.lo + u * (self.hi - self.lo)
        }
    }
    pub fn to_u(&self, v: f64) -> f64 {
        let u = if self.log {
            (v.max(self.lo).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        };
        u.clamp(0.0, 1.0)
    }
}

const fn p(name: &'static str, lo: f64, hi: f64, log: bool) -> Param {
    Param { name, lo, hi, log }
}

/// The fitted parameters of each candidate (others keep their defaults:
/// the chiller sawtooth is not fitted, it averages out).
pub fn params_of(kind: &str) -> Vec<Param> {
    match kind {
        "convection" => vec![p("h", 0.3, 60.0, true)],
        "ambient_drift" => vec![
            p("amp_c", 0.0, 5.0, false),
            p("phase_h", 0.0, 24.0, false),
            p("rate_c_per_h", -1.0, 1.0, false),
        ],
        "sensor_lag" => vec![p("tau_s", 3.0, 2000.0, true)],
        "chiller" => vec![
            p("band_c", 0.1, 3.0, false),
            p("power_w", 50.0, 20000.0, true),
            p("load_frac", 0.05, 0.95, false),
        ],
        "bearing_nonlinear" => vec![p("k_w", 0.5, 400.0, true), p("p", 1.1, 3.5, false)],
        "coolant" => vec![
            p("g_w_per_k", 0.3, 150.0, true),
            p("offset_c", -10.0, 5.0, false),
        ],
        "ballscrew" => vec![p("k_w", 1.0, 2000.0, true)],
        "bending" => vec![p("k_um_per_k", -20.0, 20.0, false)],
        "sensor_offset" => vec![p("offset_c", -5.0, 5.0, false)],
        _ => vec![],
    }
}

/// Build an effect from physical parameter values (`c` places the sensor
/// effects: which sensor, from when, in which run).
pub fn build(kind: &str, v: &[f64], c: &Cand) -> Effect {
    match kind {
        "convection" => Effect::Convection { h_w_per_m2k: v[0] },
        "ambient_drift" => Effect::AmbientDrift {
            amp_c: v[0],
            phase_h: v[1],
            rate_c_per_h: v[2],
            period_h: 24.0,
        },
        "sensor_lag" => Effect::SensorLag {
            tau_s: v[0],
            sensor: (!c.sensor.is_empty()).then(|| c.sensor.clone()),
        },
        "chiller" => Effect::Chiller {
            band_c: v[0],
            power_w: v[1],
            load_frac: v[2],
        },
        "bearing_nonlinear" => Effect::BearingNonlinear {
            k_w: v[0],
            p: v[1],
            node: (!c.node.is_empty()).then(|| c.node.clone()),
        },
        "coolant" => Effect::Coolant {
            g_w_per_k: v[0],
            offset_c: v[1],
            amp_c: 0.0,
            period_s: 900.0,
        },
        "ballscrew" => Effect::Ballscrew { k_w: v[0] },
        "bending" => Effect::Bending { k_um_per_k: v[0] },
        _ => Effect::SensorOffset {
            sensor: c.sensor.clone(),
            offset_c: v[0],
            at_s: c.at_s,
            run: c.run.clone(),
        },
    }
}

/// A candidate: one effect kind and, for the sensor effects, where it was
/// located (the sensor; for a step also its onset and run).
#[derive(Clone, Debug, Default)]
pub struct Cand {
    pub kind: &'static str,
    pub sensor: String,
    pub at_s: f64,
    pub run: Option<String>,
    /// The node a located heat effect acts on (empty: all its sites).
    pub node: String,
    /// Start values (physical) estimated from the data, else a grid.
    pub init: Vec<f64>,
}

impl Cand {
    pub fn new(kind: &'static str) -> Cand {
        Cand {
            kind,
            ..Cand::default()
        }
    }

    /// Choices made when locating it (sensor, onset, run), counted as
    /// parameters by BIC.
    pub fn located(&self) -> usize {
        usize::from(!self.sensor.is_empty())
            + usize::from(!self.node.is_empty())
            + usize::from(self.at_s > 0.0)
            + usize::from(self.run.is_some())
    }
}

/// Turn a joint u-vector into effects.
pub fn effects_of(cands: &[Cand], u: &[f64]) -> Vec<Effect> {
    let mut out = Vec::new();
    let mut i = 0;
    for c in cands {
        let ps = params_of(c.kind);
        let v: Vec<f64> = ps
            .iter()
            .enumerate()
            .map(|(j, p)| p.from_u(u[i + j]))
            .collect();
        i += ps.len();
        out.push(build(c.kind, &v, c));
    }
    out
}

/// Result of fitting a set of candidates.
#[derive(Clone, Debug)]
pub struct FitResult {
    pub cands: Vec<Cand>,
    pub u: Vec<f64>,
    pub effects: Vec<Effect>,
    pub j: f64,
    pub k: usize,
    /// Simulations the fit ran (one per trial, but those of a `TrialFn`'s
    /// set-up where one gives the trials).
    pub evals: usize,
}

/// Fit candidates jointly: a coarse grid (when no start is given) then
/// Nelder–Mead, minimising the fit-rows criterion.
pub fn fit_cands(
    ev: &Evaluator,
    cands: &[Cand],
    start: Option<Vec<f64>>,
    budget: usize,
) -> FitResult {
    fit_cands_with(ev, cands, start, budget, None)
}

/// A trial's criterion at a point of the fit's unit cube computed without
/// a simulation (`drift_family.rs`), and the simulations it took to set up.
pub type TrialFn<'f> = (&'f dyn Fn(&[f64]) -> f64, usize);

/// `fit_cands`, its trials given by `trial` when there is one.
pub fn fit_cands_with(
    ev: &Evaluator,
    cands: &[Cand],
    start: Option<Vec<f64>>,
    budget: usize,
    trial: Option<TrialFn>,
) -> FitResult {
    let d: usize = cands.iter().map(|c| params_of(c.kind).len()).sum();
    let mut active = ActiveSet::new();
    let mut obj = |us: &[Vec<f64>]| -> Vec<f64> {
        match trial {
            Some((f, _)) => us.iter().map(|u| f(u)).collect(),
            None => j_fit_at(ev, cands, us, &mut active),
        }
    };
    let mut evals = 0;
    let init = (cands.len() == 1 && cands[0].init.len() == d).then(|| {
        params_of(cands[0].kind)
            .iter()
            .zip(&cands[0].init)
            .map(|(p, v)| p.to_u(*v))
            .collect::<Vec<f64>>()
    });
    let nm_step = 0.5 / (d as f64 + 1.0).max(2.0);
    let (u, j, e) = match start.or(init) {
        Some(x0) => nelder_mead(&mut obj, &x0, nm_step, budget),
        None => {
            let g: usize = match d {
                1 => 9,
                2 => 4,
                _ => 3,
            };
            let (u, ju, n) = best_on_grid(&mut obj, &[], d, g);
            evals += n;
            if d == 1 {
                // one parameter: Brent's method in the grid's best cell
                // and its neighbours (≈ 15 trials where Nelder–Mead
                // takes ≈ 30)
                brent_in_cell(&mut obj, (u[0], ju), 1.0 / g as f64, budget)
            } else {
                nelder_mead(&mut obj, &u, nm_step, budget)
            }
        }
    };
    evals += e;
    if let Some((_, sims)) = trial {
        // its trials ran no simulation
        evals = sims;
    }
    FitResult {
        cands: cands.to_vec(),
        effects: effects_of(cands, &u),
        u,
        j,
        k: d + cands.iter().map(Cand::located).sum::<usize>(),
        evals,
    }
}

/// Trials evaluated together: their residual sets (≈ 0.5 MB each) are
/// held at once, and the freedom reads B̃ once for all of them.
const BATCH: usize = 9;

/// The fit criterion of `cands` at each of `us` (∞ where one cannot be
/// simulated), in batches sharing the freedom's pass.
fn j_fit_at(ev: &Evaluator, cands: &[Cand], us: &[Vec<f64>], start: &mut ActiveSet) -> Vec<f64> {
    let sets: Vec<Vec<Effect>> = us.iter().map(|u| effects_of(cands, u)).collect();
    ev.j_fit_many(&sets, start)
}

/// The best point of a g^d grid of cell centres over the last d
/// parameters of `cands` (the first ones fixed at `fixed`): the point
/// (last d only), its value and the evaluations spent. The first of
/// equal values wins.
fn best_on_grid(
    obj: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
    fixed: &[f64],
    d: usize,
    g: usize,
) -> (Vec<f64>, f64, usize) {
    let pts: Vec<Vec<f64>> = (0..g.pow(d as u32))
        .map(|idx| {
            let mut r = idx;
            let ua = (0..d).map(|_| {
                let i = r % g;
                r /= g;
                (i as f64 + 0.5) / g as f64
            });
            fixed.iter().copied().chain(ua).collect()
        })
        .collect();
    let vals = obj(&pts);
    let mut best = (vec![0.5; d], f64::INFINITY);
    for (u, v) in pts.iter().zip(vals) {
        if v < best.1 {
            best = (u[fixed.len()..].to_vec(), v);
        }
    }
    (best.0, best.1, pts.len())
}

/// Add one candidate to an already fitted set: a coarse grid over the new
/// parameters with the base fixed, then a joint Nelder–Mead polish.
pub fn fit_added(ev: &Evaluator, base: &FitResult, add: &Cand, budget: usize) -> FitResult {
    let mut cands = base.cands.clone();
    cands.push(add.clone());
    let d = params_of(add.kind).len();
    let g: usize = match d {
        1 => 7,
        2 => 3,
        _ => 2,
    };
    let mut start = ActiveSet::new();
    let (ua, _, evals) = best_on_grid(
        &mut |us| j_fit_at(ev, &cands, us, &mut start),
        &base.u,
        d,
        g,
    );
    let start: Vec<f64> = base.u.iter().chain(&ua).copied().collect();
    let mut r = fit_cands(ev, &cands, Some(start), budget);
    r.evals += evals;
    r
}

/// `f` over `items` in parallel (rayon), keeping the order; `threads` caps
/// the pool when it is smaller than rayon's.
pub(crate) fn par_map<T: Sync, R: Send, F: Fn(&T) -> R + Sync + Send>(
    items: &[T],
    threads: usize,
    f: F,
) -> Vec<R> {
    use rayon::prelude::*;
    let run = || items.par_iter().map(&f).collect();
    match rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
    {
        Ok(pool) if threads < rayon::current_num_threads() => pool.install(run),
        _ => run(),
    }
}

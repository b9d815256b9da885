//! The calibration's freedom, left to every candidate: the nominal is the
//! machine file calibrated within its tolerances (`calibrate.rs`), and an
//! effect is judged against it with the SAME freedom — each design value may
//! still move, but only inside its tolerance. Re-calibrating the ≈100
//! design values for every trial of every candidate would cost ≈100
//! simulations each, so the freedom is linearised at the calibrated values
//! (the sensitivity of every channel to every design value, one simulation
//! per value, computed once) and, for every trial, the design values'
//! correction is a box-constrained least-squares fit on the fit rows
//! (exact: an active set, `boxqp.rs`) whose box is the tolerance: a
//! candidate can absorb no more of a wrong design than the null hypothesis
//! could.
//!
//! Speed: that projection runs for every evaluation of every candidate
//! (≈ 800 per diagnosis). S is compressed to `REL_TOL` (relative
//! Frobenius norm in the criterion's weights) twice over: the ≈ 95
//! strongly collinear columns are kept in the basis of the eigenvectors V
//! of SᵀDS (D: the channels' weights on every row) that carry all but
//! `REL_TOL`² of its trace, and each column of SV is kept on a coarser
//! time grid (`knots.rs`) read by linear interpolation where that is as
//! close (on the benches' 10 s runs it is not: every row is kept).
//! `REL_TOL` is 10⁻⁶, not the 10⁻³ a forward difference's own error
//! would suggest: what is left once an effect is explained lies in the
//! small directions, and 10⁻³ moved the criterion by ≈ 13 and the
//! held-out gap by 8 % there (`freedom/tests.rs`; 10⁻⁶: ≤ 0.1).
//! A fit's criterion needs only the fit rows' SSE per channel, which
//! `fit_sse` gives from B̃ᵀB̃ and B̃ᵀr without forming the corrected
//! residuals. The pass over B̃ (≈ 35 k rows × ≈ 95 directions) bounds
//! the time, by reading it: B̃ is kept in f32, each channel's block in its
//! own ≈ 10–40 leading directions (`channel_basis.rs`, to 10⁻⁷: the pass
//! reads ≈ 23 of 95 columns per row on the benches), and B̃ᵀr is the calibrated
//! nominal's plus B̃ᵀ(r − r₀) over the knots where r changed (a sensor
//! effect changes one channel, a step only the rows after it); the box
//! QP's steps solve the held values' multipliers from A⁻¹, computed once,
//! and start from the fit's last trial's active set (`ActiveSet`), the
//! calibrated nominal's for a fit's first (a trial's optimum is near
//! both: ≈ 12–20 steps instead of ≈ 54 from nothing).
//! `freedom/tests.rs` checks the compressed freedom against the full one.

mod channel_basis;
mod knots;
mod timing;

use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use anyhow::Result;
use nalgebra::{DMatrix, DVector};

use super::boxqp::{box_qp_exact, box_qp_exact_inv_from};
use super::knobs::{apply, Knob};
use crate::diagnose::effects::{par_map, ActiveSet, Evaluator, FitResult, Projection};
use crate::diagnose::runs::Prepared;
use crate::sim::Machine;
use channel_basis::ChannelBasis;
use knots::Knots;
use tcomp_numerics::linalg::{dot, dot_many, leading_eigenvectors};
pub(crate) use timing::timing;

/// The linearised, bounded calibration freedom on the full grid.
pub struct Freedom {
    /// K: the sensitivities in the kept directions (B = SV) at the knots,
    /// one column per direction, column-major; B̃ = H K on every row (H:
    /// `knots`). Stored in f32 (every product sums in f64): the passes
    /// over it are bound by reading it, and B̃ᵀB̃ is formed from the same
    /// rounded values, so the criterion stays consistent; the rounding
    /// (≈ 3·10⁻⁸ relative) is far inside `REL_TOL`.
    knots_b: Vec<f32>,
    knots: Knots,
    /// Per flattened row: its first knot and the next knot's weight
    /// (`Knots::row_weights`; precomputed: the pass runs per evaluation).
    row_knot: Vec<u32>,
    row_wb: Vec<f64>,
    /// Per channel (in `stats_of`'s order): its knots, weight, B̃ᵀB̃ over
    /// its fit rows.
    chans: Vec<FitChannel>,
    /// Per flattened row: is it a fit row; its channel.
    fit: Vec<bool>,
    /// Per flattened row: was the calibrated nominal's residual missing.
    missing: Vec<bool>,
    /// The calibrated nominal's residual per flattened row and its B̃ᵀr
    /// per channel: an evaluation's B̃ᵀr is this plus B̃ᵀ of what changed,
    /// read only over the knots it changed (a sensor effect touches one
    /// channel, a step only the rows after it).
    base_r: Vec<f64>,
    base_h: Vec<DVector<f64>>,
    /// Knot rows of B̃ read, and rows that could have been, for
    /// `TCOMP_DIAG_TIMING`.
    knots_read: AtomicU64,
    knots_all: AtomicU64,
    /// Kept directions (knobs × directions).
    v: DMatrix<f64>,
    /// Calibrated θ, its bounds and prior precision per knob.
    theta: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    prec: Vec<f64>,
    /// SᵀWS over the fit rows plus the prior precision.
    a: DMatrix<f64>,
    /// Its inverse (None: not positive definite): the unconstrained
    /// optimum starts the box QP, and its steps solve the held values.
    a_inv: Option<DMatrix<f64>>,
    /// Which bound each knob ends on in the calibrated nominal's own
    /// projection (−1 lo, +1 hi, 0 free): every projection's box QP
    /// starts from that active set (the same optimum, fewer steps).
    side0: Vec<i8>,
    /// Projections done and box-QP steps, for `TCOMP_DIAG_TIMING`
    /// (printed when the freedom is dropped).
    calls: AtomicU64,
    sweeps: AtomicU64,
    ns: AtomicU64,
}

/// `dot(a, z)` for every z, four (or two) at a time through `dot_many`.
fn dots(a: &[f32], zs: &[&[f64]]) -> Vec<f64> {
    let mut out = Vec::with_capacity(zs.len());
    let mut rest = zs;
    while !rest.is_empty() {
        match rest {
            [z0, z1, z2, z3, ..] => {
                out.extend(dot_many(a, [*z0, *z1, *z2, *z3]));
                rest = &rest[4..];
            }
            [z0, z1, ..] => {
                out.extend(dot_many(a, [*z0, *z1]));
                rest = &rest[2..];
            }
            [z0, ..] => {
                out.push(dot(a, z0));
                rest = &rest[1..];
            }
            [] => {}
        }
    }
    out
}

/// Per channel B̃ᵀr, and Σ r² per channel (None: a row missing that the
/// calibrated nominal had).
type Products = (Vec<DVector<f64>>, Option<Vec<f64>>);

/// One residual set against the calibrated nominal's (`Freedom::diff_of`).
struct Diff {
    /// Hᵀ(r − r₀) at the knots (one more: a knot row's next one).
    z: Vec<f64>,
    /// Σ r² per channel over the finite fit rows.
    rr: Vec<f64>,
    /// No row missing that the nominal had.
    consistent: bool,
    /// Per channel: the knots z touches, [first, end).
    touched: Vec<(usize, usize)>,
}

/// ∂(simulated channel)/∂θ of one knob: run → channel → row.
type Column = Vec<Vec<Vec<f64>>>;

/// The weight per channel (fit rows), as the criterion has it.
fn channel_weights(ev: &Evaluator, r0: &[Vec<Vec<f64>>]) -> Vec<f64> {
    ev.stats_of(r0)
        .ch
        .iter()
        .map(|c| 1.0 / (c.sse_fit / c.n_fit.max(1) as f64 + (0.1 * c.s).powi(2)))
        .collect()
}

/// The sensitivity of every channel to one knob by a forward difference.
fn sensitivity(
    m: &Machine,
    ks: &[Knob],
    theta: &[f64],
    ps: &[Prepared],
    r0: &[Vec<Vec<f64>>],
    i: usize,
) -> Result<Column> {
    let h = 0.02;
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
}

/// The kept directions of S: eigenvectors of SᵀDS (D: `wall` per row),
/// largest eigenvalue first, leaving out the smallest ones whose
/// eigenvalues sum to at most `rel_tol`² of the trace (‖D(S − SVVᵀ)‖ ≤
/// `rel_tol`·‖DS‖, Frobenius); every direction when `rel_tol` is 0.
pub(crate) fn directions(sens: &DMatrix<f64>, wall: &[f64], rel_tol: f64) -> DMatrix<f64> {
    let nk = sens.ncols();
    let sd = DMatrix::from_fn(sens.nrows(), nk, |r, c| sens[(r, c)] * wall[r].sqrt());
    // `transpose() *` goes through matrixmultiply's gemm; `tr_mul` is a
    // scalar loop, and this product (rows × knobs²) was a third of the
    // freedom's set-up
    let g = sd.transpose() * &sd;
    let (v, dropped) = leading_eigenvectors(g, rel_tol, 1);
    if timing() {
        eprintln!(
            "diagnose timing: {} of {nk} directions kept (dropped {dropped:.1e} of the trace)",
            v.ncols()
        );
    }
    v
}

/// The compression's error budget, relative (see the module comment).
pub const REL_TOL: f64 = 1e-6;

/// Each channel's block of B̃ kept to this (relative Frobenius,
/// `channel_basis.rs`) for the pass: a tenth of `REL_TOL`, scaled with it
/// (0: every direction).
const PASS_TOL: f64 = 1e-7;

/// What the fit rows need, per channel (in `stats_of`'s order).
struct FitChannel {
    /// Its weight in the criterion.
    w: f64,
    /// B̃ᵀB̃ over its fit rows (missing rows left out).
    m: DMatrix<f64>,
    /// Its knot ranges that touch a fit row, in its own few directions:
    /// B̃ᵀr reads only these (the held-out blocks are ≈ 40 % of the rows,
    /// and the pass is bound by reading B̃).
    basis: ChannelBasis,
}

/// Per flattened row: the channel's weight, fit or not, missing or not;
/// per channel: its rows and weight.
struct Rows {
    wall: Vec<f64>,
    fit: Vec<bool>,
    missing: Vec<bool>,
    lens: Vec<usize>,
    w: Vec<f64>,
}

fn rows_of(ps: &[Prepared], r0: &[Vec<Vec<f64>>], w: &[f64]) -> Rows {
    let mut o = Rows {
        wall: Vec::new(),
        fit: Vec::new(),
        missing: Vec::new(),
        lens: Vec::new(),
        w: w.to_vec(),
    };
    let mut ci = 0;
    for (p, rr) in ps.iter().zip(r0) {
        for ch in rr {
            for (k, v) in ch.iter().enumerate() {
                o.wall.push(w[ci]);
                o.fit.push(p.is_fit(k));
                o.missing.push(!v.is_finite());
            }
            o.lens.push(ch.len());
            ci += 1;
        }
    }
    o
}

impl Freedom {
    /// Sensitivities at the calibrated θ (one simulation per knob),
    /// compressed to `REL_TOL`.
    pub(crate) fn new(
        m: &Machine,
        ks: &[Knob],
        theta: &[f64],
        ps: &[Prepared],
        threads: usize,
    ) -> Result<Freedom> {
        Freedom::with_tol(m, ks, theta, ps, threads, REL_TOL)
    }

    /// The same compressed to `rel_tol` (0: every direction, every row).
    pub(crate) fn with_tol(
        m: &Machine,
        ks: &[Knob],
        theta: &[f64],
        ps: &[Prepared],
        threads: usize,
        rel_tol: f64,
    ) -> Result<Freedom> {
        let t0 = std::time::Instant::now();
        let cal = apply(m, ks, theta);
        let ev = Evaluator::new(&cal, ps)?;
        let r0 = ev.residuals(&[])?;
        let rows = rows_of(ps, &r0, &channel_weights(&ev, &r0));
        let idx: Vec<usize> = (0..ks.len()).collect();
        let cols = par_map(&idx, threads, |&i| sensitivity(m, ks, theta, ps, &r0, i))
            .into_iter()
            .collect::<Result<Vec<_>>>()?;
        let nk = ks.len();
        let n_all = rows.wall.len();
        let mut sens = DMatrix::zeros(n_all, nk);
        for (i, col) in cols.iter().enumerate() {
            let mut dst = sens.column_mut(i);
            let mut r = 0;
            for ch in col.iter().flatten() {
                dst.rows_mut(r, ch.len()).copy_from_slice(ch);
                r += ch.len();
            }
        }
        drop(cols);
        let v = directions(&sens, &rows.wall, rel_tol);
        let basis = &sens * &v;
        drop(sens);
        let (knots, err) = knots::choose(&basis, &rows.lens, &rows.wall, rel_tol);
        let mut knots_b = knots.sample(&basis);
        drop(basis);
        knots_b.apply(|v| *v = *v as f32 as f64);
        let bases: Vec<ChannelBasis> = fit_spans(&knots, &rows)
            .iter()
            .map(|sp| ChannelBasis::truncate(&mut knots_b, sp, PASS_TOL * rel_tol / REL_TOL))
            .collect();
        let chans = fit_channels(&knots, &knots_b, &rows, bases);
        // SᵀWS ≈ V (Σ w B̃ᵀB̃) Vᵀ on the fit rows
        let nd = v.ncols();
        let mut bwb = DMatrix::zeros(nd, nd);
        for c in &chans {
            bwb += &c.m * c.w;
        }
        let mut a = &v * bwb * v.transpose();
        // exactly symmetric (the solver reads columns as rows)
        a = (&a + a.transpose()) * 0.5;
        let prec: Vec<f64> = ks.iter().map(|k| 1.0 / k.sigma().powi(2)).collect();
        for i in 0..nk {
            a[(i, i)] += prec[i];
        }
        let (lo, hi): (Vec<f64>, Vec<f64>) = ks.iter().map(Knob::bounds).unzip();
        if timing() {
            let ranks: Vec<usize> = chans.iter().map(|c| c.basis.rank()).collect();
            eprintln!(
                "diagnose timing: freedom {nk} knobs → {nd} directions × {} knots (every {} rows, error {err:.1e}), {n_all} rows, {:.3} s; the pass reads {:.1} directions per channel (ranks {ranks:?})",
                knots.n_knots,
                knots.f,
                t0.elapsed().as_secs_f64(),
                ranks.iter().sum::<usize>() as f64 / ranks.len().max(1) as f64
            );
        }
        let (row_knot, row_wb) = knots.row_weights();
        let mut fr = Freedom {
            knots_b: knots_b.iter().map(|&v| v as f32).collect(),
            knots,
            row_knot,
            row_wb,
            chans,
            fit: rows.fit,
            missing: rows.missing,
            base_r: Vec::new(),
            base_h: Vec::new(),
            knots_read: AtomicU64::new(0),
            knots_all: AtomicU64::new(0),
            v,
            theta: theta.to_vec(),
            lo,
            hi,
            prec,
            a_inv: a.clone().cholesky().map(|c| c.inverse()),
            a,
            side0: vec![0; nk],
            calls: AtomicU64::new(0),
            sweeps: AtomicU64::new(0),
            ns: AtomicU64::new(0),
        };
        // from an empty base: every row differs from 0 where it is finite
        fr.base_h = vec![DVector::zeros(nd); fr.chans.len()];
        fr.base_r = vec![0.0; n_all];
        fr.base_h = fr.fit_products(&r0).0;
        fr.base_r = r0.iter().flatten().flatten().copied().collect();
        let d0 = fr.solve(&fr.pull_from(&fr.base_h), &mut ActiveSet::new());
        fr.side0 = (0..nk)
            .map(|i| {
                let (lo, hi) = (fr.lo[i] - fr.theta[i], fr.hi[i] - fr.theta[i]);
                if d0[i] <= lo {
                    -1
                } else if d0[i] >= hi {
                    1
                } else {
                    0
                }
            })
            .collect();
        Ok(fr)
    }

    /// Number of design values that may move.
    pub fn len(&self) -> usize {
        self.theta.len()
    }

    pub fn is_empty(&self) -> bool {
        self.theta.is_empty()
    }

    /// Directions of the design values kept and rows between knots.
    /// (Read by the tests only since `freedom` left the public API.)
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn compression(&self) -> (usize, usize) {
        (self.v.ncols(), self.knots.f)
    }

    /// The bounded correction δ for the data's pull `b` (box QP), started
    /// from `start`'s active set (empty: the calibrated nominal's), which
    /// it leaves at its own.
    fn solve(&self, b: &[f64], start: &mut ActiveSet) -> Vec<f64> {
        let nk = self.len();
        let lo: Vec<f64> = (0..nk).map(|i| self.lo[i] - self.theta[i]).collect();
        let hi: Vec<f64> = (0..nk).map(|i| self.hi[i] - self.theta[i]).collect();
        let from: &[i8] = if start.len() == nk {
            start
        } else {
            &self.side0
        };
        let (d, sweeps) = match &self.a_inv {
            Some(p) => box_qp_exact_inv_from(&self.a, p, b, &lo, &hi, from),
            None => box_qp_exact(&self.a, b, &lo, &hi, &vec![0.0; nk]),
        };
        self.calls.fetch_add(1, Relaxed);
        self.sweeps.fetch_add(sweeps as u64, Relaxed);
        *start = (0..nk)
            .map(|i| i8::from(d[i] >= hi[i]) - i8::from(d[i] <= lo[i]))
            .collect();
        d
    }

    /// The bounded correction δ of the design values that best explains
    /// `res` on the fit rows (with the prior), and `res` with it removed
    /// (every row).
    pub fn correct(&self, res: &mut [Vec<Vec<f64>>]) -> Vec<f64> {
        if self.is_empty() {
            return Vec::new();
        }
        let t0 = std::time::Instant::now();
        let (h, _) = self.fit_products(res);
        let d = self.solve(&self.pull_from(&h), &mut ActiveSet::new());
        let c = self.v.tr_mul(&DVector::from_column_slice(&d));
        // B̃c at the knots, one column at a time (contiguous)
        let nkn = self.knots.n_knots;
        let mut ck = vec![0.0; nkn + 1];
        for (col, &cj) in self.knots_b.chunks_exact(nkn).zip(c.iter()) {
            for (o, &bv) in ck.iter_mut().zip(col) {
                *o += cj * bv as f64;
            }
        }
        for ((v, &j), &wb) in res
            .iter_mut()
            .flatten()
            .flatten()
            .zip(&self.row_knot)
            .zip(&self.row_wb)
        {
            let j = j as usize;
            *v -= (1.0 - wb) * ck[j] + wb * ck[j + 1];
        }
        self.ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
        d
    }

    /// Per channel: B̃ᵀr over its fit rows (non-finite r as 0), and Σ r²
    /// over the finite ones; None where r is non-finite on a row the
    /// calibrated nominal had (B̃ᵀB̃ counts that row). B̃ᵀr is the
    /// nominal's plus B̃ᵀ(r − r₀) over the knots where r differs from it.
    fn fit_products(&self, res: &[Vec<Vec<f64>>]) -> Products {
        let mut out = self.fit_products_many(&[res]);
        out.pop().unwrap_or_else(|| (self.base_h.clone(), None))
    }

    /// `fit_products` of several residual sets with one pass over B̃:
    /// the pass is bound by reading B̃ (≈ 4 M values, not in cache), so
    /// each column's knots are read once for every set while they are in
    /// L1. Each set's sums are the single pass's, term for term.
    fn fit_products_many(&self, sets: &[&[Vec<Vec<f64>>]]) -> Vec<Products> {
        let diffs: Vec<Diff> = sets.iter().map(|r| self.diff_of(r)).collect();
        let mut hs: Vec<Vec<DVector<f64>>> = vec![self.base_h.clone(); diffs.len()];
        let (mut read, mut all) = (0u64, 0u64);
        for (ci, c) in self.chans.iter().enumerate() {
            let cb = &c.basis;
            // Pᵀz per set in the channel's own directions
            let mut hp = vec![vec![0.0; cb.rank()]; diffs.len()];
            for &(a, b, off) in &cb.spans {
                all += (b - a) as u64 * diffs.len() as u64;
                // per set: the span's knots it changed
                let cut: Vec<(usize, usize)> = diffs
                    .iter()
                    .map(|d| {
                        let (t0, t1) = d.touched[ci];
                        (a.max(t0), b.min(t1))
                    })
                    .collect();
                // the sets that read the same knots (usually all: a
                // simulated effect changes every row) share each dot's pass
                let mut groups: Vec<((usize, usize), Vec<usize>)> = Vec::new();
                for (i, &r) in cut.iter().enumerate() {
                    if r.0 >= r.1 {
                        continue;
                    }
                    match groups.iter_mut().find(|g| g.0 == r) {
                        Some(g) => g.1.push(i),
                        None => groups.push((r, vec![i])),
                    }
                }
                for (o, col) in cb.p.chunks_exact(cb.len.max(1)).enumerate() {
                    for &((a1, b1), ref idx) in &groups {
                        let zs: Vec<&[f64]> = idx.iter().map(|&i| &diffs[i].z[a1..b1]).collect();
                        let pc = &col[off + a1 - a..off + b1 - a];
                        for (&i, v) in idx.iter().zip(dots(pc, &zs)) {
                            hp[i][o] += v;
                        }
                    }
                }
                read += cut
                    .iter()
                    .map(|&(a, b)| b.saturating_sub(a) as u64)
                    .sum::<u64>();
            }
            for (h, p) in hs.iter_mut().zip(&hp) {
                if p.iter().any(|&x| x != 0.0) {
                    h[ci] += &cb.v * DVector::from_column_slice(p);
                }
            }
        }
        self.knots_read.fetch_add(read, Relaxed);
        self.knots_all.fetch_add(all, Relaxed);
        hs.into_iter()
            .zip(diffs)
            .map(|(h, d)| (h, d.consistent.then_some(d.rr)))
            .collect()
    }

    /// The row pass of `fit_products`: Hᵀ(r − r₀), Σ r² and the knots
    /// touched per channel.
    fn diff_of(&self, res: &[Vec<Vec<f64>>]) -> Diff {
        let fin = |v: f64| if v.is_finite() { v } else { 0.0 };
        let mut consistent = true;
        // z = Hᵀ(r − r₀) over the fit rows (one more knot: a knot row's next one)
        let mut z = vec![0.0; self.knots.n_knots + 1];
        let mut rr = vec![0.0; self.chans.len()];
        // per channel: the knots z touches, [first, end)
        let mut touched = vec![(usize::MAX, 0usize); self.chans.len()];
        let mut row = 0;
        for (ci, ch) in res.iter().flatten().enumerate() {
            let base = &self.base_r[row..row + ch.len()];
            for (&v, &b) in ch.iter().zip(base) {
                if self.fit[row] {
                    if v.is_finite() {
                        rr[ci] += v * v;
                    } else {
                        consistent &= self.missing[row];
                    }
                    if v.to_bits() != b.to_bits() {
                        let d = fin(v) - fin(b);
                        let (j, wb) = (self.row_knot[row] as usize, self.row_wb[row]);
                        z[j] += (1.0 - wb) * d;
                        z[j + 1] += wb * d;
                        let t = &mut touched[ci];
                        *t = (t.0.min(j), t.1.max(j + 2));
                    }
                }
                row += 1;
            }
        }
        Diff {
            z,
            rr,
            consistent,
            touched,
        }
    }

    /// Sᵀ W r − prior from the channels' B̃ᵀr.
    fn pull_from(&self, h: &[DVector<f64>]) -> Vec<f64> {
        let mut s = DVector::zeros(self.v.ncols());
        for (c, hc) in self.chans.iter().zip(h) {
            s.axpy(c.w, hc, 1.0);
        }
        let g = &self.v * s;
        (0..self.len())
            .map(|i| g[i] - self.prec[i] * self.theta[i])
            .collect()
    }

    /// Where each knob would go with its bound released: the data's pull
    /// at the calibrated θ (positive: wants a larger value).
    pub fn pull(&self, _ps: &[Prepared], res: &[Vec<Vec<f64>>]) -> Vec<f64> {
        self.pull_from(&self.fit_products(res).0)
    }

    /// The fit rows' SSE per channel after the correction, from
    /// |r − B̃c|² = |r|² − 2 cᵀB̃ᵀr + cᵀ(B̃ᵀB̃)c (c = Vᵀδ), without
    /// forming the corrected residuals.
    pub fn fit_sse_of(&self, res: &[Vec<Vec<f64>>]) -> Option<Vec<f64>> {
        self.fit_sse_many(&[res], &mut ActiveSet::new())
            .pop()
            .flatten()
    }

    /// `fit_sse_of` of several residual sets, sharing the pass over B̃
    /// (`fit_products_many`): a grid's or a line search's trials.
    pub fn fit_sse_many(
        &self,
        sets: &[&[Vec<Vec<f64>>]],
        start: &mut ActiveSet,
    ) -> Vec<Option<Vec<f64>>> {
        if self.is_empty() {
            return vec![None; sets.len()];
        }
        let t0 = std::time::Instant::now();
        let out = self
            .fit_products_many(sets)
            .into_iter()
            .map(|(h, rr)| Some(self.sse_from(&h, &rr?, start)))
            .collect();
        self.ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
        out
    }

    /// The fit rows' SSE per channel after the correction, from B̃ᵀr and
    /// Σ r² per channel.
    fn sse_from(&self, h: &[DVector<f64>], rr: &[f64], start: &mut ActiveSet) -> Vec<f64> {
        let d = self.solve(&self.pull_from(h), start);
        let c = self.v.tr_mul(&DVector::from_column_slice(&d));
        self.chans
            .iter()
            .zip(h)
            .zip(rr)
            .map(|((ch, hc), r2)| (r2 - 2.0 * c.dot(hc) + (&ch.m * &c).dot(&c)).max(0.0))
            .collect()
    }

    pub fn theta(&self) -> &[f64] {
        &self.theta
    }

    pub fn bounds(&self, i: usize) -> (f64, f64) {
        (self.lo[i], self.hi[i])
    }
}

/// Per channel: its knot ranges that a fit row reads.
fn fit_spans(knots: &Knots, rows: &Rows) -> Vec<Vec<(usize, usize)>> {
    // knots a fit row reads (a row between knots j and j+1 touches both)
    let mut touched = vec![false; knots.n_knots + 1];
    knots.for_each(|r, j, _| touched[j] |= rows.fit[r]);
    (0..rows.lens.len())
        .map(|ci| {
            let (k0, k1) = knots.seg_knots(ci);
            spans(&touched[k0..k1], k0)
        })
        .collect()
}

/// Per channel: its basis and B̃ᵀB̃ over its fit rows that were not missing.
fn fit_channels(
    knots: &Knots,
    kb: &DMatrix<f64>,
    rows: &Rows,
    bases: Vec<ChannelBasis>,
) -> Vec<FitChannel> {
    let n_all = rows.fit.len();
    let bt = knots.expand(kb, n_all);
    let mut out = Vec::new();
    let mut r0 = 0;
    for ((ci, &l), basis) in rows.lens.iter().enumerate().zip(bases) {
        let used: Vec<usize> = (r0..r0 + l)
            .filter(|&r| rows.fit[r] && !rows.missing[r])
            .collect();
        let b = bt.select_rows(&used);
        let m = b.transpose() * &b;
        out.push(FitChannel {
            w: rows.w[ci],
            m,
            basis,
        });
        r0 += l;
    }
    out
}

/// The maximal runs of `true` in `on`, as knot ranges offset by `k0`.
fn spans(on: &[bool], k0: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &t) in on.iter().chain(std::iter::once(&false)).enumerate() {
        match (t, start) {
            (true, None) => start = Some(i),
            (false, Some(a)) => {
                out.push((k0 + a, k0 + i));
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// With `TCOMP_DIAG_TIMING`: each fit's candidates and evaluations.
pub(crate) fn print_evals(what: &str, fits: &[FitResult]) {
    if timing() {
        for f in fits {
            let kinds: Vec<&str> = f.cands.iter().map(|c| c.kind).collect();
            eprintln!(
                "diagnose timing: {what} {} {} evals",
                kinds.join("+"),
                f.evals
            );
        }
    }
}

impl Drop for Freedom {
    fn drop(&mut self) {
        if timing() {
            let calls = self.calls.load(Relaxed);
            eprintln!(
                "diagnose timing: {calls} projections, {:.3} s, {:.1} box-QP steps each, {:.0} % of B̃'s fit knots read",
                self.ns.load(Relaxed) as f64 * 1e-9,
                self.sweeps.load(Relaxed) as f64 / calls.max(1) as f64,
                100.0 * self.knots_read.load(Relaxed) as f64
                    / self.knots_all.load(Relaxed).max(1) as f64
            );
        }
    }
}

impl Projection for Freedom {
    fn project(&self, res: &mut [Vec<Vec<f64>>]) {
        self.correct(res);
    }
    fn fit_sse(&self, res: &[Vec<Vec<f64>>]) -> Option<Vec<f64>> {
        self.fit_sse_of(res)
    }
    fn fit_sse_many(
        &self,
        sets: &[&[Vec<Vec<f64>>]],
        start: &mut ActiveSet,
    ) -> Vec<Option<Vec<f64>>> {
        Freedom::fit_sse_many(self, sets, start)
    }
    fn pull_products(&self, sets: &[&[Vec<Vec<f64>>]]) -> Option<Vec<Vec<DVector<f64>>>> {
        if self.is_empty() {
            return None;
        }
        self.fit_products_many(sets)
            .into_iter()
            .map(|(h, rr)| rr.map(|_| h))
            .collect()
    }
    fn fit_sse_from(
        &self,
        h: &[DVector<f64>],
        rr: &[f64],
        start: &mut ActiveSet,
    ) -> Option<Vec<f64>> {
        let t0 = std::time::Instant::now();
        let out = self.sse_from(h, rr, start);
        self.ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
        Some(out)
    }
}

#[cfg(test)]
pub(crate) mod tests;

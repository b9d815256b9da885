//! The network's exact step in its modes. With capacities C and the
//! symmetric conductance matrix K (links, losses to ambient and coolant),
//! `C dx/dt = −K x + F` is diagonal in z = Uᵀ C^½ x, where U Λ Uᵀ is the
//! eigen-decomposition of C^-½ K C^-½: over a step of `dt` with the
//! heat F [W] held, each mode decays by e^(−λ dt) and gains
//! (1 − e^(−λ dt))/λ of its share of F, the same zero-order hold as
//! `x ← Φx + Ψb` from the matrix exponential, in O(n) per step instead of
//! O(n²). The heat splits into a part that changes only with the speed,
//! the feed or the coolant state (mapped to the modes when it changes) and
//! three vectors scaled every step (ambient, coolant, `coolant` effect);
//! only what something reads is mapped back: the temperatures of the
//! sensors', bending's and jackets' nodes and each direction's
//! lever-weighted sum.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use std::rc::Rc;

/// One coolant state's modes.
pub(super) struct Modes {
    /// U: eigenvectors of C^-½ K C^-½, one column per mode.
    u: DMatrix<f64>,
    /// e^(−λ dt) per mode.
    decay: Vec<f64>,
    /// diag((1 − e^(−λ dt))/λ) Uᵀ C^-½: heat per node [W] → the modes'
    /// increment over a step.
    gain: DMatrix<f64>,
    /// `gain` times the per-step heat vectors: per K of ambient, of
    /// coolant through the jackets, of the `coolant` effect's supply.
    pub(super) per_ambient: Vec<f64>,
    pub(super) per_jacket: Vec<f64>,
    pub(super) per_cool: Vec<f64>,
    /// The outputs' rows in the modes, column-major, each column padded
    /// to whole blocks of `BLOCK`: first C^-½ U at the read nodes (their
    /// temperatures), then Σ lever × C^-½ U over each direction's terms
    /// (its lever-weighted sum of temperatures).
    out_cols: Vec<f64>,
    n_out: usize,
    n_pad: usize,
}

/// Rows summed together in registers when the outputs are read.
const BLOCK: usize = 8;

/// What one coolant state's modes are made of.
pub(super) struct Spec<'a> {
    /// K: the symmetric conductance matrix [W/K] (links, losses to ambient
    /// and coolant in this state).
    pub k: &'a DMatrix<f64>,
    /// C: the capacities [J/K].
    pub c: &'a [f64],
    /// The step [s].
    pub dt: f64,
    /// The per-step heat vectors [W/K] scaled by a temperature every step:
    /// ambient, coolant through the jackets, the `coolant` effect's supply.
    pub g_amb: &'a [f64],
    pub g_jacket: &'a [f64],
    pub g_cool: &'a [f64],
    /// The outputs: the nodes whose temperatures are read, and each
    /// direction's (node, lever) terms.
    pub read: &'a [usize],
    pub dirs: &'a [Vec<(usize, f64)>],
}

impl Modes {
    /// The modes of `C dx/dt = −K x + F` for a step of `dt`, with the
    /// outputs: the `read` nodes' temperatures and each direction's lever
    /// sum.
    pub(super) fn new(spec: &Spec) -> Result<Modes> {
        let Spec {
            k,
            c,
            dt,
            read,
            dirs,
            ..
        } = *spec;
        let n = c.len();
        if n == 0 {
            // the machine file's checks refuse it already
            bail!("thermal network: no nodes");
        }
        let isq: Vec<f64> = c.iter().map(|v| 1.0 / v.sqrt()).collect();
        let s = DMatrix::from_fn(n, n, |i, j| k[(i, j)] * isq[i] * isq[j]);
        if s.iter().any(|v| !v.is_finite()) {
            bail!("thermal network: a capacity or conductance is not a finite positive number");
        }
        let eig = nalgebra::SymmetricEigen::new(s);
        let lam = &eig.eigenvalues;
        if lam.iter().any(|v| !v.is_finite()) {
            bail!("thermal network: its modes could not be computed");
        }
        let decay: Vec<f64> = lam.iter().map(|l| (-l * dt).exp()).collect();
        // (1 − e^(−λ dt))/λ, → dt for a mode without loss
        let share: Vec<f64> = lam
            .iter()
            .map(|&l| {
                if (l * dt).abs() < 1e-12 {
                    dt
                } else {
                    -(-l * dt).exp_m1() / l
                }
            })
            .collect();
        let u = eig.eigenvectors;
        let gain = DMatrix::from_fn(n, n, |mode, node| share[mode] * u[(node, mode)] * isq[node]);
        let map = |v: &[f64]| -> Vec<f64> {
            (&gain * DVector::from_column_slice(v))
                .iter()
                .copied()
                .collect()
        };
        let n_out = read.len() + dirs.len();
        let n_pad = n_out.div_ceil(BLOCK).max(1) * BLOCK;
        let mut out_cols = vec![0.0; n * n_pad];
        for (mode, col) in out_cols.chunks_exact_mut(n_pad).enumerate() {
            let t = |i: usize| isq[i] * u[(i, mode)];
            for (o, &i) in col.iter_mut().zip(read) {
                *o = t(i);
            }
            for (o, terms) in col[read.len()..].iter_mut().zip(dirs) {
                *o = terms.iter().map(|&(i, lever)| lever * t(i)).sum();
            }
        }
        Ok(Modes {
            per_ambient: map(spec.g_amb),
            per_jacket: map(spec.g_jacket),
            per_cool: map(spec.g_cool),
            u,
            decay,
            gain,
            out_cols,
            n_out,
            n_pad,
        })
    }

    /// The modal coordinates of node temperatures `x`: Uᵀ C^½ x.
    pub(super) fn to_modes(&self, x: &[f64], c: &[f64]) -> Vec<f64> {
        let y = DVector::from_fn(x.len(), |i, _| x[i] * c[i].sqrt());
        self.u.tr_mul(&y).iter().copied().collect()
    }

    /// The coordinates `z` in another state's modes: U_otherᵀ U z (the
    /// capacities cancel).
    pub(super) fn in_other(&self, other: &Modes, z: &[f64]) -> Vec<f64> {
        let y = &self.u * DVector::from_column_slice(z);
        other.u.tr_mul(&y).iter().copied().collect()
    }

    /// The modes' increment over a step for heat `f` [W] per node.
    pub(super) fn heat(&self, f: &[f64], out: &mut [f64]) {
        for (o, row) in out.iter_mut().zip(self.gain.row_iter()) {
            *o = row.iter().zip(f).map(|(g, v)| g * v).sum();
        }
    }

    /// One step: z ← e^(−λ dt) z + w.
    pub(super) fn step(&self, z: &mut [f64], w: &[f64]) {
        for ((zi, d), wi) in z.iter_mut().zip(&self.decay).zip(w) {
            *zi = d * *zi + wi;
        }
    }

    /// The outputs from `z`: the read nodes' temperatures, then each
    /// direction's lever-weighted sum (`out`: one per output). A block of
    /// outputs is summed in registers over the modes, in mode order.
    pub(super) fn outputs(&self, z: &[f64], out: &mut [f64]) {
        for r0 in (0..self.n_out).step_by(BLOCK) {
            let mut acc = [0.0f64; BLOCK];
            for (col, &v) in self.out_cols.chunks_exact(self.n_pad).zip(z) {
                let blk: &[f64; BLOCK] = col[r0..r0 + BLOCK].try_into().unwrap_or(&[0.0; BLOCK]);
                for k in 0..BLOCK {
                    acc[k] += v * blk[k];
                }
            }
            let w = BLOCK.min(self.n_out - r0);
            out[r0..r0 + w].copy_from_slice(&acc[..w]);
        }
    }
}

/// [`Modes::new`] with a small per-thread cache keyed by the exact bits of
/// everything it reads: a diagnosis re-simulates the same network many
/// times with other heat inputs (heat effects, heat-gain calibration), and
/// the eigen-decomposition is most of a coarse simulation's cost. Same
/// result, bit for bit.
pub(super) fn cached(spec: &Spec) -> Result<Rc<Modes>> {
    let Spec {
        k,
        c,
        dt,
        read,
        dirs,
        ..
    } = *spec;
    type Entry = (Vec<u64>, Rc<Modes>);
    thread_local! {
        static CACHE: std::cell::RefCell<std::collections::VecDeque<Entry>> =
            const { std::cell::RefCell::new(std::collections::VecDeque::new()) };
    }
    const KEEP: usize = 16;
    let mut key: Vec<u64> = Vec::with_capacity(k.len() + 4 * c.len() + read.len() + 2);
    key.push(c.len() as u64);
    key.push(dt.to_bits());
    key.extend(
        k.iter()
            .chain(c)
            .chain(spec.g_amb)
            .chain(spec.g_jacket)
            .chain(spec.g_cool)
            .map(|v| v.to_bits()),
    );
    key.extend(read.iter().map(|&i| i as u64));
    for terms in dirs {
        key.push(u64::MAX);
        key.extend(terms.iter().flat_map(|&(i, l)| [i as u64, l.to_bits()]));
    }
    if let Some(hit) = CACHE.with(|cache| {
        cache
            .borrow()
            .iter()
            .find(|e| e.0 == key)
            .map(|e| e.1.clone())
    }) {
        return Ok(hit);
    }
    let modes = Rc::new(Modes::new(spec)?);
    CACHE.with(|cache| {
        let mut cache = cache.borrow_mut();
        if cache.len() >= KEEP {
            cache.pop_front();
        }
        cache.push_back((key, modes.clone()));
    });
    Ok(modes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tcomp_numerics::linalg::discretize;
    use tcomp_numerics::rng::Rng;

    /// The modal step is the matrix exponential's `x ← Φx + Ψb`
    /// (b = C⁻¹F) on a random network, over several steps and a change of
    /// coolant state.
    #[test]
    fn the_modal_step_is_the_exact_zero_order_hold() {
        let mut g = Rng::paired(7);
        for n in [1usize, 2, 5, 27] {
            let mut r = || g.uniform();
            let c: Vec<f64> = (0..n).map(|_| 10f64.powf(1.0 + 4.0 * r())).collect();
            let mut links = Vec::new();
            for i in 1..n {
                links.push((i, (r() * i as f64) as usize, 0.1 + 10.0 * r()));
            }
            let g_amb: Vec<f64> = (0..n).map(|_| 0.05 + r()).collect();
            let g_jacket: Vec<f64> = (0..n)
                .map(|i| if i % 3 == 0 { 2.0 * r() } else { 0.0 })
                .collect();
            let g_cool = vec![0.0; n];
            let k_of = |extra: &[f64]| {
                let mut k =
                    DMatrix::from_diagonal(&DVector::from_fn(n, |i, _| g_amb[i] + extra[i]));
                for &(i, j, gl) in &links {
                    k[(i, i)] += gl;
                    k[(j, j)] += gl;
                    k[(i, j)] -= gl;
                    k[(j, i)] -= gl;
                }
                k
            };
            let read: Vec<usize> = (0..n).collect();
            // one direction over every other node, levers 0.5 and 2
            let dirs = vec![(0..n)
                .step_by(2)
                .map(|i| (i, 0.5 + 1.5 * (i % 4 == 0) as u8 as f64))
                .collect::<Vec<_>>()];
            let dt = 10.0;
            let (k0, k1) = (k_of(&vec![0.0; n]), k_of(&g_jacket));
            let spec = |k| Spec {
                k,
                c: &c,
                dt,
                g_amb: &g_amb,
                g_jacket: &g_jacket,
                g_cool: &g_cool,
                read: &read,
                dirs: &dirs,
            };
            let m0 = Modes::new(&spec(&k0)).unwrap();
            let m1 = Modes::new(&spec(&k1)).unwrap();
            let a_of = |k: &DMatrix<f64>| DMatrix::from_fn(n, n, |i, j| -k[(i, j)] / c[i]);
            let d0 = discretize(&a_of(&k0), dt).unwrap();
            let d1 = discretize(&a_of(&k1), dt).unwrap();
            let mut x = DVector::from_fn(n, |_, _| 20.0 + 5.0 * r());
            let mut z = m0.to_modes(x.as_slice(), &c);
            let mut xm = vec![0.0; n + 1];
            for step in 0..6 {
                let (modes, (phi, psi)) = if step < 3 { (&m0, &d0) } else { (&m1, &d1) };
                if step == 3 {
                    z = m0.in_other(&m1, &z);
                }
                let f: Vec<f64> = (0..n).map(|_| 100.0 * r() - 20.0).collect();
                let (ta, tc) = (18.0 + r(), 15.0 + r());
                // the exact step with b = C⁻¹F, F = f + ta g_amb (+ tc g_jacket)
                let on = step >= 3;
                let b = DVector::from_fn(n, |i, _| {
                    (f[i] + ta * g_amb[i] + if on { tc * g_jacket[i] } else { 0.0 }) / c[i]
                });
                x = phi * &x + psi * b;
                let mut w = vec![0.0; n];
                modes.heat(&f, &mut w);
                for i in 0..n {
                    w[i] +=
                        ta * modes.per_ambient[i] + if on { tc * modes.per_jacket[i] } else { 0.0 };
                }
                modes.step(&mut z, &w);
                modes.outputs(&z, &mut xm);
                let lin: f64 = dirs[0].iter().map(|&(i, l)| l * x[i]).sum();
                assert!(
                    (xm[n] - lin).abs() < 1e-9 * (1.0 + lin.abs()),
                    "n {n}, step {step}: direction {} vs {lin}",
                    xm[n]
                );
                for i in 0..n {
                    assert!(
                        (xm[i] - x[i]).abs() < 1e-9 * (1.0 + x[i].abs()),
                        "n {n}, step {step}, node {i}: modal {} vs exponential {}",
                        xm[i],
                        x[i]
                    );
                }
            }
        }
    }
}

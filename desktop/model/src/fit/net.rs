//! The n_in–n_hidden–1 network (logistic hidden layer, linear output) and
//! its training: a genetic algorithm searches the hidden-layer weights
//! (fitness = training MSE, the output layer solved by least squares for each
//! genome), then Levenberg–Marquardt refines all weights on the full batch
//! with early stopping on a time-block validation set.

use rayon::prelude::*;

use super::progress::Progress;
use tcomp_numerics::linalg::{least_squares, solve_spd};
use tcomp_numerics::rng::Rng;

/// Bound on |W1| and |b1| (the fixed-point core's range).
pub const W1_BOUND: f64 = 1999.0;

/// Training options for the GA + gradient network.
#[derive(Clone, Debug)]
pub struct NetOpts {
    pub hidden: usize,
    pub seed: u64,
    pub population: usize,
    pub generations: usize,
    pub tournament: usize,
    pub elites: usize,
    pub mutation_rate: f64,
    /// Rows used for GA fitness (evenly strided subsample of the training rows).
    pub ga_rows: usize,
    pub lm_iters: usize,
    /// Early stopping: accepted LM steps without improvement on the validation block.
    pub patience: usize,
    /// L2 penalty on all weights (normalized target units).
    pub l2: f64,
    /// After early stopping, retrain from the GA's weights on all training rows
    /// for the best number of steps (otherwise, the default, keep the
    /// early-stopped weights: the same step count on other rows lands
    /// elsewhere, and on FL_THERMAL's 4 h slice the refitted ensemble's test
    /// MAE was 4.8 µm against 1.9 µm kept).
    pub refit_full: bool,
    /// Ensemble size: independent trainings (seeds `seed..seed+ensemble`)
    /// whose outputs are averaged (one network's result moves with its seed).
    pub ensemble: usize,
    /// Rows the Levenberg–Marquardt steps see at most (evenly strided).
    pub max_rows: usize,
}

impl Default for NetOpts {
    fn default() -> Self {
        NetOpts {
            hidden: 11,
            seed: 3,
            population: 30,
            generations: 30,
            tournament: 3,
            elites: 2,
            mutation_rate: 0.15,
            ga_rows: 1000,
            lm_iters: 300,
            patience: 10,
            l2: 1e-5,
            refit_full: false,
            ensemble: 4,
            max_rows: 3000,
        }
    }
}

/// Flat parameter layout: for each hidden unit j, `[W1[j][0..n_in], b1[j]]`,
/// then `w2[0..nh]`, then `b2`.
#[derive(Clone, Debug)]
pub struct Net {
    pub n_in: usize,
    pub nh: usize,
    pub theta: Vec<f64>,
}

#[inline]
pub fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

impl Net {
    pub fn n_params(n_in: usize, nh: usize) -> usize {
        nh * (n_in + 1) + nh + 1
    }
    pub fn zeros(n_in: usize, nh: usize) -> Net {
        Net {
            n_in,
            nh,
            theta: vec![0.0; Net::n_params(n_in, nh)],
        }
    }
    fn out_off(&self) -> usize {
        self.nh * (self.n_in + 1)
    }
    #[inline]
    pub fn forward(&self, x: &[f64]) -> f64 {
        forward(&self.theta, self.n_in, self.nh, x)
    }
    /// Split into (w1, b1, w2, b2).
    pub fn unpack(&self) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>, f64) {
        let k = self.n_in + 1;
        let w1 = (0..self.nh)
            .map(|j| self.theta[j * k..j * k + self.n_in].to_vec())
            .collect();
        let b1 = (0..self.nh)
            .map(|j| self.theta[j * k + self.n_in])
            .collect();
        let o = self.out_off();
        (
            w1,
            b1,
            self.theta[o..o + self.nh].to_vec(),
            self.theta[o + self.nh],
        )
    }
    fn clamp_hidden(&mut self) {
        let o = self.out_off();
        for v in &mut self.theta[..o] {
            *v = v.clamp(-W1_BOUND, W1_BOUND);
        }
    }
}

#[inline]
fn forward(theta: &[f64], n_in: usize, nh: usize, x: &[f64]) -> f64 {
    let k = n_in + 1;
    let o = nh * k;
    let mut y = theta[o + nh];
    for j in 0..nh {
        let w = &theta[j * k..j * k + k];
        let mut z = w[n_in];
        for i in 0..n_in {
            z += w[i] * x[i];
        }
        y += theta[o + j] * sigmoid(z);
    }
    y
}

fn mse(net: &Net, x: &[Vec<f64>], y: &[f64]) -> f64 {
    if y.is_empty() {
        return 0.0;
    }
    x.par_iter()
        .zip(y.par_iter())
        .map(|(r, &t)| {
            let e = net.forward(r) - t;
            e * e
        })
        .sum::<f64>()
        / y.len() as f64
}

/// Set the output layer of `net` to the least-squares fit given its hidden
/// layer; returns the training MSE.
fn solve_output(net: &mut Net, x: &[Vec<f64>], y: &[f64]) -> f64 {
    let (n_in, nh) = (net.n_in, net.nh);
    let k = n_in + 1;
    let h: Vec<Vec<f64>> = x
        .iter()
        .map(|r| {
            (0..nh)
                .map(|j| {
                    let w = &net.theta[j * k..j * k + k];
                    let mut z = w[n_in];
                    for i in 0..n_in {
                        z += w[i] * r[i];
                    }
                    sigmoid(z)
                })
                .collect()
        })
        .collect();
    // A hidden layer the solver cannot use is an unfit genome, not zeros.
    let Ok(c) = least_squares(&h, y, true, 1e-6 * y.len() as f64) else {
        return f64::INFINITY;
    };
    let o = net.out_off();
    net.theta[o + nh] = c[0];
    net.theta[o..o + nh].copy_from_slice(&c[1..]);
    let mut s = 0.0;
    for (hr, &t) in h.iter().zip(y) {
        let mut p = c[0];
        for j in 0..nh {
            p += c[1 + j] * hr[j];
        }
        s += (p - t) * (p - t);
    }
    s / y.len().max(1) as f64
}

/// The GA's fitness rows in column layout (one slice per input), so the
/// hidden layer of a genome is computed column by column over all rows.
struct GaRows {
    cols: Vec<Vec<f64>>,
    y: nalgebra::DVector<f64>,
}

impl GaRows {
    fn new(x: &[Vec<f64>], y: &[f64]) -> GaRows {
        let n_in = x.first().map_or(0, Vec::len);
        let cols = (0..n_in)
            .map(|i| x.iter().map(|r| r[i]).collect())
            .collect();
        GaRows {
            cols,
            y: nalgebra::DVector::from_column_slice(y),
        }
    }
}

/// The logistic sigmoid by a vectorisable e^(−|z|): 2^(−|z|·log2 e) split
/// into an integer power of two (written into the exponent bits) and a
/// degree-6 polynomial on [−½, ½]; |z| saturates at 30 like the board's 16
/// (σ(30) = 1 − 9e-14). Within 2e-9 of σ — far inside the board's table
/// sigmoid's own 2.5e-5 — with no `exp` call or table, so the loop over a
/// hidden-layer column compiles to packed instructions.
#[inline(always)]
pub fn sigmoid_fast(z: f64) -> f64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52: rounds to an integer
    let a = z.abs().min(30.0);
    let t = -a * std::f64::consts::LOG2_E; // in [−43.3, 0]
    let r = t + MAGIC;
    let n = r - MAGIC; // round(t)
    let f = t - n; // [−½, ½]
                   // 2^f = e^(f ln 2), Taylor to degree 7 of g = f·ln 2 (|g| ≤ 0.347).
    let g = f * std::f64::consts::LN_2;
    let p = 1.0
        + g * (1.0
            + g * (0.5
                + g * (1.0 / 6.0
                    + g * (1.0 / 24.0
                        + g * (1.0 / 120.0 + g * (1.0 / 720.0 + g * (1.0 / 5040.0)))))));
    // n ≥ −44: the biased exponent stays positive.
    let e = f64::from_bits(p.to_bits().wrapping_add(r.to_bits().wrapping_shl(52)));
    let s = 1.0 / (1.0 + e);
    if z >= 0.0 {
        s
    } else {
        1.0 - s
    }
}

/// GA fitness: the training MSE with the output layer least-squares fitted
/// to the genome's hidden layer. The hidden layer is built column by column
/// (n rows × (n_hidden + 1), [`sigmoid_fast`]), its normal equations by
/// nalgebra's matrix product and solved by Cholesky with a small ridge, and
/// the SSE from the same products (yᵀy − 2cᵀHᵀy + cᵀHᵀHc) — no second pass
/// over the rows. Only ranks genomes; the winner's output layer is solved
/// again by SVD on all rows.
fn fitness(net: &mut Net, d: &GaRows) -> f64 {
    use nalgebra::DMatrix;
    let (n_in, nh) = (net.n_in, net.nh);
    let k = n_in + 1;
    let m = nh + 1;
    let n = d.y.len();
    if n == 0 {
        return f64::INFINITY;
    }
    // Columns: 1, the nh hidden units, y; one product gives HᵀH, Hᵀy, yᵀy.
    let mut h = DMatrix::<f64>::zeros(n, m + 1);
    h.column_mut(0).fill(1.0);
    h.column_mut(m).copy_from(&d.y);
    for j in 0..nh {
        let w = &net.theta[j * k..j * k + k];
        let mut col = h.column_mut(j + 1);
        let c = col.as_mut_slice();
        c.fill(w[n_in]);
        for (i, xc) in d.cols.iter().enumerate() {
            let wi = w[i];
            for (v, x) in c.iter_mut().zip(xc) {
                *v += wi * x;
            }
        }
        for v in c.iter_mut() {
            *v = sigmoid_fast(*v);
        }
    }
    let g = h.tr_mul(&h);
    let hth = g.view((0, 0), (m, m)).into_owned();
    let hty = g.view((0, m), (m, 1)).column(0).into_owned();
    let ridge = 1e-6 * n as f64;
    let mut a = hth.clone();
    for i in 1..m {
        a[(i, i)] += ridge;
    }
    let Some(ch) = a.cholesky() else {
        return f64::INFINITY;
    };
    let c = ch.solve(&hty);
    if c.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let o = net.out_off();
    net.theta[o + nh] = c[0];
    for j in 0..nh {
        net.theta[o + j] = c[j + 1];
    }
    let sse = g[(m, m)] - 2.0 * c.dot(&hty) + c.dot(&(&hth * &c));
    let v = sse.max(0.0) / n as f64;
    if v.is_finite() {
        v
    } else {
        f64::INFINITY
    }
}

/// Genetic search of the hidden-layer weights. Returns the best network
/// (output layer least-squares fitted) and its fitness history.
pub fn ga_search(
    x: &[Vec<f64>],
    y: &[f64],
    opts: &NetOpts,
    progress: &dyn Progress,
) -> (Net, Vec<f64>) {
    let n_in = x.first().map_or(0, Vec::len);
    let nh = opts.hidden;
    let genes = nh * (n_in + 1);
    let mut rng = Rng::new(opts.seed);
    // Strided subsample for fitness.
    let stride = x.len().div_ceil(opts.ga_rows.max(1)).max(1);
    let xs: Vec<Vec<f64>> = x.iter().step_by(stride).cloned().collect();
    let ys: Vec<f64> = y.iter().step_by(stride).copied().collect();
    let rows = GaRows::new(&xs, &ys);

    let new_net = |rng: &mut Rng| {
        let mut n = Net::zeros(n_in, nh);
        for g in 0..genes {
            n.theta[g] = rng.range(-4.0, 4.0);
        }
        n
    };
    let mut pop: Vec<(Net, f64)> = (0..opts.population.max(2))
        .map(|_| (new_net(&mut rng), f64::INFINITY))
        .collect();
    pop.par_iter_mut().for_each(|(n, f)| *f = fitness(n, &rows));
    let mut history = Vec::new();
    for gen in 0..opts.generations {
        pop.sort_by(|a, b| a.1.total_cmp(&b.1));
        history.push(pop[0].1);
        let sigma = 0.6 * (1.0 - gen as f64 / opts.generations.max(1) as f64) + 0.05;
        let mut next: Vec<(Net, f64)> = pop.iter().take(opts.elites).cloned().collect();
        let tour = |rng: &mut Rng, pop: &[(Net, f64)]| {
            let mut best = rng.below(pop.len());
            for _ in 1..opts.tournament.max(1) {
                let c = rng.below(pop.len());
                if pop[c].1 < pop[best].1 {
                    best = c;
                }
            }
            best
        };
        while next.len() < pop.len() {
            let a = tour(&mut rng, &pop);
            let b = tour(&mut rng, &pop);
            let mut child = Net::zeros(n_in, nh);
            for g in 0..genes {
                // Blend crossover (BLX-0.5).
                let (p, q) = (pop[a].0.theta[g], pop[b].0.theta[g]);
                let (lo, hi) = (p.min(q), p.max(q));
                let d = hi - lo;
                let mut v = rng.range(lo - 0.5 * d, hi + 0.5 * d);
                if rng.uniform() < opts.mutation_rate {
                    v += sigma * rng.normal() * (1.0 + v.abs() * 0.25);
                }
                child.theta[g] = v.clamp(-50.0, 50.0);
            }
            next.push((child, f64::INFINITY));
        }
        next[opts.elites..]
            .par_iter_mut()
            .for_each(|(n, f)| *f = fitness(n, &rows));
        pop = next;
        progress.step();
    }
    pop.sort_by(|a, b| a.1.total_cmp(&b.1));
    history.push(pop[0].1);
    let mut best = pop.swap_remove(0).0;
    // Output layer on all training rows.
    solve_output(&mut best, x, y);
    (best, history)
}

/// Gauss–Newton pieces over all rows: (JᵀJ/N, Jᵀr/N, mse). The Jacobian is
/// built in blocks of rows and JᵀJ accumulated by nalgebra's matrix product
/// (blocked, vectorized) — the cost of every Levenberg–Marquardt step.
fn normal_eqs(net: &Net, x: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
    use nalgebra::{DMatrix, DVector};
    let p = net.theta.len();
    let (n_in, nh) = (net.n_in, net.nh);
    let k = n_in + 1;
    let o = nh * k;
    let chunk = 512;
    let (jtj, jtr, sse) = x
        .par_chunks(chunk)
        .zip(y.par_chunks(chunk))
        .map(|(xc, yc)| {
            let rows = xc.len();
            // Row-major J (rows × p) = column-major Jᵀ (p × rows).
            let mut jt = DMatrix::<f64>::zeros(p, rows);
            let mut e = DVector::<f64>::zeros(rows);
            let th = &net.theta;
            let mut sse = 0.0;
            let buf = jt.as_mut_slice();
            for (ri, (r, &t)) in xc.iter().zip(yc).enumerate() {
                let g = &mut buf[ri * p..(ri + 1) * p];
                let mut out = th[o + nh];
                for j in 0..nh {
                    let w = &th[j * k..j * k + k];
                    let mut z = w[n_in];
                    for i in 0..n_in {
                        z += w[i] * r[i];
                    }
                    let h = sigmoid(z);
                    out += th[o + j] * h;
                    g[o + j] = h;
                    let d = th[o + j] * h * (1.0 - h);
                    for i in 0..n_in {
                        g[j * k + i] = d * r[i];
                    }
                    g[j * k + n_in] = d;
                }
                g[o + nh] = 1.0;
                let err = out - t;
                e[ri] = err;
                sse += err * err;
            }
            let jtj = &jt * jt.transpose();
            let jtr = &jt * e;
            (jtj, jtr, sse)
        })
        .reduce(
            || (DMatrix::zeros(p, p), DVector::zeros(p), 0.0),
            |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2),
        );
    let n = x.len().max(1) as f64;
    // Symmetric: row-major and column-major layouts agree.
    let jtj: Vec<f64> = jtj.iter().map(|v| v / n).collect();
    let jtr: Vec<f64> = jtr.iter().map(|v| v / n).collect();
    (jtj, jtr, sse / n)
}

/// Result of Levenberg–Marquardt training.
pub struct LmResult {
    pub net: Net,
    /// Accepted steps at the best validation error (or all steps without validation).
    pub best_iter: usize,
    pub iters: usize,
    pub train_mse: f64,
    pub val_mse: Option<f64>,
}

/// Levenberg–Marquardt on the full batch. With a validation set, keeps the
/// weights of the best validation error and stops after `patience` accepted
/// steps without improvement. `max_iters` bounds the accepted steps.
pub fn train_lm(
    start: &Net,
    x: &[Vec<f64>],
    y: &[f64],
    val: Option<(&[Vec<f64>], &[f64])>,
    max_iters: usize,
    opts: &NetOpts,
    progress: &dyn Progress,
) -> LmResult {
    let mut net = start.clone();
    let p = net.theta.len();
    let l2 = opts.l2;
    let obj = |n: &Net, m: f64| m + l2 * n.theta.iter().map(|v| v * v).sum::<f64>();
    let val_mse = |n: &Net| {
        val.filter(|v| !v.1.is_empty())
            .map(|(vx, vy)| mse(n, vx, vy))
    };
    let mut lambda = 1e-3;
    let (mut jtj, mut jtr, mut cur_mse) = normal_eqs(&net, x, y);
    let mut best = (net.clone(), val_mse(&net).unwrap_or(f64::INFINITY), 0usize);
    let mut accepted = 0usize;
    let mut since_best = 0usize;
    let mut stall = 0usize;
    'outer: while accepted < max_iters {
        let e0 = obj(&net, cur_mse);
        let grad: Vec<f64> = (0..p).map(|a| jtr[a] + l2 * net.theta[a]).collect();
        loop {
            let mut a = jtj.clone();
            for i in 0..p {
                a[i * p + i] += l2 + lambda * (jtj[i * p + i] + 1e-9);
            }
            let neg: Vec<f64> = grad.iter().map(|g| -g).collect();
            // A damped system that is not positive definite: damp harder.
            let Ok(d) = solve_spd(&a, &neg, p) else {
                lambda *= 4.0;
                if lambda > 1e10 {
                    break 'outer;
                }
                continue;
            };
            let mut cand = net.clone();
            for (t, dv) in cand.theta.iter_mut().zip(&d) {
                *t += dv;
            }
            cand.clamp_hidden();
            let m = mse(&cand, x, y);
            let e1 = obj(&cand, m);
            if e1.is_finite() && e1 < e0 {
                net = cand;
                lambda = (lambda / 3.0).max(1e-12);
                accepted += 1;
                progress.step();
                stall = if (e0 - e1) < 1e-10 * e0.max(1e-300) {
                    stall + 1
                } else {
                    0
                };
                break;
            }
            lambda *= 4.0;
            if lambda > 1e10 {
                break 'outer;
            }
        }
        if let Some(v) = val_mse(&net) {
            if v < best.1 {
                best = (net.clone(), v, accepted);
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= opts.patience {
                    break;
                }
            }
        }
        if stall >= 5 {
            break;
        }
        let ne = normal_eqs(&net, x, y);
        jtj = ne.0;
        jtr = ne.1;
        cur_mse = ne.2;
    }
    if val.is_some_and(|v| !v.1.is_empty()) {
        let train_mse = mse(&best.0, x, y);
        LmResult {
            net: best.0,
            best_iter: best.2,
            iters: accepted,
            train_mse,
            val_mse: Some(best.1),
        }
    } else {
        let train_mse = mse(&net, x, y);
        LmResult {
            net,
            best_iter: accepted,
            iters: accepted,
            train_mse,
            val_mse: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermocomp_core::fixed::{sigmoid_q17, SIGMOID_MAX_ERROR};

    /// The GA's sigmoid is σ to 5e-9 over the whole line (both tails, the
    /// saturation and the exponent trick), so it also stays within the
    /// board's table sigmoid's own bound of what the board computes.
    #[test]
    fn sigmoid_fast_matches_sigma_and_the_board() {
        let mut worst = 0.0f64;
        let mut worst_board = 0.0f64;
        // Every 13th Q16 value in ±26: the board's sigmoid is defined on Q16 inputs.
        for zq in (-26 * 65536..=26 * 65536).step_by(13) {
            let z = f64::from(zq) / 65536.0;
            let f = sigmoid_fast(z);
            worst = worst.max((f - sigmoid(z)).abs());
            let b = f64::from(sigmoid_q17(i64::from(zq))) / 131072.0;
            worst_board = worst_board.max((f - b).abs());
        }
        for z in [-1e300, -800.0, -45.0, 45.0, 800.0, 1e300] {
            assert!((sigmoid_fast(z) - sigmoid(z)).abs() < 5e-9, "z = {z}");
        }
        assert!(worst < 5e-9, "worst |fast − σ| = {worst:e}");
        assert!(
            worst_board <= SIGMOID_MAX_ERROR + 1e-9,
            "worst |fast − board| = {worst_board:e}"
        );
    }
}

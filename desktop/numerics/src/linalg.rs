//! The desktop's one linear-algebra entry point, on `nalgebra`: least squares
//! by SVD (never the normal equations: lagged temperature features are
//! nearly collinear), SPD solves by Cholesky for the Levenberg–Marquardt
//! step, and the matrix exponential (the exact zero-order-hold step the
//! simulator's modal step is tested against).
//! A solver that cannot give an answer returns an error, never zeros.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

/// Relative singular-value cut-off: directions weaker than this (times the
/// largest singular value) carry only rounding noise and are dropped.
const SVD_RCOND: f64 = 1e-12;

/// A dot product in four running sums of f64 (vectorised, where an
/// iterator's single running sum is not); `a` may be stored in f32,
/// widened as it is read. Written by hand: nalgebra's small dynamic
/// products walk columns with a scalar axpy.
pub fn dot<T: Copy + Into<f64>>(a: &[T], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, y)| x.into() * y)
        .sum();
    let mut s = [0.0f64; 4];
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k].into() * y[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// `dot(a, b)` for K vectors b at once, each the same sum as `dot`'s,
/// term for term: the K sums interleave (one dot waits on its own
/// additions), and `a` is read once for all of them.
pub fn dot_many<T: Copy + Into<f64>, const K: usize>(a: &[T], bs: [&[f64]; K]) -> [f64; K] {
    let n = bs.iter().map(|b| b.len()).fold(a.len(), usize::min);
    let full = n / 4 * 4;
    let mut s = [[0.0f64; 4]; K];
    for i in (0..full).step_by(4) {
        let x: [f64; 4] = [
            a[i].into(),
            a[i + 1].into(),
            a[i + 2].into(),
            a[i + 3].into(),
        ];
        for (sk, b) in s.iter_mut().zip(&bs) {
            let y = &b[i..i + 4];
            for k in 0..4 {
                sk[k] += x[k] * y[k];
            }
        }
    }
    let mut out = [0.0; K];
    for ((o, sk), b) in out.iter_mut().zip(&s).zip(&bs) {
        let tail: f64 = a[full..n]
            .iter()
            .zip(&b[full..n])
            .map(|(&x, y)| x.into() * y)
            .sum();
        *o = (sk[0] + sk[1]) + (sk[2] + sk[3]) + tail;
    }
    out
}

/// `min |X w − y|² + ridge·|w|²` for the rows of `X`; with `intercept` a
/// leading column of ones is added (never penalised). Returns `[c0, c1..]`
/// with an intercept, `[c1..]` without.
pub fn least_squares(
    rows: &[Vec<f64>],
    y: &[f64],
    intercept: bool,
    ridge: f64,
) -> Result<Vec<f64>> {
    let p = rows.first().map_or(0, Vec::len);
    let off = usize::from(intercept);
    let n = rows.len().min(y.len());
    if n == 0 || p + off == 0 {
        bail!("least squares: no rows to fit");
    }
    let cols = p + off;
    let penalised = if ridge > 0.0 { p } else { 0 };
    // Ridge as extra rows sqrt(ridge)·I under the data: one SVD solves both.
    let mut a = DMatrix::<f64>::zeros(n + penalised, cols);
    let mut b = DVector::<f64>::zeros(n + penalised);
    for (i, (r, &t)) in rows.iter().zip(y).enumerate().take(n) {
        if intercept {
            a[(i, 0)] = 1.0;
        }
        for (j, v) in r.iter().enumerate() {
            a[(i, off + j)] = *v;
        }
        b[i] = t;
    }
    let s = ridge.max(0.0).sqrt();
    for j in 0..penalised {
        a[(n + j, off + j)] = s;
    }
    solve_svd(a, &b)
}

/// Least squares on column vectors: `min |Σ_j w_j·cols[j] − y|² + λ|w|²`.
pub fn least_squares_cols(cols: &[Vec<f64>], y: &[f64], ridge: f64) -> Result<Vec<f64>> {
    let n = y.len();
    let rows: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            cols.iter()
                .map(|c| c.get(i).copied().unwrap_or(0.0))
                .collect()
        })
        .collect();
    least_squares(&rows, y, false, ridge)
}

fn solve_svd(a: DMatrix<f64>, b: &DVector<f64>) -> Result<Vec<f64>> {
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        bail!("least squares: the data hold a non-finite value");
    }
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    if smax <= 0.0 {
        bail!("least squares: every column is zero");
    }
    match svd.solve(b, smax * SVD_RCOND) {
        Ok(x) => Ok(x.iter().copied().collect()),
        Err(e) => bail!("least squares: SVD failed ({e})"),
    }
}

/// Solve `A x = b` for a symmetric positive definite `A` (row-major n×n).
/// A matrix that is not positive definite is an error.
pub fn solve_spd(a: &[f64], b: &[f64], n: usize) -> Result<Vec<f64>> {
    if a.len() != n * n || b.len() != n {
        bail!(
            "SPD solve: sizes do not match ({}×{n} vs {})",
            a.len(),
            b.len()
        );
    }
    let m = DMatrix::from_row_slice(n, n, a);
    match m.cholesky() {
        Some(c) => Ok(c
            .solve(&DVector::from_column_slice(b))
            .iter()
            .copied()
            .collect()),
        None => bail!("SPD solve: matrix is not positive definite"),
    }
}

/// `exp(A)` for a square matrix, by nalgebra's Padé scaling and squaring.
/// A matrix with a non-finite entry is an error (its exponential is not).
pub fn expm(a: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    if !a.is_square() {
        bail!(
            "matrix exponential: {}×{} is not square",
            a.nrows(),
            a.ncols()
        );
    }
    if a.iter().any(|v| !v.is_finite()) {
        bail!("matrix exponential: the matrix holds a non-finite value");
    }
    let e = a.clone().exp();
    if e.iter().any(|v| !v.is_finite()) {
        bail!("matrix exponential: the result overflows");
    }
    Ok(e)
}

/// Exact zero-order-hold discretisation of `dx/dt = A x + b` over `dt`:
/// `(Φ, Ψ)` with `x(t+dt) = Φ x(t) + Ψ b` for `b` constant over the step,
/// from the exponential of the augmented matrix `[[A, I], [0, 0]]·dt`.
pub fn discretize(a: &DMatrix<f64>, dt: f64) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let n = a.nrows();
    let mut aug = DMatrix::<f64>::zeros(2 * n, 2 * n);
    aug.view_mut((0, 0), (n, a.ncols())).copy_from(&(a * dt));
    for i in 0..n {
        aug[(i, n + i)] = dt;
    }
    let e = expm(&aug)?;
    Ok((
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, n)).into_owned(),
    ))
}

/// Solve the square system `A x = b` by LU with partial pivoting; a
/// singular (or non-finite) system is an error.
pub fn solve(a: DMatrix<f64>, b: &[f64]) -> Result<Vec<f64>> {
    if !a.is_square() || a.nrows() != b.len() {
        bail!(
            "solve: sizes do not match ({}×{} vs {})",
            a.nrows(),
            a.ncols(),
            b.len()
        );
    }
    if a.iter().chain(b).any(|v| !v.is_finite()) {
        bail!("solve: the system holds a non-finite value");
    }
    match a.lu().solve(&DVector::from_column_slice(b)) {
        Some(x) if x.iter().all(|v| v.is_finite()) => Ok(x.iter().copied().collect()),
        _ => bail!("solve: the matrix is singular"),
    }
}

/// `ridge` for several right-hand sides (columns of `y`) at once.
///
/// Beside [`least_squares`] because the diagnosis' grey-box identification
/// solves thousands of small, well-posed systems: Cholesky on the scaled
/// Gram matrix (SVD only when it fails) is the fast path there.
pub fn ridge_multi(x: &DMatrix<f64>, y: &DMatrix<f64>, lambda: f64) -> Option<DMatrix<f64>> {
    RidgeFactor::new(x, lambda).solve(y)
}

/// What a ridge fit needs of X alone (the column scaling, the factored
/// Gram matrix), to solve for several right-hand sides on the same rows:
/// the same arithmetic as [`ridge_multi`], which goes through it.
pub struct RidgeFactor {
    scale: DVector<f64>,
    xs: DMatrix<f64>,
    solver: RidgeSolver,
}

enum RidgeSolver {
    Cholesky(nalgebra::Cholesky<f64, nalgebra::Dyn>),
    /// The Gram matrix was not positive definite (rank-deficient X).
    Svd(nalgebra::SVD<f64, nalgebra::Dyn, nalgebra::Dyn>),
}

impl RidgeFactor {
    pub fn new(x: &DMatrix<f64>, lambda: f64) -> RidgeFactor {
        let p = x.ncols();
        let mut scale = DVector::zeros(p);
        for j in 0..p {
            let n = x.column(j).norm();
            scale[j] = if n > 0.0 { 1.0 / n } else { 0.0 };
        }
        let xs = x * DMatrix::from_diagonal(&scale);
        let mut g = xs.tr_mul(&xs);
        for j in 0..p {
            g[(j, j)] += lambda.max(1e-12);
        }
        let solver = match g.clone().cholesky() {
            Some(c) => RidgeSolver::Cholesky(c),
            None => RidgeSolver::Svd(g.svd(true, true)),
        };
        RidgeFactor { scale, xs, solver }
    }

    /// The coefficients for each column of `y` (None: not finite).
    pub fn solve(&self, y: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let rhs = self.xs.tr_mul(y);
        let b = match &self.solver {
            RidgeSolver::Cholesky(c) => c.solve(&rhs),
            RidgeSolver::Svd(s) => s.solve(&rhs, 1e-12).ok()?,
        };
        let b = DMatrix::from_diagonal(&self.scale) * b;
        b.iter().all(|v| v.is_finite()).then_some(b)
    }
}

/// Ridge least squares with column scaling: `argmin |y − Xb|² + λ|Db|²`,
/// `D` the column norms (so λ is relative): [`ridge_multi`] with one
/// right-hand side.
pub fn ridge(x: &DMatrix<f64>, y: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let y = DMatrix::from_column_slice(y.len(), 1, y.as_slice());
    ridge_multi(x, &y, lambda).map(|b| b.column(0).into_owned())
}

/// The eigenvectors of the symmetric `g`, largest eigenvalue first,
/// leaving out the smallest ones whose eigenvalues sum to at most
/// `rel_tol`² of the trace (at least `min_keep` kept), and the share of
/// the trace left out: for g = MᵀM, ‖M − MVVᵀ‖ ≤ `rel_tol`·‖M‖ (Frobenius).
pub fn leading_eigenvectors(g: DMatrix<f64>, rel_tol: f64, min_keep: usize) -> (DMatrix<f64>, f64) {
    let n = g.ncols();
    let eig = nalgebra::SymmetricEigen::new(g);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let trace: f64 = eig.eigenvalues.iter().map(|l| l.max(0.0)).sum();
    let budget = rel_tol * rel_tol * trace;
    let (mut dropped, mut kept) = (0.0, n);
    while kept > min_keep {
        let l = eig.eigenvalues[order[kept - 1]].max(0.0);
        if dropped + l > budget {
            break;
        }
        dropped += l;
        kept -= 1;
    }
    let v = DMatrix::from_fn(n, kept, |r, c| eig.eigenvectors[(r, order[c])]);
    (v, dropped / trace.max(1e-300))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_leading_eigenvectors_leave_out_at_most_the_budget() {
        // M with singular values 10, 1, 1e-4, 1e-9 (orthogonal columns)
        let m = DMatrix::from_fn(6, 4, |r, c| {
            if r == c {
                [10.0, 1.0, 1e-4, 1e-9][c]
            } else {
                0.0
            }
        });
        let g = m.transpose() * &m;
        let total = 101.0 + 1e-8 + 1e-18;
        for (tol, want) in [(1e-3, 2), (1e-6, 3), (1e-12, 4), (0.5, 1)] {
            let (v, dropped) = leading_eigenvectors(g.clone(), tol, 0);
            assert_eq!(v.ncols(), want, "tol {tol}");
            assert!(
                dropped <= tol * tol,
                "tol {tol}: dropped {dropped} of {total}"
            );
            // largest first: the first column is the 10's direction
            assert!((v[(0, 0)].abs() - 1.0).abs() < 1e-12);
        }
        // at least `min_keep`
        assert_eq!(leading_eigenvectors(g, 10.0, 2).0.ncols(), 2);
    }

    #[test]
    fn dot_many_gives_each_dot_bit_for_bit() {
        // lengths around the four-term blocks; awkward magnitudes
        for n in [0, 1, 3, 4, 5, 8, 13, 101] {
            let a: Vec<f32> = (0..n)
                .map(|i| ((i * 37 % 11) as f32 - 5.3) * 1.7e-3)
                .collect();
            let b: Vec<Vec<f64>> = (0..3)
                .map(|k| {
                    (0..n)
                        .map(|i| ((i * 13 + k * 7) % 17) as f64 * 0.1 - 0.83 + 1e9 * (i % 2) as f64)
                        .collect()
                })
                .collect();
            let many = dot_many(&a, [&b[0][..], &b[1][..], &b[2][..]]);
            for k in 0..3 {
                assert_eq!(
                    many[k].to_bits(),
                    dot(&a, &b[k]).to_bits(),
                    "n {n}, vector {k}"
                );
            }
        }
    }

    #[test]
    fn a_ridge_factor_reused_gives_what_a_fresh_fit_gives_bit_for_bit() {
        // the diagnosis reuses one factor for every output on the same rows
        let x = DMatrix::from_fn(40, 4, |i, j| {
            ((i * 7 + j * 3) as f64 * 0.37).sin() + j as f64
        });
        let f = RidgeFactor::new(&x, 1e-6);
        for s in [0.3, -2.0, 11.0] {
            let y = DVector::from_fn(40, |i, _| (i as f64 * s).cos());
            let once = ridge(&x, &y, 1e-6).unwrap();
            let reused = f
                .solve(&DMatrix::from_column_slice(40, 1, y.as_slice()))
                .unwrap();
            let bits = |v: &[f64]| v.iter().map(|b| b.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(once.as_slice()), bits(reused.as_slice()));
        }
    }

    #[test]
    fn least_squares_recovers_a_plane_with_collinear_columns() {
        // y = 2 + 3·a − b, with a third column that copies a (rank-deficient):
        // the minimum-norm solution splits a's weight between the two copies.
        let rows: Vec<Vec<f64>> = (0..50)
            .map(|i| {
                let a = i as f64 * 0.1;
                let b = (i as f64 * 0.37).sin();
                vec![a, b, a]
            })
            .collect();
        let y: Vec<f64> = rows.iter().map(|r| 2.0 + 3.0 * r[0] - r[1]).collect();
        let c = least_squares(&rows, &y, true, 0.0).unwrap();
        assert!((c[0] - 2.0).abs() < 1e-9, "{c:?}");
        assert!((c[1] + c[3] - 3.0).abs() < 1e-9, "{c:?}");
        assert!((c[1] - c[3]).abs() < 1e-9, "{c:?}");
        assert!((c[2] + 1.0).abs() < 1e-9, "{c:?}");
    }

    #[test]
    fn ridge_shrinks_but_leaves_the_intercept_alone() {
        let rows: Vec<Vec<f64>> = (0..20).map(|i| vec![i as f64]).collect();
        let y: Vec<f64> = rows.iter().map(|r| 10.0 + r[0]).collect();
        let plain = least_squares(&rows, &y, true, 0.0).unwrap();
        let shrunk = least_squares(&rows, &y, true, 1e4).unwrap();
        assert!(shrunk[1].abs() < plain[1].abs());
        assert!(shrunk[0] > plain[0], "the intercept takes up the mean");
    }

    #[test]
    fn failures_are_errors_not_zeros() {
        assert!(least_squares(&[], &[], true, 0.0).is_err());
        assert!(least_squares(&[vec![f64::NAN]], &[1.0], true, 0.0).is_err());
        assert!(solve_spd(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0], 2).is_err());
        let x = solve_spd(&[4.0, 1.0, 1.0, 3.0], &[1.0, 2.0], 2).unwrap();
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12);
        assert!((x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn expm_of_a_diagonal_and_a_rotation() {
        let e = expm(&DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -2.0])).unwrap();
        assert!(
            (e[(0, 0)] - 1f64.exp()).abs() < 1e-12 && (e[(1, 1)] - (-2f64).exp()).abs() < 1e-12
        );
        let t = 0.7;
        let r = expm(&DMatrix::from_row_slice(2, 2, &[0.0, -t, t, 0.0])).unwrap();
        assert!((r[(0, 0)] - t.cos()).abs() < 1e-12 && (r[(1, 0)] - t.sin()).abs() < 1e-12);
        assert!(expm(&DMatrix::from_row_slice(1, 1, &[f64::NAN])).is_err());
    }

    #[test]
    fn discretize_a_first_order_lag() {
        let a = DMatrix::from_row_slice(1, 1, &[-0.01]);
        let (phi, psi) = discretize(&a, 10.0).unwrap();
        assert!((phi[(0, 0)] - (-0.1f64).exp()).abs() < 1e-14);
        // ∫0^10 e^{-0.01 s} ds = (1 - e^{-0.1}) / 0.01
        assert!((psi[(0, 0)] - (1.0 - (-0.1f64).exp()) / 0.01).abs() < 1e-11);
    }

    #[test]
    fn solve_small_and_singular() {
        let x = solve(
            DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 3.0]),
            &[3.0, 5.0],
        )
        .unwrap();
        assert!((x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12);
        assert!(solve(
            DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]),
            &[1.0, 1.0]
        )
        .is_err());
    }
}

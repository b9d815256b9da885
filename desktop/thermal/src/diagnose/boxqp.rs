//! A small box-constrained quadratic program (the calibration's step and
//! the freedom left to candidates both solve one).

use nalgebra::DMatrix;

/// min ½ xᵀAx − bᵀx subject to lo ≤ x ≤ hi (A symmetric positive
/// definite), by projected Gauss–Seidel from 0 (clamped).
pub fn box_qp(a: &DMatrix<f64>, b: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    box_qp_counted(a, b, lo, hi).0
}

/// `box_qp` and the sweeps it took. A is read by columns (A symmetric:
/// column i is row i), contiguous, so the sweep's dot products vectorise:
/// it runs for every evaluation of every candidate.
pub fn box_qp_counted(a: &DMatrix<f64>, b: &[f64], lo: &[f64], hi: &[f64]) -> (Vec<f64>, usize) {
    box_qp_from(a, b, lo, hi, &vec![0.0; b.len()])
}

/// `box_qp_counted` with the sweeps started from `x0` (clamped). The
/// freedom starts them from the unconstrained optimum A⁻¹b: its sweeps,
/// capped, still end near the cap (≈ 197 of 200 on the bench's cases, the
/// directions of a large calibration are near-collinear), but end closer
/// to the optimum than sweeps from 0.
pub fn box_qp_from(
    a: &DMatrix<f64>,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    x0: &[f64],
) -> (Vec<f64>, usize) {
    let n = b.len();
    let mut x: Vec<f64> = (0..n).map(|i| x0[i].clamp(lo[i], hi[i])).collect();
    let cols = a.as_slice();
    for sweep in 0..200 {
        let mut moved = 0.0f64;
        for i in 0..n {
            let aii = a[(i, i)];
            if aii <= 0.0 {
                continue;
            }
            let s = b[i] - (dot(&cols[i * n..(i + 1) * n], &x) - aii * x[i]);
            let xi = (s / aii).clamp(lo[i], hi[i]);
            moved = moved.max((xi - x[i]).abs());
            x[i] = xi;
        }
        if moved < 1e-7 {
            return (x, sweep + 1);
        }
    }
    (x, 200)
}

/// A dot product in four running sums (vectorised).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut s = [0.0f64; 4];
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

//! A small box-constrained quadratic program (the calibration's step and
//! the freedom left to candidates both solve one).

use nalgebra::DMatrix;

/// min ½ xᵀAx − bᵀx subject to lo ≤ x ≤ hi (A symmetric positive
/// definite), by projected Gauss–Seidel from 0 (clamped).
pub fn box_qp(a: &DMatrix<f64>, b: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut x: Vec<f64> = (0..n).map(|i| 0.0f64.clamp(lo[i], hi[i])).collect();
    for _ in 0..200 {
        let mut moved = 0.0f64;
        for i in 0..n {
            let aii = a[(i, i)];
            if aii <= 0.0 {
                continue;
            }
            let mut s = b[i];
            for j in 0..n {
                if j != i {
                    s -= a[(i, j)] * x[j];
                }
            }
            let xi = (s / aii).clamp(lo[i], hi[i]);
            moved = moved.max((xi - x[i]).abs());
            x[i] = xi;
        }
        if moved < 1e-7 {
            break;
        }
    }
    x
}

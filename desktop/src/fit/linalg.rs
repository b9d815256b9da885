//! Small dense linear algebra (f64): symmetric positive (semi)definite solves
//! and least squares through the normal equations with a small ridge.

/// Solve `A x = b` for symmetric positive definite `A` (row-major, n×n) by
/// Cholesky. Returns `None` when `A` is not positive definite.
pub fn solve_spd(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let mut s = y[i];
        for k in i + 1..n {
            s -= l[k * n + i] * x[k];
        }
        x[i] = s / l[i * n + i];
    }
    Some(x)
}

/// Solve an SPD system, adding growing diagonal jitter if it is singular.
pub fn solve_spd_robust(a: &[f64], b: &[f64], n: usize) -> Vec<f64> {
    if let Some(x) = solve_spd(a, b, n) {
        return x;
    }
    let scale = (0..n)
        .map(|i| a[i * n + i].abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    let mut jitter = 1e-12 * scale;
    loop {
        let mut aj = a.to_vec();
        for i in 0..n {
            aj[i * n + i] += jitter;
        }
        if let Some(x) = solve_spd(&aj, b, n) {
            return x;
        }
        jitter *= 10.0;
        if jitter > 1e6 * scale {
            return vec![0.0; n];
        }
    }
}

/// Least squares `min |X w − y|² + ridge·|w|²` where each row of `X` is given;
/// with `intercept`, a leading column of ones is added (not penalized).
/// Returns `[c0, c1..]` with intercept, `[c1..]` without.
pub fn least_squares(rows: &[Vec<f64>], y: &[f64], intercept: bool, ridge: f64) -> Vec<f64> {
    let p = rows.first().map_or(0, Vec::len) + usize::from(intercept);
    let mut ata = vec![0.0; p * p];
    let mut aty = vec![0.0; p];
    let mut v = vec![0.0; p];
    for (r, &t) in rows.iter().zip(y) {
        let off = usize::from(intercept);
        if intercept {
            v[0] = 1.0;
        }
        v[off..].copy_from_slice(r);
        for i in 0..p {
            aty[i] += v[i] * t;
            for j in 0..=i {
                ata[i * p + j] += v[i] * v[j];
            }
        }
    }
    for i in 0..p {
        for j in 0..i {
            ata[j * p + i] = ata[i * p + j];
        }
        if !(intercept && i == 0) {
            ata[i * p + i] += ridge;
        }
    }
    solve_spd_robust(&ata, &aty, p)
}

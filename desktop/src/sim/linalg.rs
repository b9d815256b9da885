//! Small dense linear algebra for the thermal network: row-major square
//! matrices, the matrix exponential (scaling and squaring with a Taylor
//! series) and a Gaussian-elimination solver. Sizes are tens of nodes, so
//! nothing clever is needed.

/// Row-major square matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Mat {
    pub n: usize,
    pub a: Vec<f64>,
}

impl Mat {
    pub fn zeros(n: usize) -> Mat {
        Mat {
            n,
            a: vec![0.0; n * n],
        }
    }

    pub fn identity(n: usize) -> Mat {
        let mut m = Mat::zeros(n);
        for i in 0..n {
            m.a[i * n + i] = 1.0;
        }
        m
    }

    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.a[i * self.n + j]
    }

    #[inline]
    pub fn set(&mut self, i: usize, j: usize, v: f64) {
        self.a[i * self.n + j] = v;
    }

    #[inline]
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        self.a[i * self.n + j] += v;
    }

    pub fn mul(&self, o: &Mat) -> Mat {
        let n = self.n;
        let mut r = Mat::zeros(n);
        for i in 0..n {
            for k in 0..n {
                let x = self.a[i * n + k];
                if x == 0.0 {
                    continue;
                }
                let row = &o.a[k * n..(k + 1) * n];
                let out = &mut r.a[i * n..(i + 1) * n];
                for (o, &y) in out.iter_mut().zip(row) {
                    *o += x * y;
                }
            }
        }
        r
    }

    /// `y = self · x`.
    #[inline]
    pub fn mul_vec_into(&self, x: &[f64], y: &mut [f64]) {
        let n = self.n;
        for (i, yi) in y.iter_mut().enumerate().take(n) {
            let row = &self.a[i * n..(i + 1) * n];
            let mut s = 0.0;
            for (r, xv) in row.iter().zip(x) {
                s += r * xv;
            }
            *yi = s;
        }
    }

    pub fn norm1(&self) -> f64 {
        let n = self.n;
        (0..n)
            .map(|j| (0..n).map(|i| self.a[i * n + j].abs()).sum::<f64>())
            .fold(0.0, f64::max)
    }

    pub fn scale(&mut self, s: f64) {
        for v in &mut self.a {
            *v *= s;
        }
    }
}

/// `exp(m)` by scaling and squaring with an 18-term Taylor series
/// (accurate to machine precision once the scaled norm is below 1/2).
pub fn expm(m: &Mat) -> Mat {
    let n = m.n;
    let norm = m.norm1();
    let mut s = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.5 {
        scale *= 0.5;
        s += 1;
    }
    let mut x = m.clone();
    x.scale(scale);
    let mut result = Mat::identity(n);
    let mut term = Mat::identity(n);
    for k in 1..=18 {
        term = term.mul(&x);
        term.scale(1.0 / k as f64);
        for (r, t) in result.a.iter_mut().zip(&term.a) {
            *r += t;
        }
    }
    for _ in 0..s {
        result = result.mul(&result);
    }
    result
}

/// Exact zero-order-hold discretisation of `dx/dt = A x + b` over `dt`:
/// returns `(Φ, Ψ)` with `x(t+dt) = Φ x(t) + Ψ b` for `b` constant over
/// the step. Uses the augmented-matrix exponential `[[A, I], [0, 0]]`.
pub fn discretize(a: &Mat, dt: f64) -> (Mat, Mat) {
    let n = a.n;
    let mut aug = Mat::zeros(2 * n);
    for i in 0..n {
        for j in 0..n {
            aug.set(i, j, a.get(i, j) * dt);
        }
        aug.set(i, n + i, dt);
    }
    let e = expm(&aug);
    let mut phi = Mat::zeros(n);
    let mut psi = Mat::zeros(n);
    for i in 0..n {
        for j in 0..n {
            phi.set(i, j, e.get(i, j));
            psi.set(i, j, e.get(i, n + j));
        }
    }
    (phi, psi)
}

/// Solve `m x = b` by Gaussian elimination with partial pivoting.
/// Returns `None` when the matrix is singular.
pub fn solve(m: &Mat, b: &[f64]) -> Option<Vec<f64>> {
    let n = m.n;
    let mut a = m.a.clone();
    let mut x = b.to_vec();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i * n + c].abs().total_cmp(&a[j * n + c].abs()))?;
        if a[p * n + c].abs() < 1e-300 {
            return None;
        }
        if p != c {
            for j in 0..n {
                a.swap(p * n + j, c * n + j);
            }
            x.swap(p, c);
        }
        let d = a[c * n + c];
        for r in c + 1..n {
            let f = a[r * n + c] / d;
            if f == 0.0 {
                continue;
            }
            for j in c..n {
                a[r * n + j] -= f * a[c * n + j];
            }
            x[r] -= f * x[c];
        }
    }
    for c in (0..n).rev() {
        let mut s = x[c];
        for j in c + 1..n {
            s -= a[c * n + j] * x[j];
        }
        x[c] = s / a[c * n + c];
    }
    Some(x)
}

/// Ridge-regularised least squares `min |X w - y|² + λ|w|²` via the normal
/// equations (X given column-wise). Small problems only.
pub fn lstsq_cols(cols: &[Vec<f64>], y: &[f64], lambda: f64) -> Option<Vec<f64>> {
    let p = cols.len();
    let mut m = Mat::zeros(p);
    let mut rhs = vec![0.0; p];
    for i in 0..p {
        for j in i..p {
            let s: f64 = cols[i].iter().zip(&cols[j]).map(|(a, b)| a * b).sum();
            m.set(i, j, s);
            m.set(j, i, s);
        }
        rhs[i] = cols[i].iter().zip(y).map(|(a, b)| a * b).sum();
        m.add(i, i, lambda);
    }
    solve(&m, &rhs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expm_scalar_and_discretize() {
        let mut a = Mat::zeros(1);
        a.set(0, 0, -0.01);
        let (phi, psi) = discretize(&a, 10.0);
        assert!((phi.get(0, 0) - (-0.1f64).exp()).abs() < 1e-14);
        // ∫0^10 e^{-0.01 s} ds = (1 - e^{-0.1}) / 0.01
        assert!((psi.get(0, 0) - (1.0 - (-0.1f64).exp()) / 0.01).abs() < 1e-11);
    }

    #[test]
    fn solve_small() {
        let m = Mat {
            n: 2,
            a: vec![2.0, 1.0, 1.0, 3.0],
        };
        let x = solve(&m, &[3.0, 5.0]).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12);
    }
}

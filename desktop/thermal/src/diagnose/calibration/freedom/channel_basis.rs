//! Each channel's block of B̃ in its own few directions, for the pass.
//!
//! The freedom keeps ≈ 95 directions for all channels together, but one
//! channel's fit rows see far fewer of them: a temperature's or a
//! displacement's sensitivities are smooth curves, and one channel's block
//! K_c (its fit knots × the directions) has numerical rank ≈ 15–35 at
//! 10⁻⁷ (measured on the open-world benches: ranks 9–36 of 95). The pass
//! B̃ᵀr reads B̃ once per evaluation and is bound by that read, so each
//! block is kept as K_c ≈ P_c V_cᵀ, V_c the leading eigenvectors of
//! K_cᵀK_c and P_c = K_c V_c (fit knots × rank, f32): B̃ᵀr = V_c (P_cᵀ r)
//! reads rank instead of 95 columns. The truncated block P_c V_cᵀ replaces
//! K_c in the freedom itself (its B̃ᵀB̃, its corrections), so the
//! criterion stays an exact sum of squares of one consistent B̃.

use nalgebra::DMatrix;
use tcomp_numerics::linalg::leading_eigenvectors;

/// One channel's fit knots in its own directions.
pub(crate) struct ChannelBasis {
    /// Its knot ranges [a, b) that touch a fit row, and each one's first
    /// row in `p`.
    pub spans: Vec<(usize, usize, usize)>,
    /// Rows of `p` (fit knots).
    pub len: usize,
    /// P = K V, column-major (`len` × rank), rounded to f32 (the pass is
    /// bound by reading it).
    pub p: Vec<f32>,
    /// V: directions × rank.
    pub v: DMatrix<f64>,
}

impl ChannelBasis {
    /// The channel's block of `kb` over `spans` (knot ranges), truncated
    /// to the fewest leading directions whose left-out eigenvalues of KᵀK
    /// sum to at most `rel_tol`² of its trace (every direction when
    /// `rel_tol` is 0); `kb`'s rows there are replaced by P Vᵀ (P as
    /// stored, in f32).
    pub fn truncate(kb: &mut DMatrix<f64>, spans: &[(usize, usize)], rel_tol: f64) -> Self {
        let nd = kb.ncols();
        let mut at = 0;
        let spans: Vec<(usize, usize, usize)> = spans
            .iter()
            .map(|&(a, b)| {
                at += b - a;
                (a, b, at - (b - a))
            })
            .collect();
        let len = at;
        let mut k = DMatrix::zeros(len, nd);
        for &(a, b, off) in &spans {
            k.rows_mut(off, b - a).copy_from(&kb.rows(a, b - a));
        }
        let v = if rel_tol > 0.0 {
            // gemm (`transpose() *`), not the scalar `tr_mul`
            leading_eigenvectors(k.transpose() * &k, rel_tol, 0).0
        } else {
            DMatrix::identity(nd, nd)
        };
        let mut p = &k * &v;
        p.apply(|x| *x = *x as f32 as f64);
        let kt = &p * v.transpose();
        for &(a, b, off) in &spans {
            kb.rows_mut(a, b - a).copy_from(&kt.rows(off, b - a));
        }
        ChannelBasis {
            spans,
            len,
            p: p.iter().map(|&x| x as f32).collect(),
            v,
        }
    }

    pub fn rank(&self) -> usize {
        self.v.ncols()
    }

    /// The truncated block's row at `knot` (None: not a fit knot here).
    #[cfg(test)]
    pub fn row(&self, knot: usize) -> Option<Vec<f64>> {
        let &(a, _, off) = self.spans.iter().find(|s| (s.0..s.1).contains(&knot))?;
        let r = off + knot - a;
        Some(
            (0..self.v.nrows())
                .map(|d| {
                    (0..self.rank())
                        .map(|j| self.p[j * self.len + r] as f64 * self.v[(d, j)])
                        .sum()
                })
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_low_rank_block_keeps_its_rank_and_its_values() {
        // 40 knots × 12 directions of rank 3 (smooth curves), plus a
        // knot range outside the spans that must stay as it was
        let (n, nd) = (50, 12);
        let curve = |t: f64, j: usize| match j {
            0 => 1.0 - (-t / 7.0).exp(),
            1 => (t / 9.0).sin(),
            _ => t * 0.01,
        };
        let kb0 = DMatrix::from_fn(n, nd, |r, c| {
            (0..3)
                .map(|j| curve(r as f64, j) * (c as f64 / nd as f64 - 0.4).powi(j as i32))
                .sum()
        });
        let mut kb = kb0.clone();
        let cb = ChannelBasis::truncate(&mut kb, &[(0, 20), (30, 50)], 1e-7);
        assert_eq!(cb.rank(), 3);
        assert_eq!(cb.len, 40);
        let scale = kb0.amax();
        for r in 0..n {
            for c in 0..nd {
                assert!(
                    (kb[(r, c)] - kb0[(r, c)]).abs() <= 1e-6 * scale,
                    "({r}, {c}): {} vs {}",
                    kb[(r, c)],
                    kb0[(r, c)]
                );
            }
            match cb.row(r) {
                // the stored block is what the pass reads
                Some(row) => (0..nd).for_each(|c| {
                    assert!((row[c] - kb[(r, c)]).abs() <= 1e-12 * scale, "({r}, {c})")
                }),
                None => assert!((20..30).contains(&r), "knot {r}"),
            }
        }
        // untouched outside the spans, bit for bit
        for r in 20..30 {
            assert_eq!(kb.row(r), kb0.row(r));
        }
    }

    #[test]
    fn a_zero_tolerance_keeps_every_direction_and_a_zero_block_none() {
        let mut kb = DMatrix::from_fn(10, 4, |r, c| ((r * 4 + c) as f64).sin());
        assert_eq!(ChannelBasis::truncate(&mut kb, &[(0, 10)], 0.0).rank(), 4);
        let mut z = DMatrix::zeros(10, 4);
        let cb = ChannelBasis::truncate(&mut z, &[(2, 8)], 1e-7);
        assert_eq!(cb.rank(), 0);
        assert!(z.iter().all(|&x| x == 0.0));
    }
}

//! A coarser time grid for the calibration freedom's sensitivities: every
//! (run, channel) series of a sensitivity is kept at knots every `f` rows
//! and read between them by linear interpolation. Sensitivities of a
//! thermal network to its design values are slow (time constants of
//! minutes to hours), so the interpolation error is small, and it is
//! measured on the real matrix before a grid is chosen (`choose`).

use nalgebra::DMatrix;

/// The grid: one segment per (run, channel), in flattened row order.
pub(crate) struct Knots {
    /// Rows between knots.
    pub f: usize,
    /// Per segment: first flattened row, its rows, first knot.
    segs: Vec<(usize, usize, usize)>,
    pub n_knots: usize,
}

impl Knots {
    /// Knots every `f` rows (and at each segment's last row) of segments
    /// of the given lengths.
    pub fn new(lens: &[usize], f: usize) -> Knots {
        let (mut row, mut knot, mut segs) = (0, 0, Vec::new());
        for &l in lens {
            segs.push((row, l, knot));
            row += l;
            knot += if l == 0 { 0 } else { (l - 1).div_ceil(f) + 1 };
        }
        Knots {
            f,
            segs,
            n_knots: knot,
        }
    }

    /// The segment's knot range.
    pub fn seg_knots(&self, s: usize) -> (usize, usize) {
        let (_, l, k0) = self.segs[s];
        let n = if l == 0 {
            0
        } else {
            (l - 1).div_ceil(self.f) + 1
        };
        (k0, k0 + n)
    }

    /// Calls `visit(row, knot, weight)` for the (one or two) knots of every
    /// flattened row, rows in order.
    pub fn for_each(&self, mut visit: impl FnMut(usize, usize, f64)) {
        let f = self.f;
        for &(r0, l, k0) in &self.segs {
            for t in 0..l {
                let j = t / f;
                let a = j * f;
                let b = ((j + 1) * f).min(l - 1);
                if t == a || b == a {
                    visit(r0 + t, k0 + j, 1.0);
                } else {
                    let wb = (t - a) as f64 / (b - a) as f64;
                    visit(r0 + t, k0 + j, 1.0 - wb);
                    visit(r0 + t, k0 + j + 1, wb);
                }
            }
        }
    }

    /// Per flattened row: its first knot j and the weight of knot j + 1
    /// (1 − that on j; 0 on a knot, where j + 1 may be one past the end).
    pub fn row_weights(&self) -> (Vec<u32>, Vec<f64>) {
        let (mut js, mut ws) = (Vec::new(), Vec::new());
        let mut last = usize::MAX;
        self.for_each(|r, j, w| {
            if r == last {
                ws[r] = w;
            } else {
                js.push(j as u32);
                ws.push(0.0);
                last = r;
            }
        });
        (js, ws)
    }

    /// The rows of `m` at the knots.
    pub fn sample(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let mut rows = Vec::with_capacity(self.n_knots);
        for &(r0, l, _) in &self.segs {
            if l == 0 {
                continue;
            }
            let n = (l - 1).div_ceil(self.f) + 1;
            rows.extend((0..n).map(|j| r0 + (j * self.f).min(l - 1)));
        }
        DMatrix::from_fn(rows.len(), m.ncols(), |r, c| m[(rows[r], c)])
    }

    /// The knots' matrix read on every row (interpolated).
    /// Column by column (contiguous; a row at a time strides over every
    /// column), the sum `for_each`'s weights give, term for term.
    pub fn expand(&self, k: &DMatrix<f64>, n_rows: usize) -> DMatrix<f64> {
        let (js, ws) = self.row_weights();
        let mut out = DMatrix::zeros(n_rows, k.ncols());
        for (mut o, kc) in out.column_iter_mut().zip(k.column_iter()) {
            for ((v, &j), &wb) in o.iter_mut().zip(&js).zip(&ws) {
                let j = j as usize;
                *v = if wb == 0.0 {
                    kc[j]
                } else {
                    (1.0 - wb) * kc[j] + wb * kc[j + 1]
                };
            }
        }
        out
    }
}

/// Candidate grids, coarsest first.
const STEPS: [usize; 5] = [8, 6, 4, 3, 2];

/// The coarsest grid whose interpolation of `b` (rows weighted by `wall`)
/// is within `rel_tol` of it (relative Frobenius norm), and that error;
/// every row (`f` = 1) when none is, or `rel_tol` is 0.
pub(crate) fn choose(b: &DMatrix<f64>, lens: &[usize], wall: &[f64], rel_tol: f64) -> (Knots, f64) {
    // column by column (column-major: contiguous), not row by row
    let wsum = |m: &DMatrix<f64>| -> f64 {
        m.column_iter()
            .map(|c| c.iter().zip(wall).map(|(v, w)| w * v * v).sum::<f64>())
            .sum()
    };
    let norm2 = wsum(b);
    if rel_tol > 0.0 && norm2 > 0.0 {
        for f in STEPS {
            let k = Knots::new(lens, f);
            let err2 = wsum(&(b - k.expand(&k.sample(b), b.nrows())));
            let rel = (err2 / norm2).sqrt();
            if super::timing() {
                eprintln!("diagnose timing: knots every {f} rows: error {rel:.1e}");
            }
            if rel <= rel_tol {
                return (k, rel);
            }
        }
    }
    (Knots::new(lens, 1), 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expand_reads_every_row_as_for_each_weighs_it() {
        // segments shorter than, equal to and longer than a step; an empty one
        let lens = [1, 3, 0, 7, 10];
        for f in [1, 2, 3, 4] {
            let kn = Knots::new(&lens, f);
            let k = DMatrix::from_fn(kn.n_knots, 3, |r, c| (r * 7 + c * 13) as f64 * 0.37 - 2.0);
            let n: usize = lens.iter().sum();
            let mut want = DMatrix::zeros(n, 3);
            kn.for_each(|r, j, w| {
                for c in 0..3 {
                    want[(r, c)] += w * k[(j, c)];
                }
            });
            assert_eq!(kn.expand(&k, n), want, "every {f} rows");
        }
    }
}

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

    /// Σ wall·(b − its interpolation from the knots)² over every row and
    /// column — what `expand(sample(b))` leaves — stopping as soon as it
    /// exceeds `budget` (None): a grid that fails does so within a few
    /// rows, and expanding the whole matrix for each candidate grid was a
    /// third of the freedom's set-up.
    pub fn error2_within(&self, b: &DMatrix<f64>, wall: &[f64], budget: f64) -> Option<f64> {
        let f = self.f;
        let mut err2 = 0.0;
        for col in b.column_iter() {
            for &(r0, l, _) in &self.segs {
                for t in 0..l {
                    let j = t / f;
                    let (a, e) = (j * f, ((j + 1) * f).min(l - 1));
                    if t == a || e == a {
                        continue; // a knot: exact
                    }
                    let wb = (t - a) as f64 / (e - a) as f64;
                    let d = col[r0 + t] - ((1.0 - wb) * col[r0 + a] + wb * col[r0 + e]);
                    err2 += wall[r0 + t] * d * d;
                }
                if err2 > budget {
                    return None;
                }
            }
        }
        Some(err2)
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
            let err2 = k.error2_within(b, wall, rel_tol * rel_tol * norm2);
            if super::timing::timing() {
                match err2 {
                    Some(e) => eprintln!(
                        "diagnose timing: knots every {f} rows: error {:.1e}",
                        (e / norm2).sqrt()
                    ),
                    None => {
                        eprintln!("diagnose timing: knots every {f} rows: error > {rel_tol:.0e}")
                    }
                }
            }
            if let Some(e) = err2 {
                return (k, (e / norm2).sqrt());
            }
        }
    }
    (Knots::new(lens, 1), 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_streamed_error_is_what_the_expanded_knots_leave() {
        let lens = [5, 0, 17, 9];
        let n: usize = lens.iter().sum();
        let b = DMatrix::from_fn(n, 3, |r, c| ((r * r) as f64 * 0.013 + c as f64).sin());
        let wall: Vec<f64> = (0..n).map(|r| 1.0 + (r % 3) as f64).collect();
        for f in [2, 3, 4, 8] {
            let k = Knots::new(&lens, f);
            let d = &b - k.expand(&k.sample(&b), n);
            let want: f64 = d
                .column_iter()
                .map(|c| c.iter().zip(&wall).map(|(v, w)| w * v * v).sum::<f64>())
                .sum();
            let got = k.error2_within(&b, &wall, f64::INFINITY).unwrap();
            assert!(
                (got - want).abs() <= 1e-12 * want,
                "every {f}: {got} vs {want}"
            );
            assert!(want > 0.0);
            assert_eq!(k.error2_within(&b, &wall, 0.5 * want), None, "every {f}");
        }
    }

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

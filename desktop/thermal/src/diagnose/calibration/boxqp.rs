//! A small box-constrained quadratic program (the calibration's step and
//! the freedom left to candidates both solve one).

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use tcomp_numerics::linalg::dot;

/// min ½ xᵀAx − bᵀx subject to lo ≤ x ≤ hi by projected Gauss–Seidel
/// from `x0` (clamped), and the sweeps it took: the fallback of
/// `box_qp_exact`. A is read by columns (A symmetric: column i is row i),
/// contiguous, so the sweep's dot products vectorise. Capped, the sweeps
/// end unsettled on a large calibration (≈ 197 of 200 on the bench's
/// cases: its directions are near-collinear).
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

/// min ½ xᵀAx − bᵀx subject to lo ≤ x ≤ hi, exactly, by a primal active
/// set (A symmetric positive definite; lo ≤ 0 ≤ hi not required). The
/// iterate stays feasible: each step solves the free values with the
/// bound ones held (a Cholesky of the free block), moves toward that
/// solution until a value meets its bound (then held), and when the solve
/// is feasible releases the held value whose multiplier has the wrong
/// sign. Written by hand: nalgebra has no bound-constrained QP, and the
/// blocks are small (the knobs of a calibration). Falls back to the capped
/// sweeps from its last iterate after `4 n + 8` steps or a failed factor.
pub fn box_qp_exact(
    a: &DMatrix<f64>,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    x0: &[f64],
) -> (Vec<f64>, usize) {
    box_qp_active_set(a, None, b, (lo, hi), x0, None, None)
}

/// `box_qp_exact` given P = A⁻¹ too: a step then solves the held values'
/// multipliers (P_HH μ = x_H − (Pb)_H, z = Pb + P_{·H} μ) when fewer values
/// are held than free — a |H|² system instead of the free block's, the
/// same optimum. The freedom solves ≈ 800 of these per diagnosis with the
/// same A, so P is computed once.
pub fn box_qp_exact_inv(
    a: &DMatrix<f64>,
    a_inv: &DMatrix<f64>,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> (Vec<f64>, usize) {
    let pb = a_inv * nalgebra::DVector::from_column_slice(b);
    box_qp_active_set(
        a,
        Some((a_inv, pb.as_slice())),
        b,
        (lo, hi),
        pb.as_slice(),
        None,
        None,
    )
}

/// `box_qp_exact_inv` started from a guess of which values end on which
/// bound (`side`: −1 at lo, +1 at hi, 0 free), e.g. the solution of a
/// nearby problem: the free values start at their optimum with those held,
/// clamped. The optimum is unique (A positive definite), so the guess
/// changes only the steps taken to it: a candidate's projection is close to
/// the calibrated nominal's, whose active set takes ≈ 50 steps to find
/// from nothing.
pub fn box_qp_exact_inv_from(
    a: &DMatrix<f64>,
    a_inv: &DMatrix<f64>,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    side: &[i8],
) -> (Vec<f64>, usize) {
    let n = b.len();
    let pb = a_inv * nalgebra::DVector::from_column_slice(b);
    let held: Vec<bool> = side.iter().map(|&s| s != 0).collect();
    let x: Vec<f64> = (0..n)
        .map(|i| match side[i] {
            s if s < 0 => lo[i],
            s if s > 0 => hi[i],
            _ => 0.0,
        })
        .collect();
    let free: Vec<usize> = (0..n).filter(|&i| !held[i]).collect();
    let mut x0 = x.clone();
    let mut factor = None;
    match solve_held(a_inv, pb.as_slice(), &x, &held, &free, &mut factor) {
        Some(z) => free.iter().zip(z).for_each(|(&i, v)| x0[i] = v),
        None => return box_qp_exact_inv(a, a_inv, b, lo, hi),
    }
    box_qp_active_set(
        a,
        Some((a_inv, pb.as_slice())),
        b,
        (lo, hi),
        &x0,
        Some(&held),
        factor,
    )
}

/// The active-set steps from `x0` (`held0`: values held at their bound
/// from the start; `factor`: a factor a first solve already made).
fn box_qp_active_set(
    a: &DMatrix<f64>,
    inv: Option<(&DMatrix<f64>, &[f64])>,
    b: &[f64],
    (lo, hi): (&[f64], &[f64]),
    x0: &[f64],
    held0: Option<&[bool]>,
    mut factor: Option<Factor>,
) -> (Vec<f64>, usize) {
    let n = b.len();
    let mut x: Vec<f64> = (0..n).map(|i| x0[i].clamp(lo[i], hi[i])).collect();
    // held at a bound: the start's clamped values and those given held
    let mut held: Vec<bool> = (0..n)
        .map(|i| x[i] != x0[i] || held0.is_some_and(|h| h[i]))
        .collect();
    for step in 0..4 * n + 8 {
        let free: Vec<usize> = (0..n).filter(|&i| !held[i]).collect();
        let z = match inv {
            Some((p, pb)) if 2 * free.len() > n => solve_held(p, pb, &x, &held, &free, &mut factor),
            _ => solve_free(a, b, &x, &free, &mut factor),
        };
        let z = match z {
            Some(z) => z,
            None => break,
        };
        // largest step toward z that stays inside the box, and the value
        // (with the bound it meets) that limits it
        let (mut alpha, mut block) = (1.0f64, None);
        for (k, &i) in free.iter().enumerate() {
            let d = z[k] - x[i];
            let (room, bound) = if d > 0.0 {
                ((hi[i] - x[i]) / d, hi[i])
            } else if d < 0.0 {
                ((lo[i] - x[i]) / d, lo[i])
            } else {
                (f64::INFINITY, x[i])
            };
            if room < alpha {
                alpha = room.max(0.0);
                block = Some((i, bound));
            }
        }
        for (k, &i) in free.iter().enumerate() {
            x[i] = (x[i] + alpha * (z[k] - x[i])).clamp(lo[i], hi[i]);
        }
        if let Some((i, bound)) = block {
            x[i] = bound;
            held[i] = true;
            continue;
        }
        // feasible: release the held value that most wants to come back
        let mut worst = (0.0f64, None);
        let cols = a.as_slice();
        for i in (0..n).filter(|&i| held[i]) {
            // A symmetric: row i is column i (contiguous)
            let g = dot(&cols[i * n..(i + 1) * n], &x) - b[i];
            // at lo the objective must not fall inward (g ≥ 0), at hi g ≤ 0
            let pull = if x[i] <= lo[i] { -g } else { g };
            if pull > worst.0 + 1e-12 {
                worst = (pull, Some(i));
            }
        }
        match worst.1 {
            Some(i) => held[i] = false,
            None => return (x, step + 1),
        }
    }
    let (x, sweeps) = box_qp_from(a, b, lo, hi, &x);
    (x, 4 * n + 8 + sweeps)
}

/// The Cholesky factor of the block a step solves (A over the free
/// values, or P = A⁻¹ over the held ones), kept from step to step: a step
/// holds or releases one value, and updating the factor for that costs
/// O(k²) where factoring anew costs O(k³) (it was a third of the box QP).
pub(crate) struct Factor {
    /// Over the held values (P_HH), not the free ones (A_FF).
    held: bool,
    set: Vec<usize>,
    chol: Cholesky<f64, Dyn>,
}

/// The factor of `m` over `set` (sorted) for the `held` kind of step:
/// the cached one as it is, updated by one value when the set grew or
/// shrank by one, else factored anew (None: not positive definite).
fn factor_of<'f>(
    cache: &'f mut Option<Factor>,
    m: &DMatrix<f64>,
    set: &[usize],
    held: bool,
) -> Option<&'f Cholesky<f64, Dyn>> {
    let updated = cache.take().and_then(|f| {
        if f.held != held {
            return None;
        }
        let old = &f.set;
        // the first place the two sets differ
        let j = old.iter().zip(set).position(|(a, b)| a != b);
        let chol = if set.len() == old.len() {
            (j.is_none()).then_some(f.chol)?
        } else if set.len() == old.len() + 1 {
            let j = j.unwrap_or(old.len());
            (old[j..] == set[j + 1..]).then_some(())?;
            let col = DVector::from_fn(set.len(), |r, _| m[(set[r], set[j])]);
            f.chol.insert_column(j, col)
        } else if set.len() + 1 == old.len() {
            let j = j.unwrap_or(set.len());
            (old[j + 1..] == set[j..]).then_some(())?;
            f.chol.remove_column(j)
        } else {
            return None;
        };
        // an update that lost positive definiteness: factor anew
        let l = chol.l_dirty();
        (0..l.nrows())
            .all(|i| l[(i, i)] > 0.0 && l[(i, i)].is_finite())
            .then_some(chol)
    });
    let chol = match updated {
        Some(c) => c,
        None => DMatrix::from_fn(set.len(), set.len(), |r, c| m[(set[r], set[c])]).cholesky()?,
    };
    *cache = Some(Factor {
        held,
        set: set.to_vec(),
        chol,
    });
    cache.as_ref().map(|f| &f.chol)
}

/// The free values' optimum with the held ones fixed: A_FF z = b_F − A_FH x_H.
fn solve_free(
    a: &DMatrix<f64>,
    b: &[f64],
    x: &[f64],
    free: &[usize],
    factor: &mut Option<Factor>,
) -> Option<Vec<f64>> {
    let n = b.len();
    let nf = free.len();
    if nf == 0 {
        return Some(Vec::new());
    }
    let is_free = {
        let mut v = vec![false; n];
        free.iter().for_each(|&i| v[i] = true);
        v
    };
    let rhs = nalgebra::DVector::from_fn(nf, |r, _| {
        let i = free[r];
        b[i] - (0..n)
            .filter(|&j| !is_free[j])
            .map(|j| a[(i, j)] * x[j])
            .sum::<f64>()
    });
    let z = factor_of(factor, a, free, false)?.solve(&rhs);
    Some(z.as_slice().to_vec())
}

/// The same optimum from P = A⁻¹: the held values' multipliers μ solve
/// P_HH μ = x_H − (Pb)_H, and the free values are (Pb)_F + P_FH μ.
fn solve_held(
    p: &DMatrix<f64>,
    pb: &[f64],
    x: &[f64],
    held: &[bool],
    free: &[usize],
    factor: &mut Option<Factor>,
) -> Option<Vec<f64>> {
    let h: Vec<usize> = (0..pb.len()).filter(|&i| held[i]).collect();
    if h.is_empty() {
        return Some(free.iter().map(|&i| pb[i]).collect());
    }
    let rhs = nalgebra::DVector::from_fn(h.len(), |r, _| x[h[r]] - pb[h[r]]);
    let mu = factor_of(factor, p, &h, true)?.solve(&rhs);
    Some(
        free.iter()
            .map(|&i| {
                pb[i]
                    + h.iter()
                        .zip(mu.iter())
                        .map(|(&j, m)| p[(i, j)] * m)
                        .sum::<f64>()
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random SPD problem with a few strongly coupled directions.
    fn problem(n: usize, seed: u64) -> (DMatrix<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut g = tcomp_numerics::rng::Rng::paired(seed);
        let m = DMatrix::from_fn(n + 3, n, |_, _| g.uniform() - 0.5);
        let mut a = m.transpose() * m;
        for i in 0..n {
            a[(i, i)] += 0.05;
        }
        let b: Vec<f64> = (0..n).map(|_| 4.0 * (g.uniform() - 0.5)).collect();
        let lo = vec![-0.3; n];
        let hi = vec![0.25; n];
        (a, b, lo, hi)
    }

    fn objective(a: &DMatrix<f64>, b: &[f64], x: &[f64]) -> f64 {
        let xv = nalgebra::DVector::from_column_slice(x);
        0.5 * (xv.transpose() * a * &xv)[(0, 0)] - b.iter().zip(x).map(|(p, q)| p * q).sum::<f64>()
    }

    #[test]
    fn the_exact_box_qp_meets_the_kkt_conditions_and_beats_the_capped_sweeps() {
        for seed in 0..20 {
            let n = 30;
            let (a, b, lo, hi) = problem(n, seed);
            let (x, _) = box_qp_exact(&a, &b, &lo, &hi, &vec![0.0; n]);
            for i in 0..n {
                assert!(
                    x[i] >= lo[i] - 1e-12 && x[i] <= hi[i] + 1e-12,
                    "seed {seed}: x{i} {}",
                    x[i]
                );
                let g: f64 = (0..n).map(|j| a[(i, j)] * x[j]).sum::<f64>() - b[i];
                let inside = x[i] > lo[i] + 1e-9 && x[i] < hi[i] - 1e-9;
                if inside {
                    assert!(g.abs() < 1e-7, "seed {seed}: gradient {g} at free x{i}");
                } else if x[i] <= lo[i] + 1e-9 {
                    assert!(g > -1e-7, "seed {seed}: x{i} at lo wants up ({g})");
                } else {
                    assert!(g < 1e-7, "seed {seed}: x{i} at hi wants down ({g})");
                }
            }
            let inv = a.clone().cholesky().unwrap().inverse();
            let (xi, _) = box_qp_exact_inv(&a, &inv, &b, &lo, &hi);
            for i in 0..n {
                assert!(
                    (xi[i] - x[i]).abs() < 1e-9,
                    "seed {seed}: x{i} {} vs {}",
                    xi[i],
                    x[i]
                );
            }
            let (gs, _) = box_qp_from(&a, &b, &lo, &hi, &vec![0.0; n]);
            assert!(
                objective(&a, &b, &x) <= objective(&a, &b, &gs) + 1e-12,
                "seed {seed}"
            );
        }
    }

    #[test]
    fn a_factor_updated_by_one_value_solves_as_a_fresh_one() {
        let (a, ..) = problem(12, 3);
        let mut cache = None;
        // grow at the front, middle and end, shrink, keep, jump
        let sets: [&[usize]; 8] = [
            &[2, 5, 9],
            &[0, 2, 5, 9],
            &[0, 2, 5, 7, 9],
            &[0, 2, 5, 7, 9, 11],
            &[0, 5, 7, 9, 11],
            &[0, 5, 7, 9, 11],
            &[0, 5, 7, 9],
            &[1, 3, 4],
        ];
        for set in sets {
            let rhs = DVector::from_fn(set.len(), |r, _| (r as f64 * 0.7).sin());
            let got = factor_of(&mut cache, &a, set, true).unwrap().solve(&rhs);
            let sub = DMatrix::from_fn(set.len(), set.len(), |r, c| a[(set[r], set[c])]);
            let want = sub.cholesky().unwrap().solve(&rhs);
            assert!((got - &want).amax() <= 1e-9 * want.amax(), "{set:?}");
            assert_eq!(cache.as_ref().unwrap().set, set);
        }
        // the other kind of block is factored anew, not updated
        let f = factor_of(&mut cache, &a, &[1, 3, 4, 6], false).unwrap();
        assert_eq!(f.l_dirty().nrows(), 4);
        assert!(!cache.as_ref().unwrap().held);
    }

    #[test]
    fn a_guessed_active_set_changes_the_steps_not_the_optimum() {
        for seed in 0..20 {
            let n = 30;
            let (a, b, lo, hi) = problem(n, seed);
            let inv = a.clone().cholesky().unwrap().inverse();
            let (x, steps) = box_qp_exact_inv(&a, &inv, &b, &lo, &hi);
            let right: Vec<i8> = (0..n)
                .map(|i| i8::from(x[i] >= hi[i]) - i8::from(x[i] <= lo[i]))
                .collect();
            // every value guessed on the wrong bound
            let wrong: Vec<i8> = right.iter().map(|s| if *s == 0 { 1 } else { -s }).collect();
            for guess in [&right, &wrong, &vec![0; n]] {
                let (xg, sg) = box_qp_exact_inv_from(&a, &inv, &b, &lo, &hi, guess);
                for i in 0..n {
                    assert!(
                        (xg[i] - x[i]).abs() < 1e-9,
                        "seed {seed}: x{i} {} vs {}",
                        xg[i],
                        x[i]
                    );
                }
                if guess == &right {
                    assert!(
                        sg <= steps.min(2),
                        "seed {seed}: {sg} steps from the right guess"
                    );
                }
            }
        }
    }
}

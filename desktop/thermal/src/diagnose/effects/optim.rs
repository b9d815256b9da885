//! Bounded optimisers on the unit cube [0, 1]^d for the effects' fits:
//! Nelder–Mead for several parameters, Brent's method (argmin) for one.
//! Both take an objective that evaluates several points at once (a
//! batch shares the freedom's pass over B̃).

/// Bounded Nelder–Mead on [0,1]^d (points clamped). Returns (best u, value, evals).
/// `f` evaluates several points at once (the start's simplex and a
/// shrink's points share the freedom's pass).
pub(crate) fn nelder_mead<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    f: &mut F,
    x0: &[f64],
    step: f64,
    max_evals: usize,
) -> (Vec<f64>, f64, usize) {
    // Hand-written although argmin (a dependency, used for Brent below) has a
    // NelderMead: argmin's evaluates one point per `cost` call, is unbounded
    // and stops on the spread of the simplex's values only. Here (1) the
    // start's simplex and a shrink's d points go to `f` as one batch (one
    // pass of the freedom over B̃ for all of them), (2) every trial point is
    // clamped to [0, 1]^d, (3) the budget is counted in evaluations
    // (`max_evals`, a shrink costs d), not iterations, and (4) it stops when
    // the values agree to 1e-6 (relative) AND the simplex is narrower than
    // 1e-4 in u. The sequence of trial points (reflection −1, expansion −2,
    // contraction ±0.5, shrink ½ towards the best) fixes every fitted
    // parameter and so every verdict bit for bit: the tests and the benches'
    // figures assert those, so a switch would be a behaviour change.
    let d = x0.len();
    let clamp = |x: &mut Vec<f64>| x.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    let mut pts: Vec<Vec<f64>> = vec![x0.to_vec()];
    for i in 0..d {
        let mut x = x0.to_vec();
        x[i] = if x[i] + step <= 1.0 {
            x[i] + step
        } else {
            x[i] - step
        };
        pts.push(x);
    }
    let mut evals = pts.len();
    let mut vals: Vec<f64> = f(&pts);
    while evals < max_evals {
        let mut idx: Vec<usize> = (0..=d).collect();
        idx.sort_by(|&a, &b| vals[a].total_cmp(&vals[b]));
        pts = idx.iter().map(|&i| pts[i].clone()).collect();
        vals = idx.iter().map(|&i| vals[i]).collect();
        if (vals[d] - vals[0]).abs() < 1e-6 * (1.0 + vals[0].abs()) {
            let spread = (0..d)
                .map(|j| {
                    pts.iter().map(|p| p[j]).fold(f64::MIN, f64::max)
                        - pts.iter().map(|p| p[j]).fold(f64::MAX, f64::min)
                })
                .fold(0.0, f64::max);
            if spread < 1e-4 {
                break;
            }
        }
        let cen: Vec<f64> = (0..d)
            .map(|j| pts[..d].iter().map(|p| p[j]).sum::<f64>() / d as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            let mut x: Vec<f64> = (0..d).map(|j| cen[j] + t * (pts[d][j] - cen[j])).collect();
            clamp(&mut x);
            x
        };
        let xr = along(-1.0);
        let fr = f(std::slice::from_ref(&xr))[0];
        evals += 1;
        if fr < vals[0] {
            let xe = along(-2.0);
            let fe = f(std::slice::from_ref(&xe))[0];
            evals += 1;
            if fe < fr {
                pts[d] = xe;
                vals[d] = fe;
            } else {
                pts[d] = xr;
                vals[d] = fr;
            }
        } else if fr < vals[d - 1] {
            pts[d] = xr;
            vals[d] = fr;
        } else {
            let (xc, fc) = if fr < vals[d] {
                let x = along(-0.5);
                let v = f(std::slice::from_ref(&x))[0];
                (x, v)
            } else {
                let x = along(0.5);
                let v = f(std::slice::from_ref(&x))[0];
                (x, v)
            };
            evals += 1;
            if fc < vals[d].min(fr) {
                pts[d] = xc;
                vals[d] = fc;
            } else {
                for i in 1..=d {
                    for j in 0..d {
                        pts[i][j] = pts[0][j] + 0.5 * (pts[i][j] - pts[0][j]);
                    }
                }
                let shrunk = f(&pts[1..]);
                vals[1..].copy_from_slice(&shrunk);
                evals += d;
            }
        }
    }
    let best = (0..=d)
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    (pts[best].clone(), vals[best], evals)
}

/// Brent's absolute tolerance in u: the fit's criterion is flat to
/// second order at its minimum, so 3·10⁻⁴ of a parameter's range (0.2 %
/// of a time constant's factor 600) moves it by far less than the noise.
const BRENT_T: f64 = 1e-4;

/// The minimum of `f` over [c − w, c + w] ∩ [0, 1] by Brent's method
/// (argmin's `BrentOpt`, to 3·`BRENT_T` in u), and the
/// interval's end on [0, 1]'s edge when it is lower (an effect at its
/// parameter's bound); the cell's centre `c` (its value known) when
/// neither is lower, or Brent fails. Returns (u, value, evaluations).
pub(crate) fn brent_in_cell<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    f: &mut F,
    (c, jc): (f64, f64),
    w: f64,
    max_evals: usize,
) -> (Vec<f64>, f64, usize) {
    use argmin::core::{CostFunction, Executor};
    use std::cell::RefCell;
    struct Cost<'a, F>(RefCell<(&'a mut F, usize)>);
    impl<F: FnMut(&[Vec<f64>]) -> Vec<f64>> CostFunction for Cost<'_, F> {
        type Param = f64;
        type Output = f64;
        fn cost(&self, u: &f64) -> Result<f64, argmin::core::Error> {
            let mut g = self.0.borrow_mut();
            g.1 += 1;
            Ok((g.0)(&[vec![*u]])[0])
        }
    }
    let (a, b) = ((c - w).max(0.0), (c + w).min(1.0));
    let cost = Cost(RefCell::new((f, 0)));
    let solver = argmin::solver::brent::BrentOpt::new(a, b).set_tolerance(1.5e-8, BRENT_T);
    let best = Executor::new(cost, solver)
        .configure(|s| s.max_iters(max_evals as u64))
        .run()
        .ok()
        .and_then(|r| {
            let st = r.state();
            let (u, j) = (st.best_param?, st.best_cost);
            let n = r.problem.problem.as_ref().map_or(0, |p| p.0.borrow().1);
            Some((u, j, n))
        });
    let (mut u, mut j, mut n) = best.unwrap_or((c, jc, 0));
    if j.is_nan() || j > jc {
        (u, j) = (c, jc);
    }
    for edge in [0.0, 1.0] {
        if (edge == a || edge == b) && (u - edge).abs() < 3.0 * BRENT_T {
            let je = f(&[vec![edge]])[0];
            n += 1;
            if je < j {
                (u, j) = (edge, je);
            }
        }
    }
    (vec![u], j, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    type Count = std::rc::Rc<std::cell::Cell<usize>>;

    /// Counts the points a batch-evaluating objective is asked for.
    fn counted(g: impl Fn(f64) -> f64) -> (impl FnMut(&[Vec<f64>]) -> Vec<f64>, Count) {
        let n = Count::default();
        let n2 = n.clone();
        let f = move |us: &[Vec<f64>]| {
            n2.set(n2.get() + us.len());
            us.iter().map(|u| g(u[0])).collect()
        };
        (f, n)
    }

    #[test]
    fn brent_finds_an_inner_minimum_in_fewer_trials_than_nelder_mead() {
        // a smooth, asymmetric bottom at u = 0.3171
        let g = |u: f64| (u - 0.3171).powi(2) * (1.0 + 3.0 * (u - 0.3171)) + 7.0;
        let (mut f, n) = counted(g);
        let (u, j, e) = brent_in_cell(&mut f, (0.3, g(0.3)), 1.0 / 9.0, 100);
        assert!((u[0] - 0.3171).abs() < 3.0 * BRENT_T, "{u:?}");
        assert!((j - 7.0).abs() < 1e-6);
        assert_eq!(e, n.get(), "every trial counted");
        let (mut f, n_nm) = counted(g);
        let (u_nm, _, _) = nelder_mead(&mut f, &[0.3], 0.25, 100);
        assert!((u_nm[0] - 0.3171).abs() < 1e-3);
        assert!(
            n.get() < n_nm.get(),
            "Brent {} trials, Nelder–Mead {}",
            n.get(),
            n_nm.get()
        );
    }

    #[test]
    fn brent_keeps_the_cell_centre_when_every_trial_fails() {
        // a simulation that fails away from the centre (∞)
        let g = |u: f64| {
            if (u - 0.5).abs() < 1e-12 {
                3.0
            } else {
                f64::INFINITY
            }
        };
        let (mut f, _) = counted(g);
        let (u, j, _) = brent_in_cell(&mut f, (0.5, 3.0), 1.0 / 9.0, 100);
        assert_eq!((u[0], j), (0.5, 3.0));
    }

    #[test]
    fn brent_returns_the_bound_itself_when_the_minimum_is_on_it() {
        for (c, edge) in [(0.5 / 9.0, 0.0), (8.5 / 9.0, 1.0)] {
            // falls towards the edge all the way
            let g = move |u: f64| (u - edge).abs() + 2.0;
            let (mut f, _) = counted(g);
            let (u, j, _) = brent_in_cell(&mut f, (c, g(c)), 1.0 / 9.0, 100);
            assert_eq!(u[0], edge);
            assert_eq!(j, 2.0);
        }
    }
}

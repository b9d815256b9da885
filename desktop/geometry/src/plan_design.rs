//! Designing a line plan by the criterion of [`crate::plan`]: greedy
//! addition of lines from a candidate pool to fixed base lines, then
//! exchange, each step scored by the posterior's worst-term σ (Woodbury
//! updates of the posterior covariance). `examples/plan_design.rs` runs it
//! for the default volume; [`crate::plan::rich_additions`] holds its choice.

use nalgebra::DMatrix;

use crate::kinematics::Structure;
use crate::lines::LineSpec;
use crate::plan::{
    line_rows, nuisance_sd, objective, posterior_cov, reading_sigma, setup, variances, whitened,
    worst_variances, CLASS_DEGREE,
};

/// Greedy addition, then exchange, of `add` lines from `pool` to the fixed
/// `base` lines, on the stated criterion at `noise_um`. Returns the chosen
/// pool indices in the order they were added and the objective after each
/// addition (worst σ in tolerance units + a hundredth of the mean).
pub fn design(
    st: &Structure,
    stroke: [f64; 3],
    base: &[LineSpec],
    pool: &[LineSpec],
    add: usize,
    noise_um: f64,
) -> (Vec<usize>, Vec<f64>) {
    let s = setup(CLASS_DEGREE);
    let sigma = reading_sigma(noise_um);
    let white = |l: &LineSpec| {
        let (a, sc) = line_rows(st, stroke, &s.cols, l);
        whitened(&a, &sc, sigma, nuisance_sd(l))
    };
    let base_b: Vec<DMatrix<f64>> = base.iter().map(white).collect();
    let cand: Vec<DMatrix<f64>> = pool.iter().map(white).collect();
    let mut c = posterior_cov(&s, &base_b);
    // The objective with candidate b added to the posterior c (Woodbury).
    let with = |c: &DMatrix<f64>,
                v0: &[f64],
                b: &DMatrix<f64>|
     -> Option<(f64, DMatrix<f64>, DMatrix<f64>)> {
        let bc = b * c;
        let k = DMatrix::identity(b.nrows(), b.nrows()) + &bc * b.transpose();
        let kc = k.cholesky()?;
        let g = &bc * &s.phi;
        let kg = kc.solve(&g);
        let var: Vec<f64> = (0..g.ncols())
            .map(|q| v0[q] - g.column(q).dot(&kg.column(q)))
            .collect();
        Some((objective(&s, &worst_variances(&s, &var)), bc, kc.inverse()))
    };
    let update = |c: &DMatrix<f64>, bc: &DMatrix<f64>, kinv: &DMatrix<f64>| -> DMatrix<f64> {
        c - bc.transpose() * kinv * bc
    };
    let mut chosen: Vec<usize> = Vec::new();
    let mut trace = Vec::new();
    for _ in 0..add {
        let v0 = variances(&s, &c);
        let mut best: Option<(f64, usize, DMatrix<f64>, DMatrix<f64>)> = None;
        for (i, b) in cand.iter().enumerate() {
            if chosen.contains(&i) {
                continue;
            }
            if let Some((j, bc, kinv)) = with(&c, &v0, b) {
                if best.as_ref().is_none_or(|x| j < x.0) {
                    best = Some((j, i, bc, kinv));
                }
            }
        }
        let Some((j, i, bc, kinv)) = best else { break };
        c = update(&c, &bc, &kinv);
        chosen.push(i);
        trace.push(j);
    }
    // Exchange: replace an added line by a better candidate while one is found.
    for _pass in 0..3 {
        let mut improved = false;
        for slot in 0..chosen.len() {
            let v_now = objective(&s, &worst_variances(&s, &variances(&s, &c)));
            // Remove the slot's line: (M − BᵀB)⁻¹ = C + CBᵀ(I − BCBᵀ)⁻¹BC.
            let b = &cand[chosen[slot]];
            let bc = b * &c;
            let k = DMatrix::identity(b.nrows(), b.nrows()) - &bc * b.transpose();
            let Some(kinv) = k.try_inverse() else {
                continue;
            };
            let c_minus = &c + bc.transpose() * kinv * &bc;
            let v0 = variances(&s, &c_minus);
            let mut best: Option<(f64, usize, DMatrix<f64>, DMatrix<f64>)> = None;
            for (i, b) in cand.iter().enumerate() {
                if chosen.contains(&i) {
                    continue;
                }
                if let Some((j, bc, kinv)) = with(&c_minus, &v0, b) {
                    if best.as_ref().is_none_or(|x| j < x.0) {
                        best = Some((j, i, bc, kinv));
                    }
                }
            }
            if let Some((j, i, bc, kinv)) = best {
                if j < v_now - 1e-9 {
                    c = update(&c_minus, &bc, &kinv);
                    chosen[slot] = i;
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
    if let Some(last) = trace.last_mut() {
        *last = objective(&s, &worst_variances(&s, &variances(&s, &c)));
    }
    (chosen, trace)
}

//! The joint fit (`joint`) with the generic linear model (issue 49 item 3):
//! when the lines determine the machine without an assumed shape (at
//! least `generic::MIN_LINES` lines, no null direction — `identify`'s rule)
//! the linear axes are the generic identifier's (Legendre degree 16 per
//! error, prior by the evidence), not the polynomial model, whose misfit
//! on waves in pitch, yaw or roll aliases into the location errors and the
//! spindle's direction through the tool length.
//!
//! The generic identification is Gaussian given its hyperparameters: the
//! lines leave the error columns θ at N(θ̂, Σ). Adding the R-test files,
//!
//!   R-test rows: (d − lin(θ̂)) / σ_R = (A_rot x + J δ) / σ_R
//!   prior rows:  0 = z,  δ = L z,  Σ = L Lᵀ
//!
//! is the exact posterior of the rotary errors and δ given both data sets
//! (the lines enter through θ̂ and Σ, their scales and zeros integrated
//! out): eliminating z is the generalised least-squares fit with the
//! covariance σ_R² I + J Σ Jᵀ, so the linear model's uncertainty is
//! carried into every rotary σ. z are the whitened modes of Σ (L = V Λ^½
//! from its eigen-decomposition, modes below 1e-12 of the largest left
//! out), so the prior rows are the identity and never a rank problem. σ_R
//! from the fit with θ̂ as known input, then once more from the joint fit's
//! own R-test residual. The adequacy test holds each file out with the
//! prior rows kept and not rescaled (they are in units of their σ).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, SymmetricEigen, Vector3};

use super::columns::{Col, RotaryOptions};
use super::identify::{solve, Design, JointLinear, RotaryIdentification};
use super::joint::{design_and_noise, rms};
use super::model::Linear;
use crate::errors::GeometricErrors;
use crate::generic::Generic;
use crate::identify::LineObs;
use crate::kinematics::Structure;
use crate::rtest::RTestFile;

/// The linear axes as the generic identifier left them: its posterior and
/// the lines it came from (averaged runs).
#[derive(Clone, Copy)]
pub struct GenericPrior<'a> {
    pub structure: &'a Structure,
    pub generic: &'a Generic,
    pub lines: &'a [LineObs],
}

/// L with Σ = L Lᵀ over the modes of Σ above 1e-12 of the largest.
fn whitening(cov: DMatrix<f64>) -> Result<DMatrix<f64>> {
    let n = cov.nrows();
    let eig = SymmetricEigen::new(cov);
    let lmax = eig.eigenvalues.max();
    if !(lmax > 0.0) {
        bail!("internal: the generic linear model has no posterior variance");
    }
    let modes: Vec<usize> = (0..n)
        .filter(|&i| eig.eigenvalues[i] > 1e-12 * lmax)
        .collect();
    Ok(DMatrix::from_fn(n, modes.len(), |r, c| {
        eig.eigenvectors[(r, modes[c])] * eig.eigenvalues[modes[c]].sqrt()
    }))
}

/// J: each R-test reading's sensitivity to the error columns (workpiece
/// frame, three rows per reading).
fn sensitivity_rows(d: &Design, p: &GenericPrior, n: usize) -> DMatrix<f64> {
    let mut j = DMatrix::<f64>::zeros(3 * d.poses.len(), n);
    for (k, (s, pos, tool)) in d.poses.iter().enumerate() {
        let m: Vec<Vec<f64>> = (0..3)
            .map(|dir| {
                let mut u = [0.0; 3];
                u[dir] = 1.0;
                p.generic.error_row(p.structure, u, *pos, *tool)
            })
            .collect();
        for c in 0..n {
            let v = s.lin_rot * Vector3::new(m[0][c], m[1][c], m[2][c]);
            for dir in 0..3 {
                j[(3 * k + dir, c)] = v[dir];
            }
        }
    }
    j
}

/// The weighted joint problem at `sigma_r`, solved.
fn joint_solve(
    files: &[RTestFile],
    o: &RotaryOptions,
    d: &Design,
    jl: &DMatrix<f64>,
    sigma_r: f64,
) -> Result<RotaryIdentification> {
    let (mr, nr, nz) = (d.b.len(), d.cols.len(), jl.ncols());
    let mut cols = d.cols.clone();
    cols.extend((0..nz).map(Col::Lin));
    let mut a = DMatrix::<f64>::zeros(mr + nz, nr + nz);
    let mut b = DVector::<f64>::zeros(mr + nz);
    a.view_mut((0, 0), (mr, nr)).copy_from(&(&d.a / sigma_r));
    a.view_mut((0, nr), (mr, nz)).copy_from(&(jl / sigma_r));
    a.view_mut((mr, nr), (nz, nz)).fill_with_identity();
    b.rows_mut(0, mr).copy_from(&(&d.b / sigma_r));
    let mut id = solve(files, o, &cols, a, b, &d.reference, mr, sigma_r)?;
    if let Some(st) = id.design.as_mut() {
        st.prior_rows = true;
    }
    if id.linear_delta.len() != nz {
        bail!(
            "internal: joint fit returned {} linear modes for {nz}",
            id.linear_delta.len()
        );
    }
    Ok(id)
}

/// Rotary errors and the corrected generic linear model from the R-test
/// files and the lines' generic posterior (module doc).
pub fn identify_rotary_joint_generic(
    files: &[RTestFile],
    p: &GenericPrior,
    o: &RotaryOptions,
) -> Result<(RotaryIdentification, GeometricErrors)> {
    let g = p.generic;
    let lin = Linear {
        structure: p.structure,
        errors: &g.fit.errors,
    };
    let (d, plain, sigma_r0) = design_and_noise(files, lin, o)?;
    let mr = d.b.len();
    let dof = |rank: usize| mr.saturating_sub(rank).max(1) as f64;
    if !(sigma_r0 > 0.0) {
        bail!("joint fit: the R-test files fit without residual (noise-free data); take the linear model as known input (identify-rotary --linear-fixed)");
    }
    let (_, cov) = g.error_posterior();
    let l = whitening(cov)?;
    let jrows = sensitivity_rows(&d, p, l.nrows());
    let jl = &jrows * &l;
    let nz = jl.ncols();
    let first = joint_solve(files, o, &d, &jl, sigma_r0)?;
    let rank_rot = first.rank.saturating_sub(nz);
    let sigma_r = first.residual_rms_um * (mr as f64 / dof(rank_rot)).sqrt();
    let mut id = if sigma_r > 0.0 {
        joint_solve(files, o, &d, &jl, sigma_r)?
    } else {
        first
    };
    let z = DVector::from_column_slice(&id.linear_delta);
    let delta = &l * &z;
    let change = &jrows * &delta;
    id.linear = Some(JointLinear {
        linear_model: "generic",
        sigma_lines_um: g.fit.hyper.noise_um,
        sigma_rtest_um: sigma_r.max(0.0),
        change_at_rtest_rms_um: rms(change.as_slice()),
        line_residual_rms_um: g.line_residual_rms(p.structure, p.lines, delta.as_slice()),
        line_residual_rms_um_before: g.line_residual_rms(p.structure, p.lines, &[]),
        joint_condition_number: id.condition_number,
        linear_unknowns: nz,
        line_readings: nz,
    });
    id.condition_number = plain.condition_number;
    Ok((id, g.errors_with(delta.as_slice())))
}

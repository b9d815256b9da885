//! The SVD the least-squares identifications share (`identify`,
//! `adequacy`, `rotary::identify` and its null directions): the design's
//! columns scaled to unit norm, so that the singular values compare like
//! with like, and the completion of a thin SVD's right vectors to a basis
//! (the null directions a design with fewer rows than unknowns has and the
//! thin SVD does not list).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

/// Each column's norm (1 for a zero column) and the design with its
/// columns divided by them.
fn unit_columns(a: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let n = a.ncols();
    let norms: Vec<f64> = (0..n)
        .map(|j| a.column(j).norm())
        .map(|v| if v > 0.0 { v } else { 1.0 })
        .collect();
    let mut an = a.clone();
    for j in 0..n {
        an.column_mut(j).scale_mut(1.0 / norms[j]);
    }
    (norms, an)
}

/// A thin SVD on unit-norm columns: (each column's norm, 1 for a zero
/// column — unknown j of the unit problem is unknown j of the design times
/// `norms[j]` —, U, Vᵀ, the singular values).
pub(crate) type UnitSvd = (Vec<f64>, DMatrix<f64>, DMatrix<f64>, DVector<f64>);

/// The thin SVD of `a` with unit-norm columns.
pub(crate) fn unit_svd(a: &DMatrix<f64>) -> Result<UnitSvd> {
    let (norms, an) = unit_columns(a);
    let svd = an.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        bail!("internal: SVD without U or Vᵀ");
    };
    Ok((norms, u, vt, svd.singular_values))
}

/// The unit vectors that complete the orthonormal `basis` of Rⁿ
/// (Gram–Schmidt on the unit vectors e₁ … eₙ in turn), in the order found;
/// `basis` ends up holding them too.
pub(crate) fn complete_basis(basis: &mut Vec<DVector<f64>>, n: usize) -> Vec<DVector<f64>> {
    let mut added = Vec::new();
    for k in 0..n {
        let mut v = DVector::zeros(n);
        v[k] = 1.0;
        for q in basis.iter() {
            let d = q.dot(&v);
            v -= q * d;
        }
        if v.norm() > 1e-6 {
            v /= v.norm();
            basis.push(v.clone());
            added.push(v);
        }
    }
    added
}

//! What R-test files cannot see (`identify`): the null directions of the
//! fit, the error names in each, and why (rtest.md's known cases first:
//! an axis that never moves, a nest on the C axis, too few non-collinear
//! nest positions, sensors that move together).

use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;
use std::collections::BTreeSet;

use super::columns::{Col, RotaryOptions};
use crate::identify::NULL_WEIGHT;
use crate::rtest::RTestFile;
use crate::unit_svd::complete_basis;

/// One direction the files cannot see: its error names and why.
#[derive(Clone, Debug, Serialize)]
pub struct Unobservable {
    pub terms: Vec<String>,
    pub why: String,
    pub singular_value: f64,
    /// Largest weights of the unit-norm null direction.
    pub combination: Vec<(String, f64)>,
}

/// Distinct nest positions of the files and how many of them are not collinear (1, 2 or 3).
pub(crate) fn nest_spread(files: &[RTestFile]) -> (usize, usize, bool) {
    let mut nests: Vec<[f64; 3]> = Vec::new();
    for f in files {
        if !nests
            .iter()
            .any(|n| (0..3).all(|k| (n[k] - f.nest_mm[k]).abs() < 0.5))
        {
            nests.push(f.nest_mm);
        }
    }
    let on_axis = nests.iter().all(|n| n[0].hypot(n[1]) < 1.0);
    let span = match nests.len() {
        0 | 1 => nests.len(),
        _ => {
            let d: Vec<Vector3<f64>> = nests[1..]
                .iter()
                .map(|n| Vector3::from(*n) - Vector3::from(nests[0]))
                .collect();
            let m = DMatrix::from_fn(3, d.len(), |i, j| d[j][i]);
            let sv = m.svd(false, false).singular_values;
            1 + sv.iter().filter(|s| **s > 1.0).count().min(2)
        }
    };
    (nests.len(), span, on_axis)
}

/// Null directions: right singular vectors with a small singular value,
/// and the complement of the row space when there are fewer rows than unknowns.
pub(crate) fn null_directions(
    sv: &[f64],
    vt: &DMatrix<f64>,
    tol: f64,
    m: usize,
    n: usize,
) -> Vec<(DVector<f64>, f64)> {
    let mut null: Vec<(DVector<f64>, f64)> = (0..sv.len())
        .filter(|&i| sv[i] <= tol)
        .map(|i| (vt.row(i).transpose(), sv[i]))
        .collect();
    if m < n {
        let mut basis: Vec<DVector<f64>> = (0..sv.len()).map(|i| vt.row(i).transpose()).collect();
        null.extend(complete_basis(&mut basis, n).into_iter().map(|v| (v, 0.0)));
    }
    null
}

/// The unobservable directions with their terms and reasons, every term
/// in one, and the columns in one.
pub(crate) fn describe_null(
    files: &[RTestFile],
    o: &RotaryOptions,
    cols: &[Col],
    null: Vec<(DVector<f64>, f64)>,
) -> (Vec<Unobservable>, BTreeSet<String>, BTreeSet<usize>) {
    let (nests, span, on_axis) = nest_spread(files);
    let moves = |f: fn(&crate::rtest::RTestRow) -> f64| {
        files
            .iter()
            .flat_map(|f| f.rows.iter())
            .any(|r| f(r).abs() > 1e-6)
    };
    let (a_moves, c_moves) = (moves(|r| r.a_deg), moves(|r| r.c_deg));
    let mut unobservable = Vec::new();
    let mut unobs_terms = BTreeSet::new();
    let mut unobs_cols = BTreeSet::new();
    for (v, s) in null {
        let mut terms = BTreeSet::new();
        let mut comb: Vec<(String, f64)> = Vec::new();
        for (j, w) in v.iter().enumerate() {
            if w.abs() > NULL_WEIGHT {
                terms.extend(cols[j].terms(o));
                comb.push((cols[j].name(o, files), *w));
                unobs_cols.insert(j);
            }
        }
        comb.sort_by(|p, q| q.1.abs().total_cmp(&p.1.abs()));
        comb.truncate(8);
        let why = reason(&terms, nests, span, on_axis, a_moves, c_moves, s);
        unobs_terms.extend(terms.iter().cloned());
        unobservable.push(Unobservable {
            terms: terms.into_iter().collect(),
            why,
            singular_value: s,
            combination: comb,
        });
    }
    (unobservable, unobs_terms, unobs_cols)
}

/// Why the terms of one null direction cannot be told apart (rtest.md's known cases first).
fn reason(
    terms: &BTreeSet<String>,
    nests: usize,
    span: usize,
    on_axis: bool,
    a_moves: bool,
    c_moves: bool,
    s: f64,
) -> String {
    let has = |names: &[&str]| names.iter().any(|n| terms.iter().any(|t| t.starts_with(n)));
    let a_terms = terms.iter().any(|t| t.ends_with('A') || t.contains("OA"));
    let c_terms = terms.iter().any(|t| t.ends_with('C') || t.contains("OC"));
    if !a_moves && a_terms {
        return "A never moves in these files: the A axis's errors are not seen".into();
    }
    if !c_moves && c_terms {
        return "C never moves in these files: the C axis's errors are not seen".into();
    }
    if on_axis && has(&["XOC", "YOC", "AOC", "BOC"]) {
        return "the nest is on the C axis: it sees only XOC + h·BOC and YOC − h·AOC".into();
    }
    if span < 3 && has(&["XOC", "YOC", "AOC", "BOC", "EZC", "ECC"]) {
        return format!(
            "{nests} nest position(s), {span} not collinear: with error motions modelled, fewer than three non-collinear nest positions cannot separate XOC, YOC, AOC, BOC from EZC/ECC"
        );
    }
    if terms.iter().any(|t| t.starts_with("spindle")) {
        return "the files' tool lengths do not separate the spindle's direction from the location errors (use tool lengths further apart)".into();
    }
    if terms.iter().any(|t| t.contains("/T_")) {
        return "the sensors' temperatures move together (or not at all) in these files: their drift coefficients cannot be told apart".into();
    }
    format!("the poses do not separate these terms (relative singular value {s:.1e}); add sweeps or lower the component order")
}

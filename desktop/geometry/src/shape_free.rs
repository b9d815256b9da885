//! σ's for a point estimate from a class that is not told the shape
//! (issue 49 item 2): the polynomial model's own posterior assumes its
//! degrees, so on a plan with null directions (today's 14 lines: 57 for
//! the Legendre-16 class) it cannot cover what no line sees. Here the
//! generic identifier's posterior (`generic`: Legendre degree 16 per
//! error, evidence-chosen prior) judges any estimate: under it the truth
//! is N(m, Σ), so the estimate's expected squared error at a position is
//! (estimate − m)² + σ², σ the posterior σ there. Along a null direction σ
//! is the prior's spread (the lines removed none of it); where the lines
//! see the machine it is the noise's. The generic model's own misfit
//! inflation (held-out prediction against its predictive expectation)
//! multiplies σ as it does for the generic model's printed σ's.
//!
//! **Along the null directions the prior is decay-free.** The evidence
//! chooses the order decay p from what the lines see; on a smooth machine
//! it is steep (2.9 on `geometry simulate`'s class), which made the prior
//! — and so the σ — along the null directions of orders 2–3 small, while
//! nothing in the data says what a machine hides there (machines with a
//! hidden part there were covered at 72–99 %, 89.9 % pooled). So the
//! truth is modelled as the evidence's class plus an independent part in
//! the null space S (`null_space`, `plan`'s criterion at degree 16) whose
//! prior brings the evidence's, along S, up to a decay-free class: every
//! order of an error gets at least an even share of that error's prior
//! size (the mean square over the stroke, which the seen low orders
//! determine), i.e. a flat spectrum at the size of the seen term. With R
//! the free σ's (the larger of the evidence's and the even share), Q an
//! orthonormal basis of R⁻¹S and D the evidence's variance over the free
//! one, the added covariance is C = R Q Qᵀ(I − D)Q Qᵀ R: the prior along
//! S becomes exactly the free one in the free class's metric (Qᵀ D Q +
//! Qᵀ(I − D) Q = I), the seen part keeps the evidence's. No reading sees
//! S, so the evidence, the posterior mean and the hold-out (hence the
//! inflation) are unchanged, and the posterior covariance is Σ + C
//! exactly. No constant enters and the decay does not shape it (with a
//! flat fitted decay C = 0). Why not the error's first-order variance at
//! every order (the largest per-order prior): that is a flat spectrum up
//! to 16 times the seen term's mean square; measured, its median σ (3.6 µm /
//! 15 µrad over the hidden-part machines) was as large as the true errors
//! themselves (per machine medians 2.1–4.1 µm / 4.5–11.4 µrad), so it told
//! nothing. The even share keeps the
//! error's size and covers the hidden part (tests/shape_free_null_prior.rs).

use anyhow::Result;
use nalgebra::{DMatrix, DVector};

use super::adequacy::StatedNoise;
use super::errors::{GeometricErrors, Term};
use super::generic::{basis, centred_design, identify_generic, Generic, DEGREE};
use super::identify::LineObs;
use super::kinematics::Structure;
use super::plan::{NULL_TOLERANCE, POSITIONS};
use super::smooth::{to_errors, SCol};

/// The shape-free posterior of one set of lines.
pub struct ShapeFree {
    generic: Generic,
    /// The generic model's σ inflation (≥ 1).
    pub inflation: f64,
    null: NullPrior,
}

impl ShapeFree {
    /// Fit the generic class to `lines`; `line_sigma_um` is each line's
    /// stated σ per (averaged) reading, as for the adequacy test.
    pub fn fit(
        st: &Structure,
        lines: &[LineObs],
        stroke: [f64; 3],
        line_sigma_um: &[f64],
        noise: StatedNoise,
    ) -> Result<ShapeFree> {
        let generic = identify_generic(st, lines, stroke)?;
        let inflation = generic.adequacy(line_sigma_um, noise).sigma_inflation;
        let (cols, pv) = generic.columns_and_prior();
        let null = NullPrior::new(st, lines, stroke, cols, pv);
        Ok(ShapeFree {
            generic,
            inflation,
            null,
        })
    }

    /// Posterior σ of `term` at `q_mm` with the decay-free prior along the
    /// null directions (module doc) [µm or µrad], before the inflation.
    pub fn posterior_sigma(&self, term: Term, q_mm: f64) -> f64 {
        let s = self.generic.sigma(term, q_mm);
        s.hypot(
            self.null
                .term_sigma(term, q_mm / self.null.stroke[term.axis.index()]),
        )
    }

    /// The generic posterior's own σ of `term` at `q_mm` (the evidence's
    /// prior along the null directions too, as printed before the null
    /// prior), before the inflation: for comparison.
    pub fn evidence_sigma(&self, term: Term, q_mm: f64) -> f64 {
        self.generic.sigma(term, q_mm)
    }

    /// The same for squareness `i` [µrad].
    pub fn evidence_squareness_sigma(&self, i: usize) -> f64 {
        self.generic.squareness_sigma(i)
    }

    /// The same for squareness `i` [µrad].
    pub fn posterior_squareness_sigma(&self, i: usize) -> f64 {
        let s = self.generic.squareness_sigma(i);
        s.hypot(self.null.squareness_sigma(i))
    }

    /// The shape-free posterior mean (the generic model's estimate).
    pub fn mean(&self) -> &GeometricErrors {
        &self.generic.fit.errors
    }

    /// RMS error of `estimate`'s `term` at `q_mm` under the posterior
    /// [µm or µrad]: √((estimate − mean)² + (inflation · σ)²).
    pub fn term_sigma(&self, estimate: &GeometricErrors, term: Term, q_mm: f64) -> f64 {
        let bias = estimate.value(term, q_mm) - self.mean().value(term, q_mm);
        bias.hypot(self.inflation * self.posterior_sigma(term, q_mm))
    }

    /// The same for squareness `i` (EC0Y, EB0Z, EA0Z) [µrad].
    pub fn squareness_sigma(&self, estimate: &GeometricErrors, i: usize) -> f64 {
        let bias = estimate.squareness.get(i) - self.mean().squareness.get(i);
        bias.hypot(self.inflation * self.posterior_squareness_sigma(i))
    }
}

/// Share [%] of terms × positions (20 per stroke; the axis zero and a
/// straightness's stroke end, where the convention pins both to zero, not
/// counted) and the squareness whose true error is within 3 `sigma` of
/// `model`; `sigma(Some(term), _, q)` or `sigma(None, i, _)` for
/// squareness `i`.
pub fn coverage_3sigma(
    model: &GeometricErrors,
    truth: &super::score::TabulatedTruth,
    sigma: impl Fn(Option<Term>, usize, f64) -> f64,
) -> f64 {
    let (mut inside, mut n) = (0usize, 0usize);
    for t in Term::all() {
        let l = truth.stroke_mm[t.axis.index()];
        let last = if t.is_straightness() { 19 } else { 20 };
        for k in 1..=last {
            let q = l * k as f64 / 20.0;
            let d = (model.value(t, q) - truth.value_ref(t, q)).abs();
            inside += usize::from(d <= 3.0 * sigma(Some(t), 0, q));
            n += 1;
        }
    }
    for (i, r) in truth.squareness_ref().iter().enumerate() {
        let d = (model.squareness.get(i) - r).abs();
        inside += usize::from(d <= 3.0 * sigma(None, i, 0.0));
        n += 1;
    }
    100.0 * inside as f64 / n.max(1) as f64
}

/// The null directions of `lines` for the class of Legendre degree
/// `degree` per error (at most the shape-free class's 16) and squareness,
/// each line's zero free: error sets that change no reading of any line to
/// first order, each scaled to a largest coefficient of 1 (µm or µrad).
/// At degree 16, what the generic model's `null_combinations` names in
/// words, as error functions; at a lower degree, what a machine that
/// smooth can hide from the lines.
pub fn null_errors(
    st: &Structure,
    lines: &[LineObs],
    stroke: [f64; 3],
    degree: usize,
) -> Vec<GeometricErrors> {
    let degree = degree.clamp(2, DEGREE);
    let mut cols = Vec::new();
    for term in Term::all() {
        let first = if term.is_straightness() { 2 } else { 1 };
        cols.extend((first..=degree).map(|j| SCol::Term { term, j }));
    }
    cols.extend((0..3).map(SCol::Squareness));
    let null = null_space(&centred_design(st, lines, stroke, &cols));
    (null.column_iter())
        .map(|x| {
            let peak = x.iter().fold(0.0f64, |p, v| p.max(v.abs())).max(1e-300);
            let x: Vec<f64> = x.iter().map(|v| v / peak).collect();
            to_errors(&cols, &x, degree, stroke)
        })
        .collect()
}

/// The prior added along the null directions (module doc): its covariance
/// over the error columns (terms and squareness) of the generic posterior.
struct NullPrior {
    cols: Vec<SCol>,
    cov: DMatrix<f64>,
    stroke: [f64; 3],
}

impl NullPrior {
    /// `cols` and `pv`: the generic posterior's columns and their prior
    /// variances at the evidence's choice.
    fn new(
        st: &Structure,
        lines: &[LineObs],
        stroke: [f64; 3],
        cols: &[SCol],
        pv: &[f64],
    ) -> NullPrior {
        let (cols, p): (Vec<SCol>, Vec<f64>) = (cols.iter().zip(pv))
            .filter(|(c, _)| !matches!(c, SCol::Scale(_)))
            .map(|(c, v)| (*c, *v))
            .unzip();
        let n = cols.len();
        // Decay-free: each order at least an even share of the error's
        // prior size (mean square over the stroke).
        let msq = |c: &SCol| match *c {
            SCol::Term { term, j } => {
                let n = POSITIONS - 1;
                (0..=n)
                    .map(|i| basis(term.is_straightness(), j, i as f64 / n as f64).powi(2))
                    .sum::<f64>()
                    / (n + 1) as f64
            }
            _ => 1.0,
        };
        let free: Vec<f64> = (cols.iter().zip(&p))
            .map(|(c, v)| match *c {
                SCol::Term { term, .. } => {
                    let (mut size, mut orders) = (0.0, 0.0);
                    for (d, w) in cols.iter().zip(&p) {
                        if matches!(*d, SCol::Term { term: t, .. } if t == term) {
                            size += w * msq(d);
                            orders += msq(d);
                        }
                    }
                    v.max(size / orders)
                }
                _ => *v,
            })
            .collect();
        let null = null_space(&centred_design(st, lines, stroke, &cols));
        let k = null.ncols();
        if k == 0 {
            return NullPrior {
                cov: DMatrix::zeros(n, n),
                cols,
                stroke,
            };
        }
        let r = DVector::from_iterator(n, free.iter().map(|f| f.max(0.0).sqrt()));
        let w = DMatrix::from_fn(n, k, |i, c| null[(i, c)] / r[i].max(f64::MIN_POSITIVE));
        let q = w.qr().q();
        let keep = DMatrix::from_diagonal(&DVector::from_iterator(
            n,
            p.iter()
                .zip(&free)
                .map(|(v, f)| 1.0 - v / f.max(f64::MIN_POSITIVE)),
        ));
        let m = q.transpose() * keep * &q;
        let rq = DMatrix::from_diagonal(&r) * &q;
        NullPrior {
            cov: &rq * m * rq.transpose(),
            cols,
            stroke,
        }
    }

    /// The added σ of `term` at u = q / stroke.
    fn term_sigma(&self, term: Term, u: f64) -> f64 {
        let g: Vec<(usize, f64)> = (self.cols.iter().enumerate())
            .filter_map(|(i, c)| match *c {
                SCol::Term { term: t, j } if t == term => {
                    Some((i, basis(t.is_straightness(), j, u)))
                }
                _ => None,
            })
            .collect();
        let v: f64 = (g.iter())
            .flat_map(|&(i, gi)| g.iter().map(move |&(j, gj)| (i, j, gi * gj)))
            .map(|(i, j, w)| w * self.cov[(i, j)])
            .sum();
        v.max(0.0).sqrt()
    }

    /// The added σ of squareness `i`.
    fn squareness_sigma(&self, i: usize) -> f64 {
        (self.cols.iter())
            .position(|c| *c == SCol::Squareness(i))
            .map_or(0.0, |k| self.cov[(k, k)].max(0.0).sqrt())
    }
}

/// The null space of the centred design `a` (`plan`'s criterion: columns
/// scaled to unit norm, singular values below `NULL_TOLERANCE` of the
/// largest), one column per direction in `a`'s own coefficients.
fn null_space(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.ncols();
    let norms: Vec<f64> = (0..n)
        .map(|j| match a.column(j).norm() {
            x if x > 0.0 => x,
            _ => 1.0,
        })
        .collect();
    let mut a = a.clone();
    for (j, nn) in norms.iter().enumerate() {
        a.column_mut(j).scale_mut(1.0 / nn);
    }
    let svd = a.svd(false, true);
    let Some(vt) = svd.v_t else {
        return DMatrix::zeros(n, 0);
    };
    let smax = svd.singular_values.max().max(f64::MIN_POSITIVE);
    let rows: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] < NULL_TOLERANCE * smax)
        .collect();
    DMatrix::from_fn(n, rows.len(), |j, c| vt[(rows[c], j)] / norms[j])
}

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

use anyhow::Result;

use super::adequacy::StatedNoise;
use super::errors::{GeometricErrors, Term};
use super::generic::{centred_design, identify_generic, Generic, DEGREE};
use super::identify::LineObs;
use super::kinematics::Structure;
use super::plan::NULL_TOLERANCE;
use super::smooth::{to_errors, SCol};

/// The shape-free posterior of one set of lines.
pub struct ShapeFree {
    generic: Generic,
    /// The generic model's σ inflation (≥ 1).
    pub inflation: f64,
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
        Ok(ShapeFree { generic, inflation })
    }

    /// The shape-free posterior mean (the generic model's estimate).
    pub fn mean(&self) -> &GeometricErrors {
        &self.generic.fit.errors
    }

    /// RMS error of `estimate`'s `term` at `q_mm` under the posterior
    /// [µm or µrad]: √((estimate − mean)² + (inflation · σ)²).
    pub fn term_sigma(&self, estimate: &GeometricErrors, term: Term, q_mm: f64) -> f64 {
        let bias = estimate.value(term, q_mm) - self.mean().value(term, q_mm);
        bias.hypot(self.inflation * self.generic.sigma(term, q_mm))
    }

    /// The same for squareness `i` (EC0Y, EB0Z, EA0Z) [µrad].
    pub fn squareness_sigma(&self, estimate: &GeometricErrors, i: usize) -> f64 {
        let bias = estimate.squareness.get(i) - self.mean().squareness.get(i);
        bias.hypot(self.inflation * self.generic.squareness_sigma(i))
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
    let n = cols.len();
    let mut a = centred_design(st, lines, stroke, &cols);
    let norms: Vec<f64> = (0..n).map(|j| a.column(j).norm()).collect();
    for (j, nn) in norms.iter().enumerate() {
        if *nn > 0.0 {
            a.column_mut(j).scale_mut(1.0 / nn);
        }
    }
    let svd = a.svd(false, true);
    let Some(vt) = svd.v_t else {
        return Vec::new();
    };
    let smax = svd.singular_values.max().max(f64::MIN_POSITIVE);
    (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] < NULL_TOLERANCE * smax)
        .map(|i| {
            let x: Vec<f64> = (0..n)
                .map(|j| vt[(i, j)] / norms[j].max(f64::MIN_POSITIVE))
                .collect();
            let peak = x.iter().fold(0.0f64, |p, v| p.max(v.abs())).max(1e-300);
            let x: Vec<f64> = x.iter().map(|v| v / peak).collect();
            to_errors(&cols, &x, degree, stroke)
        })
        .collect()
}

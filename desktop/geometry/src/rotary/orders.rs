//! The harmonic order of each rotary axis's error motions chosen by the
//! data (issue 49 item 3): `identify-rotary --order-a auto --order-c auto`.
//!
//! **Method: the Bayesian evidence (marginal likelihood) of the fit at the
//! stated noise**, one axis at a time. Candidate order h of an axis says:
//! its six error motions are Fourier series of harmonics 1…h whose
//! coefficients of harmonic k are a priori N(0, (τ ρ^(k−1))²) — one τ for
//! the three translations [µm], one for the three rotations [µrad], one
//! ratio ρ from one harmonic to the next (how fast the motions' spectrum
//! falls, or rises, is the data's to say) —, and harmonics above h are
//! zero. Every other unknown (location errors, drift, spindle,
//! file offsets, the other axis's harmonics up to [`MAX_ORDER`], the
//! linear model's corrections) has the prior the fit gives it (flat, or
//! the generic linear model's posterior rows); it is the same for every
//! candidate, so its constant cancels. The problem is linear-Gaussian, so
//! the evidence is exact: with the other unknowns projected out of the
//! axis's harmonic columns (Schur complement G of the normal equations,
//! g the projected right side, in units of the stated noise),
//!
//!   −2 ln E(h, τ) = −gₕᵀ(Gₕ + Λ)⁻¹gₕ + ln det(Gₕ + Λ) − ln det Λ + const,
//!
//! Λ = diag(1/(τ ρ^(k−1))²) over the coefficients of harmonics k ≤ h.
//! τ_µm, τ_µrad and ρ are set per candidate by maximising E (type-II maximum likelihood, as the generic
//! line identifier chooses its priors); the order with the largest
//! evidence wins (the lower on a tie). Why the evidence and not a leave-one-file-out test: the
//! Occam factor ln det(I + τ²G) charges each added coefficient for the
//! prior volume it opens, so an order is added only when the data pay for
//! it; there is no significance level to choose, the whole joint fit
//! (with the lines, their posterior) is used at once, and it costs one fit
//! at the largest order plus algebra on ≤ 72 columns instead of one
//! leave-one-file-out pass per candidate. At the stated noise (not the
//! fit's residual) so that the verdict is the adequacy test's premise: a
//! misfit the stated noise cannot explain asks for more harmonics, and the
//! adequacy test then says whether they were enough.
//!
//! Each axis is judged with the other's harmonics at [`MAX_ORDER`] (free):
//! the choice of one does not depend on the order the other is tried in.
//! The order is per axis, not per error motion: the six motions of an axis
//! are sampled by the same sweeps, and [`RotaryOptions`] holds one order
//! per axis.
//!
//! **The fit that follows is that order's posterior, not plain least
//! squares.** The evidence judged order h under the prior N(0, (τ ρ^(k−1))²)
//! on harmonic k's coefficients; fitting the chosen order without it would
//! charge a harmonic nothing in the fit that the evidence charged for in
//! the choice (five-axis-blind FOURTH_FIGURES: orders 3–6 tie on A, and
//! where order 4 won the unregularised fourth harmonic, nearly
//! indistinguishable from A's tilt over ±100° sweeps, took BOA/COA's σ to
//! 5 µrad). So an `auto` axis is fitted at its chosen order with the τ_µm,
//! τ_µrad, ρ the evidence fitted for that order, as prior rows in the
//! least squares ([`HarmonicPrior`], `columns::prior_rows`: one row
//! σ_stated/σ_prior per coefficient, right side 0, weighted as an R-test
//! reading): the solution is the posterior mean, and the adequacy test's
//! covariance of those rows (`RotaryIdentification::assess`) the
//! posterior covariance, from which every printed σ comes. Chosen over the
//! alternative (fit at [`MAX_ORDER`] with that order's prior, the order
//! then a report) because the model written, exported and converted keeps
//! the order the report names. The prior of each axis is the one its
//! evidence fitted with the other axis at [`MAX_ORDER`]; a given order
//! keeps plain least squares.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::Serialize;

use super::columns::{harmonic, Col, HarmonicPrior, RotaryOptions};
use super::identify::{RotaryIdentification, RANK_TOL};
use super::model::Axis5;
use crate::adequacy::StatedNoise;

/// The largest order tried (the design refuses more: the sweeps cannot carry them).
pub const MAX_ORDER: usize = 6;

/// An axis's order: given, or chosen by the evidence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    Auto,
    Given(usize),
}

impl std::str::FromStr for Order {
    type Err = String;
    fn from_str(s: &str) -> Result<Order, String> {
        match s.trim() {
            "auto" => Ok(Order::Auto),
            t => match t.parse::<usize>() {
                Ok(n) if n <= MAX_ORDER => Ok(Order::Given(n)),
                _ => Err(format!(
                    "`auto` or a whole number 0 to {MAX_ORDER}, got `{t}`"
                )),
            },
        }
    }
}

/// One candidate order's evidence.
#[derive(Clone, Debug, Serialize)]
pub struct Candidate {
    pub order: usize,
    /// ln of the evidence relative to order 0 (location errors only).
    pub ln_evidence: f64,
    /// The prior the evidence chose (none at order 0): the first
    /// harmonic's sizes τ [µm, µrad] and the ratio ρ of each harmonic's
    /// size to the one before (from order 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prior_um: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prior_urad: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prior_ratio: Option<f64>,
}

/// The order of one axis and how it came.
#[derive(Clone, Debug, Serialize)]
pub struct OrderChoice {
    /// `A` or `C`.
    pub axis: &'static str,
    pub order: usize,
    /// `evidence` or `given`.
    pub chosen_by: &'static str,
    /// Every candidate 0…[`MAX_ORDER`] (evidence only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub candidates: Vec<Candidate>,
}

fn axis_name(ax: Axis5) -> &'static str {
    match ax {
        Axis5::A => "A",
        Axis5::C => "C",
    }
}

/// The orders for `fit` (one of the rotary fits, called with the options
/// it should use): each `Auto` axis chosen by the evidence at `noise`
/// (module doc), a `Given` one kept. Returns the options to fit with and
/// the choices; `fit` is called once, at the largest orders and without a
/// harmonic prior, when an axis is `Auto`. The options returned carry, per
/// `Auto` axis above order 0, the prior its evidence chose (module doc).
pub fn choose_orders(
    fit: impl Fn(&RotaryOptions) -> Result<RotaryIdentification>,
    base: &RotaryOptions,
    order_c: Order,
    order_a: Order,
    noise: StatedNoise,
) -> Result<(RotaryOptions, Vec<OrderChoice>)> {
    let pick = |o: Order| match o {
        Order::Auto => MAX_ORDER,
        Order::Given(n) => n,
    };
    let mut o = RotaryOptions {
        order_c: pick(order_c),
        order_a: pick(order_a),
        harmonic_prior: Vec::new(),
        ..base.clone()
    };
    let given = |ax: Axis5, n: usize| OrderChoice {
        axis: axis_name(ax),
        order: n,
        chosen_by: "given",
        candidates: vec![],
    };
    let auto: Vec<Axis5> = [(Axis5::C, order_c), (Axis5::A, order_a)]
        .into_iter()
        .filter(|(_, o)| *o == Order::Auto)
        .map(|(ax, _)| ax)
        .collect();
    let mut choices = Vec::new();
    if !auto.is_empty() {
        let id = fit(&o)?;
        let Some(d) = id.design.as_ref() else {
            bail!("internal: identification without its design");
        };
        let (a, b) = d.at_noise(noise.um);
        let (n, r) = (a.tr_mul(&a), a.tr_mul(&b));
        for &ax in &auto {
            let c = evidence_by_order(&n, &r, &d.cols, ax)?;
            let best = c
                .iter()
                .fold(None::<&Candidate>, |b, x| match b {
                    Some(b) if b.ln_evidence >= x.ln_evidence => Some(b),
                    _ => Some(x),
                })
                .map_or(0, |c| c.order);
            if let Some(w) = c.iter().find(|x| x.order == best && best > 0) {
                o.harmonic_prior.push(HarmonicPrior {
                    axis: ax,
                    tau_um: w.prior_um.unwrap_or(f64::INFINITY),
                    tau_urad: w.prior_urad.unwrap_or(f64::INFINITY),
                    ratio: w.prior_ratio.unwrap_or(1.0),
                    noise_um: noise.um,
                });
            }
            match ax {
                Axis5::C => o.order_c = best,
                Axis5::A => o.order_a = best,
            }
            choices.push(OrderChoice {
                axis: axis_name(ax),
                order: best,
                chosen_by: "evidence",
                candidates: c,
            });
        }
    }
    for (ax, ord) in [(Axis5::C, order_c), (Axis5::A, order_a)] {
        if let Order::Given(k) = ord {
            choices.push(given(ax, k));
        }
    }
    choices.sort_by_key(|c| c.axis);
    Ok((o, choices))
}

/// The evidence of every order 0…[`MAX_ORDER`] of `ax` from the normal
/// equations `n`, `r` of the problem at the largest order (module doc).
fn evidence_by_order(
    n: &DMatrix<f64>,
    r: &DVector<f64>,
    cols: &[Col],
    ax: Axis5,
) -> Result<Vec<Candidate>> {
    let h_idx: Vec<usize> = (0..cols.len())
        .filter(|&j| harmonic(&cols[j], ax).is_some())
        .collect();
    let f_idx: Vec<usize> = (0..cols.len())
        .filter(|&j| harmonic(&cols[j], ax).is_none())
        .collect();
    let (g, gv) = schur(n, r, &h_idx, &f_idx)?;
    let info: Vec<(usize, bool)> = h_idx
        .iter()
        .filter_map(|&j| harmonic(&cols[j], ax))
        .collect();
    let mut out = vec![Candidate {
        order: 0,
        ln_evidence: 0.0,
        prior_um: None,
        prior_urad: None,
        prior_ratio: None,
    }];
    for h in 1..=MAX_ORDER {
        let sub: Vec<usize> = (0..info.len()).filter(|&i| info[i].0 <= h).collect();
        if sub.is_empty() {
            continue;
        }
        let gs = DMatrix::from_fn(sub.len(), sub.len(), |i, j| g[(sub[i], sub[j])]);
        let bs = DVector::from_fn(sub.len(), |i, _| gv[sub[i]]);
        let kind: Vec<(usize, bool)> = sub.iter().map(|&i| info[i]).collect();
        let urad: Vec<bool> = kind.iter().map(|k| k.1).collect();
        let f = |v: &[f64; 3]| neg2_ln_evidence(&gs, &bs, &kind, v);
        let v = maximise(f);
        out.push(Candidate {
            order: h,
            ln_evidence: -0.5 * f(&v),
            prior_um: urad.iter().any(|u| !u).then(|| v[0].exp()),
            prior_urad: urad.iter().any(|u| *u).then(|| v[1].exp()),
            prior_ratio: (h > 1).then(|| v[2].exp()),
        });
    }
    Ok(out)
}

/// The Schur complement of the `f` block: G = N_hh − N_hf N_ff⁺ N_fh and
/// g = r_h − N_hf N_ff⁺ r_f, the pseudo-inverse on unit-scaled columns
/// over the directions the fit keeps (singular values above
/// [`RANK_TOL`]·σ_max, as `identify` does).
fn schur(
    n: &DMatrix<f64>,
    r: &DVector<f64>,
    h: &[usize],
    f: &[usize],
) -> Result<(DMatrix<f64>, DVector<f64>)> {
    let scale: Vec<f64> = f
        .iter()
        .map(|&j| n[(j, j)].sqrt())
        .map(|s| if s > 0.0 { s } else { 1.0 })
        .collect();
    let nff = DMatrix::from_fn(f.len(), f.len(), |i, j| {
        n[(f[i], f[j])] / (scale[i] * scale[j])
    });
    // right sides: N_fh columns then r_f, unit-scaled
    let mut rhs = DMatrix::from_fn(f.len(), h.len() + 1, |i, j| {
        if j < h.len() {
            n[(f[i], h[j])]
        } else {
            r[f[i]]
        }
    });
    for i in 0..f.len() {
        rhs.row_mut(i).scale_mut(1.0 / scale[i]);
    }
    let eig = SymmetricEigen::new(nff);
    let lmax = eig.eigenvalues.max();
    if !(lmax > 0.0) {
        bail!("internal: the fit's other unknowns carry no information");
    }
    let tol = RANK_TOL * RANK_TOL * lmax;
    let v = &eig.eigenvectors;
    let mut proj = v.tr_mul(&rhs);
    for k in 0..proj.nrows() {
        let l = eig.eigenvalues[k];
        proj.row_mut(k)
            .scale_mut(if l > tol { 1.0 / l.sqrt() } else { 0.0 });
    }
    // (N_hf N_ff⁺ N_fh) = projᵀ proj over the kept directions
    let q = proj.tr_mul(&proj);
    let nh = h.len();
    let g = DMatrix::from_fn(nh, nh, |i, j| n[(h[i], h[j])] - q[(i, j)]);
    let gv = DVector::from_fn(nh, |i, _| r[h[i]] - q[(i, nh)]);
    Ok((g, gv))
}

/// −2 ln E (without the constant) at `v` = (ln τ_µm, ln τ_µrad, ln ρ)
/// for coefficients of `kind` (harmonic, µrad).
fn neg2_ln_evidence(
    g: &DMatrix<f64>,
    b: &DVector<f64>,
    kind: &[(usize, bool)],
    v: &[f64; 3],
) -> f64 {
    let var: Vec<f64> = kind
        .iter()
        .map(|(h, u)| (2.0 * (v[usize::from(*u)] + (*h as f64 - 1.0) * v[2])).exp())
        .collect();
    let mut m = g.clone();
    for (i, s2) in var.iter().enumerate() {
        m[(i, i)] += 1.0 / s2;
    }
    let Some(ch) = m.cholesky() else {
        return f64::INFINITY;
    };
    let logdet_m: f64 = 2.0 * ch.l().diagonal().iter().map(|x| x.ln()).sum::<f64>();
    let logdet_prior: f64 = var.iter().map(|s| s.ln()).sum();
    let x = ch.solve(b);
    -b.dot(&x) + logdet_m + logdet_prior
}

/// Bounds of ln τ (10⁻⁴ to 10⁴ µm or µrad, far outside any error motion
/// and any noise) and of ln ρ (a factor 10⁴ from one harmonic to the next).
const LN_TAU: (f64, f64) = (-9.2, 9.2);

/// Coordinate search of the evidence over (ln τ_µm, ln τ_µrad, ln ρ): each
/// coordinate stepped both ways while that improves it, the steps halved
/// when none does (as the line identifiers' search).
fn maximise(f: impl Fn(&[f64; 3]) -> f64) -> [f64; 3] {
    let mut v = [0.0; 3];
    let mut best = f(&v);
    let mut step = 1.0;
    for _ in 0..400 {
        let mut moved = false;
        for k in 0..3 {
            for dir in [1.0, -1.0] {
                let mut w = v;
                w[k] = (w[k] + dir * step).clamp(LN_TAU.0, LN_TAU.1);
                let fw = f(&w);
                if fw < best - 1e-9 {
                    best = fw;
                    v = w;
                    moved = true;
                }
            }
        }
        if !moved {
            step *= 0.5;
            if step < 0.005 {
                break;
            }
        }
    }
    v
}

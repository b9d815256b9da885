//! The ambient drift's trials without a simulation each.
//!
//! The drift adds amp·(sin(ωt + φ) − sin φ) + rate·t to the air, which is
//! amp·cos φ · sin ωt + amp·sin φ · (cos ωt − 1) + rate · t: linear in
//! c = (amp·cos φ, amp·sin φ, rate). The network is linear in its air
//! temperature (its conductances do not depend on it; only a cycling
//! chiller's thermostat would make it not, and it is not part of this
//! fit), so a trial's residuals are r(c) = r₀ + Σ c_j D_j, D_j the change
//! a unit drift j makes. Three unit simulations give every trial's fit-row
//! sums: per channel Σ r² = vᵀGv (v = (1, c), G the Gram matrix of r₀ and
//! the D_j) and the freedom's B̃ᵀr = h₀ + Σ c_j (h_j − h₀). A fit of the
//! drift (≈ 117 trials, each a simulation and a pass over B̃) then costs
//! three simulations (r₀ is the nominal's), one pass over B̃ for the
//! four sets and a box QP per trial. A fourth simulation
//! checks the linearity on the machine at hand: where it does not hold to
//! 10⁻⁹, the family is not used and every trial simulates as before.

use nalgebra::{DMatrix, DVector};
use std::cell::RefCell;

use super::effect_fit::{
    build, fit_cands, fit_cands_with, params_of, stats_of, ActiveSet, Cand, Evaluator, FitResult,
    Projection, Residuals, Stats,
};
use crate::sim::Effect;

/// Unit drifts: sin ωt, cos ωt − 1 (phase a quarter period), t [h].
fn unit(j: usize) -> Effect {
    let (amp, phase_h, rate) = [(1.0, 0.0, 0.0), (1.0, 6.0, 0.0), (0.0, 0.0, 1.0)][j];
    Effect::AmbientDrift {
        amp_c: amp,
        phase_h,
        rate_c_per_h: rate,
        period_h: 24.0,
    }
}

/// c of the drift's fitted values (amp, phase [h], rate), as `build`
/// makes the effect (24 h period).
fn coefficients(v: &[f64]) -> [f64; 3] {
    let Effect::AmbientDrift {
        amp_c,
        phase_h,
        rate_c_per_h,
        period_h,
    } = build("ambient_drift", v, &Cand::new("ambient_drift"))
    else {
        return [f64::NAN; 3];
    };
    let phi = 2.0 * std::f64::consts::PI * phase_h / period_h;
    [amp_c * phi.cos(), amp_c * phi.sin(), rate_c_per_h]
}

/// One vector per channel.
type PerChannel = Vec<DVector<f64>>;

/// The drift's trials from three unit responses.
pub(crate) struct DriftFamily<'a> {
    freedom: Option<&'a dyn Projection>,
    /// The statistics of r₀ (fit rows counted, noise per channel).
    st: Stats,
    /// Per channel: the Gram matrix of (r₀, D₁, D₂, D₃) over its finite
    /// fit rows.
    gram: Vec<DMatrix<f64>>,
    /// With a freedom: per channel B̃ᵀr₀ and each B̃ᵀD_j (formed once,
    /// not per trial).
    h: Option<(PerChannel, [PerChannel; 3])>,
    /// The last trial's active set (the fit's trials run in order).
    active: RefCell<ActiveSet>,
}

impl<'a> DriftFamily<'a> {
    /// The unit drifts' and the check's.
    pub const SIMULATIONS: usize = 4;

    /// None where a unit simulation fails, the freedom cannot give its
    /// products, or the check trial is not reproduced to 10⁻⁹.
    pub fn new(ev: &Evaluator<'a>) -> Option<DriftFamily<'a>> {
        let r0 = ev.raw_residuals(&[]).ok()?;
        let rj: Vec<Residuals> = (0..3)
            .map(|j| ev.raw_residuals(&[unit(j)]).ok())
            .collect::<Option<_>>()?;
        let mut gram = Vec::new();
        for (ri, (p, rr)) in ev.runs.iter().zip(&r0).enumerate() {
            for (c, r) in rr.iter().enumerate() {
                let mut g = DMatrix::zeros(4, 4);
                for (k, &v0) in r.iter().enumerate() {
                    if !v0.is_finite() || !p.is_fit(k) {
                        continue;
                    }
                    let v = [
                        v0,
                        rj[0][ri][c][k] - v0,
                        rj[1][ri][c][k] - v0,
                        rj[2][ri][c][k] - v0,
                    ];
                    for a in 0..4 {
                        for b in 0..4 {
                            g[(a, b)] += v[a] * v[b];
                        }
                    }
                }
                gram.push(g);
            }
        }
        let h = match ev.freedom {
            None => None,
            Some(f) => {
                let sets: Vec<&[Vec<Vec<f64>>]> = std::iter::once(&r0)
                    .chain(&rj)
                    .map(|r| r.as_slice())
                    .collect();
                let mut hs = f.pull_products(&sets)?.into_iter();
                let h0 = hs.next()?;
                let d = |hj: Vec<DVector<f64>>| -> Vec<DVector<f64>> {
                    hj.iter().zip(&h0).map(|(x, y)| x - y).collect()
                };
                let dh = [d(hs.next()?), d(hs.next()?), d(hs.next()?)];
                Some((h0, dh))
            }
        };
        let fam = DriftFamily {
            freedom: ev.freedom,
            st: stats_of(ev.runs, &r0),
            gram,
            h,
            active: RefCell::new(ActiveSet::new()),
        };
        // the check: a trial away from the units, simulated
        let v = [1.3, 7.0, -0.2];
        let cand = Cand::new("ambient_drift");
        let want = ev.j_fit(&[build("ambient_drift", &v, &cand)]).ok()?;
        let got = fam.j_fit(&v);
        ((got - want).abs() <= 1e-9 * want.abs().max(1.0)).then_some(fam)
    }

    /// `j_fit` at the point `u` of the fit's unit cube (`params_of`).
    pub fn j_fit_u(&self, u: &[f64]) -> f64 {
        let v: Vec<f64> = params_of("ambient_drift")
            .iter()
            .zip(u)
            .map(|(p, x)| p.from_u(*x))
            .collect();
        self.j_fit(&v)
    }

    /// The fit criterion (`Stats::j_fit`) at the drift's values (amp,
    /// phase [h], rate).
    pub fn j_fit(&self, v: &[f64]) -> f64 {
        let c = coefficients(v);
        let w = DVector::from_vec(vec![1.0, c[0], c[1], c[2]]);
        // Σ r² per channel over the fit rows
        let rr: Vec<f64> = self
            .gram
            .iter()
            .map(|g| (g * &w).dot(&w).max(0.0))
            .collect();
        let sse = match (&self.h, self.freedom) {
            (Some((h0, dh)), Some(f)) => {
                let hc: Vec<DVector<f64>> = (0..h0.len())
                    .map(|ch| {
                        let mut x = h0[ch].clone();
                        for j in 0..3 {
                            x += &dh[j][ch] * c[j];
                        }
                        x
                    })
                    .collect();
                match f.fit_sse_from(&hc, &rr, &mut self.active.borrow_mut()) {
                    Some(s) => s,
                    None => return f64::INFINITY,
                }
            }
            _ => rr,
        };
        let mut st = self.st.clone();
        st.ch.iter_mut().zip(sse).for_each(|(ch, e)| ch.sse_fit = e);
        st.j_fit()
    }
}

/// One candidate fitted alone (`fit_cands`), the drift by its family
/// where the family holds.
pub(crate) fn fit_alone(ev: &Evaluator, c: &Cand, budget: usize) -> FitResult {
    let one = std::slice::from_ref(c);
    let family = (c.kind == "ambient_drift")
        .then(|| DriftFamily::new(ev))
        .flatten();
    match &family {
        Some(f) => {
            let trial: &dyn Fn(&[f64]) -> f64 = &|u| f.j_fit_u(u);
            fit_cands_with(
                ev,
                one,
                None,
                budget,
                Some((trial, DriftFamily::SIMULATIONS)),
            )
        }
        None => fit_cands(ev, one, None, budget),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::calibration::{calibrate, setup, Freedom};

    #[test]
    fn the_family_gives_each_trial_as_its_simulation_does() {
        let (design, ps) = setup();
        let cal = calibrate(&design, &ps, 2).unwrap();
        let fr = Freedom::new(&design, &cal.knobs, &cal.theta, &ps, 2).unwrap();
        let bare = Evaluator::new(&cal.machine, &ps).unwrap();
        let ev = Evaluator::new(&cal.machine, &ps)
            .unwrap()
            .with_freedom(Some(&fr));
        let cand = Cand::new("ambient_drift");
        for e in [&bare, &ev] {
            let fam = DriftFamily::new(e).expect("the network is linear in its air");
            for v in [
                [0.0, 0.0, 0.0],
                [2.5, 3.0, 0.4],
                [0.3, 20.0, -0.9],
                [4.9, 13.5, 0.0],
            ] {
                let want = e.j_fit(&[build("ambient_drift", &v, &cand)]).unwrap();
                let got = fam.j_fit(&v);
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                    "{v:?}: family {got} vs simulated {want}"
                );
            }
        }
    }

    #[test]
    fn a_family_that_misses_its_check_trial_is_not_used() {
        // the check trial is compared with its simulation: sums that are
        // not what the trial's residuals give (here: a projection that
        // squares them but says its SSE is Σ r²) must fail it
        struct Squaring;
        impl Projection for Squaring {
            fn project(&self, res: &mut [Vec<Vec<f64>>]) {
                res.iter_mut()
                    .flatten()
                    .flatten()
                    .for_each(|v| *v *= v.abs());
            }
            fn pull_products(&self, sets: &[&[Vec<Vec<f64>>]]) -> Option<Vec<Vec<DVector<f64>>>> {
                Some(
                    sets.iter()
                        .map(|s| vec![DVector::zeros(1); s.iter().flatten().count()])
                        .collect(),
                )
            }
            fn fit_sse_from(
                &self,
                _h: &[DVector<f64>],
                rr: &[f64],
                _start: &mut ActiveSet,
            ) -> Option<Vec<f64>> {
                Some(rr.to_vec())
            }
        }
        let (design, ps) = setup();
        let ev = Evaluator::new(&design, &ps)
            .unwrap()
            .with_freedom(Some(&Squaring));
        assert!(DriftFamily::new(&ev).is_none());
    }
}

//! The image's output filter section (issue 51 item 1, section kind 6) from
//! a fit file's `output_lag_s` ([`crate::fit::output_lag`] chooses it at fit
//! time): per direction the decay exp(−step/τ) per model step in Q30.

use thermocomp_core::float::FloatModel;
use thermocomp_core::limits::MAX_DIRECTIONS;

use crate::fit::model::ModelFile;

/// The largest decay the image holds (the parser refuses 2^30 and above).
const MAX_DECAY_Q30: u32 = (1 << 30) - 1;

/// round(exp(−step_ms/τ)·2^30), at most 2^30 − 1; `None` for a τ that is
/// not a positive finite number of seconds.
pub fn decay_q30(step_ms: u32, tau_s: f64) -> Option<u32> {
    if !(tau_s.is_finite() && tau_s > 0.0) {
        return None;
    }
    let d = (-f64::from(step_ms) / 1000.0 / tau_s).exp() * f64::from(1u32 << 30);
    Some((d.round() as u32).min(MAX_DECAY_Q30))
}

/// The time constant (s) a decay stands for (`None` for 0: no filter).
pub fn tau_s(step_ms: u32, decay_q30: u32) -> Option<f64> {
    (decay_q30 > 0)
        .then(|| -f64::from(step_ms) / 1000.0 / (f64::from(decay_q30) / f64::from(1u32 << 30)).ln())
}

/// The image's decay per direction from the fit file's `output_lag_s`, and
/// one line per direction saying which; `None` (no section: the image stays
/// the older format, served as before) when no direction has a low-pass.
pub fn decays(
    file: &ModelFile,
    float: &FloatModel,
) -> (Option<[u32; MAX_DIRECTIONS]>, Vec<String>) {
    let mut out = [0u32; MAX_DIRECTIONS];
    let mut lines = Vec::new();
    for (d, dir) in out.iter_mut().zip(&float.directions) {
        let ch = format!("d{}_um", dir.name);
        let tau = file.output_lag_s.get(&ch).copied();
        match tau.map(|t| (t, decay_q30(float.step_ms, t))) {
            Some((t, Some(q))) => {
                *d = q;
                lines.push(format!("output low-pass {ch}: {t:.0} s"));
            }
            Some((t, None)) => lines.push(format!(
                "output low-pass {ch}: none (the fit file's {t} s is not a positive time constant)"
            )),
            None => lines.push(format!("output low-pass {ch}: none")),
        }
    }
    let any = out.iter().any(|&d| d > 0);
    (any.then_some(out), lines)
}

//! The diagnosis's first-order lag filters (the modal network's inputs,
//! a sensor's lag behind its body). Below `ident`, `stats` and
//! `open_effects`, which all filter with them.

/// First-order lag with zero-order hold: `x ← a x + (1 − a) u`, output
/// before the update (the state at the sample), starting at `x0`.
pub fn lag(u: &[f64], dt: f64, tau: f64, x0: f64) -> Vec<f64> {
    let a = (-dt / tau).exp();
    let mut x = x0;
    u.iter()
        .map(|&v| {
            let y = x;
            x = a * x + (1.0 - a) * v;
            y
        })
        .collect()
}

/// Lag of a measured (not piecewise-constant) signal, started at its first
/// value: a sensor that follows its body with time constant `tau`.
pub fn lag_signal(u: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let a = (-dt / tau).exp();
    let mut x = u.first().copied().unwrap_or(0.0);
    u.iter()
        .map(|&v| {
            x = a * x + (1.0 - a) * v;
            x
        })
        .collect()
}

/// Values with gaps held from the last finite value (the first finite one
/// before it; 0 when there is none): a series the filters can read.
pub fn held(v: &[f64]) -> Vec<f64> {
    let mut last = v.iter().copied().find(|x| x.is_finite()).unwrap_or(0.0);
    v.iter()
        .map(|&x| {
            if x.is_finite() {
                last = x;
            }
            last
        })
        .collect()
}

/// A sensor's rise from its first valid value, gaps held.
pub fn held_rise(v: &[f64]) -> Vec<f64> {
    let h = held(v);
    let z = h.first().copied().unwrap_or(0.0);
    h.iter().map(|x| x - z).collect()
}

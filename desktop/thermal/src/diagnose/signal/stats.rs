//! Statistics of residuals shared by both diagnosis modes: correlation, lag
//! filter, operating phases, where the gap lies, whiteness.

use serde_json::{json, Value};
use std::collections::BTreeMap;
pub use tcomp_numerics::stats::mean_finite;

/// Pearson correlation over rows where both are finite (the crate's one
/// Pearson, `select::pearson`).
pub fn corr(a: &[f64], b: &[f64]) -> f64 {
    let o =
        |v: &[f64]| -> Vec<Option<f64>> { v.iter().map(|x| x.is_finite().then_some(*x)).collect() };
    tcomp_numerics::stats::pearson(&o(a), &o(b))
}

/// Centered moving average with window `w` rows (NaN-aware).
pub fn moving_avg(v: &[f64], w: usize) -> Vec<f64> {
    let n = v.len();
    let h = w / 2;
    let mut cs = vec![0.0; n + 1];
    let mut cn = vec![0usize; n + 1];
    for i in 0..n {
        let ok = v[i].is_finite();
        cs[i + 1] = cs[i] + if ok { v[i] } else { 0.0 };
        cn[i + 1] = cn[i] + ok as usize;
    }
    (0..n)
        .map(|i| {
            let a = i.saturating_sub(h);
            let b = (i + h + 1).min(n);
            let c = cn[b] - cn[a];
            if c == 0 {
                f64::NAN
            } else {
                (cs[b] - cs[a]) / c as f64
            }
        })
        .collect()
}

/// First-order lag of a piecewise-constant input, from rest (the crate's
/// one lag filter is `lag::lag`).
pub fn first_order(v: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let mut y = super::lag::lag(v, dt, tau, 0.0);
    // `lag` reports the state before each update; one step ahead here so
    // that row k includes the input of row k
    if let (Some(last), Some(&u)) = (y.last().copied(), v.last()) {
        let a = (-dt / tau).exp();
        y.remove(0);
        y.push(a * last + (1.0 - a) * u);
    }
    y
}

/// Operating phase of each row from the spindle speed.
pub fn phases(rpm: &[f64], dt: f64) -> Vec<&'static str> {
    let mut out = Vec::with_capacity(rpm.len());
    let mut ran = false;
    let mut since_start = f64::INFINITY;
    let mut since_change = f64::INFINITY;
    let mut prev = rpm.first().copied().unwrap_or(0.0);
    if prev > 0.0 {
        since_start = 0.0;
    }
    for &r in rpm {
        if (r - prev).abs() > 50.0 {
            if prev <= 0.0 && r > 0.0 {
                since_start = 0.0;
            } else if prev > 0.0 && r > 0.0 {
                since_change = 0.0;
            }
        }
        prev = r;
        let ph = if r > 0.0 {
            ran = true;
            if since_change < 600.0 {
                "speed_change"
            } else if since_start < 3600.0 {
                "warm_up"
            } else {
                "steady"
            }
        } else if ran {
            "cool_down"
        } else {
            "idle"
        };
        out.push(ph);
        since_start += dt;
        since_change += dt;
    }
    out
}

/// Operating phase of each row from the temperatures when there is no
/// spindle speed: heating, cooling or steady by the mean sensor slope
/// (smoothed over 10 min) against a threshold of 0.2 °C/h.
pub fn phases_from_temperatures(sensors: &[&[f64]], dt: f64) -> Vec<&'static str> {
    let n = sensors.first().map_or(0, |s| s.len());
    let mean: Vec<f64> = (0..n)
        .map(|k| mean_finite(sensors.iter().map(|v| v[k])))
        .collect();
    let w = ((600.0 / dt).round() as usize).max(1);
    let sm = moving_avg(&mean, w);
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(w / 2);
            let b = (k + w / 2).min(n.saturating_sub(1));
            let slope_h = if b > a {
                (sm[b] - sm[a]) / ((b - a) as f64 * dt) * 3600.0
            } else {
                0.0
            };
            if !slope_h.is_finite() {
                "unknown"
            } else if slope_h > 0.2 {
                "heating"
            } else if slope_h < -0.2 {
                "cooling"
            } else {
                "steady"
            }
        })
        .collect()
}

/// RMS, peak and count of the finite values.
pub fn rms_of(vals: impl Iterator<Item = f64>) -> (f64, f64, usize) {
    let (mut s, mut pk, mut n) = (0.0, 0.0f64, 0usize);
    for v in vals.filter(|v| v.is_finite()) {
        s += v * v;
        pk = pk.max(v.abs());
        n += 1;
    }
    if n == 0 {
        (f64::NAN, f64::NAN, 0)
    } else {
        ((s / n as f64).sqrt(), pk, n)
    }
}

/// Rounded to 4 decimals for JSON (null when not finite).
pub fn r4(x: f64) -> Value {
    if x.is_finite() {
        json!((x * 1e4).round() / 1e4)
    } else {
        Value::Null
    }
}

/// One channel's residual in one run, for the where analysis.
pub struct ResidualView<'a> {
    pub name: &'a str,
    pub is_disp: bool,
    pub resid: &'a [f64],
    pub phases: &'a [&'static str],
    pub dt: f64,
}

/// Where the gap lies: per sensor, per direction, per operating phase and
/// per band (moving-average split: > 1 h, 10 min–1 h, < 10 min).
pub fn where_json(views: &[ResidualView]) -> Value {
    let mut names: Vec<(&str, bool)> = Vec::new();
    for v in views {
        if !names.contains(&(v.name, v.is_disp)) {
            names.push((v.name, v.is_disp));
        }
    }
    let mut sensors = serde_json::Map::new();
    let mut dirs = serde_json::Map::new();
    for (name, disp) in &names {
        let vals: Vec<f64> = views
            .iter()
            .filter(|v| v.name == *name && v.is_disp == *disp)
            .flat_map(|v| v.resid.iter().copied())
            .collect();
        let (rms, pk, n) = rms_of(vals.iter().copied());
        let mean = vals.iter().filter(|v| v.is_finite()).sum::<f64>() / n.max(1) as f64;
        let o = json!({"rms": r4(rms), "peak": r4(pk), "mean": r4(mean)});
        if *disp {
            dirs.insert(name.to_string(), o);
        } else {
            sensors.insert(name.to_string(), o);
        }
    }
    let mut ph_t: BTreeMap<&str, (f64, usize)> = Default::default();
    let mut ph_d: BTreeMap<&str, (f64, usize)> = Default::default();
    let mut bands_t = [(0.0, 0usize); 3];
    let mut bands_d = [(0.0, 0usize); 3];
    for v in views {
        let tgt = if v.is_disp { &mut ph_d } else { &mut ph_t };
        for (k, x) in v.resid.iter().enumerate() {
            if x.is_finite() {
                let e = tgt
                    .entry(v.phases.get(k).copied().unwrap_or("unknown"))
                    .or_default();
                e.0 += x * x;
                e.1 += 1;
            }
        }
        let w10 = ((600.0 / v.dt).round() as usize).max(1);
        let w60 = ((3600.0 / v.dt).round() as usize).max(1);
        let slow = moving_avg(v.resid, w60);
        let mid10 = moving_avg(v.resid, w10);
        let b = if v.is_disp {
            &mut bands_d
        } else {
            &mut bands_t
        };
        for k in 0..v.resid.len() {
            if !v.resid[k].is_finite() {
                continue;
            }
            let parts = [slow[k], mid10[k] - slow[k], v.resid[k] - mid10[k]];
            for (bi, x) in parts.iter().enumerate() {
                if x.is_finite() {
                    b[bi].0 += x * x;
                    b[bi].1 += 1;
                }
            }
        }
    }
    // rows per phase: count each row once (from the first channel of each run)
    let mut ph_rows: BTreeMap<&str, usize> = Default::default();
    let mut seen_first: Vec<*const &'static str> = Vec::new();
    for v in views {
        let key = v.phases.as_ptr();
        if seen_first.contains(&key) {
            continue;
        }
        seen_first.push(key);
        for p in v.phases {
            *ph_rows.entry(p).or_default() += 1;
        }
    }
    let rm = |e: Option<&(f64, usize)>| match e {
        Some((s, n)) if *n > 0 => r4((s / *n as f64).sqrt()),
        _ => Value::Null,
    };
    let mut phase = serde_json::Map::new();
    for (k, rows) in &ph_rows {
        phase.insert(
            k.to_string(),
            json!({"rows": rows, "rms_c": rm(ph_t.get(k)), "rms_um": rm(ph_d.get(k))}),
        );
    }
    let band_names = ["slow_gt_1h", "mid_10min_1h", "fast_lt_10min"];
    let mut bands = serde_json::Map::new();
    for (i, bn) in band_names.iter().enumerate() {
        bands.insert(
            bn.to_string(),
            json!({"rms_c": rm(Some(&bands_t[i])), "rms_um": rm(Some(&bands_d[i]))}),
        );
    }
    json!({"sensors": sensors, "directions": dirs, "phases": phase, "bands": bands})
}

/// Ljung–Box portmanteau statistic of a residual series over `lags` lags,
/// on every `step`-th finite value (so neighbouring rows of a finely sampled
/// slow series do not count as independent). Returns (Q, degrees of
/// freedom, p-value).
pub fn ljung_box(v: &[f64], lags: usize, step: usize) -> Option<(f64, usize, f64)> {
    let x: Vec<f64> = v
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .step_by(step.max(1))
        .collect();
    let n = x.len();
    if n < 4 * lags + 4 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let c0: f64 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    if c0 <= 0.0 {
        return Some((0.0, lags, 1.0));
    }
    let mut q = 0.0;
    for h in 1..=lags {
        let ch: f64 = (h..n).map(|i| (x[i] - mean) * (x[i - h] - mean)).sum();
        let r = ch / c0;
        q += r * r / (n - h) as f64;
    }
    q *= n as f64 * (n as f64 + 2.0);
    Some((q, lags, chi2_sf(q, lags as f64)))
}

/// Upper tail of the χ² distribution (Wilson–Hilferty normal approximation).
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let z = ((x / k).powf(1.0 / 3.0) - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt();
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Upper tail of the standard normal, P(Z > z) (through `erfc`).
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function (Numerical Recipes' erfcc, |error| < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Why a channel cannot be used in a run, if it cannot: it reads in fewer
/// than half the rows (a dead or unplugged sensor), or it reads the same
/// value in every row (stuck: a DS18B20 that answers its power-on 85 °C, a
/// frozen logger) while `others_move` (another temperature of the run
/// changes: in a run where every sensor stands still, as on an idle
/// machine in a steady room, a still sensor is not a fault). `values` NaN
/// where missing; `unit` for the message.
pub fn unusable_channel(values: &[f64], unit: &str, others_move: bool) -> Option<String> {
    let valid: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if valid.len() * 2 < values.len() {
        return Some(format!(
            "reads in {} of the {} rows",
            valid.len(),
            values.len()
        ));
    }
    let first = *valid.first()?;
    (others_move && valid.len() >= STUCK_MIN_ROWS && !moves(values))
        .then(|| format!("reads {first} {unit} in all {} rows (stuck)", valid.len()))
}

/// Whether a channel's readings (NaN where missing) take more than one value.
pub fn moves(values: &[f64]) -> bool {
    let mut valid = values.iter().filter(|v| v.is_finite());
    valid.next().is_some_and(|first| valid.any(|v| v != first))
}

/// Rows of one value that make a channel stuck (fewer: a short run that may
/// be steady).
pub const STUCK_MIN_ROWS: usize = 30;

#[cfg(test)]
mod tests {
    #[test]
    fn dead_and_stuck_channels_are_told_apart_from_steady_ones() {
        let stuck = vec![85.0; STUCK_MIN_ROWS];
        assert!(unusable_channel(&stuck, "°C", true)
            .unwrap()
            .contains("(stuck)"));
        // a short steady stretch is not stuck, nor a still sensor in a run
        // where no other sensor moves either
        assert!(unusable_channel(&stuck[1..], "°C", true).is_none());
        assert!(unusable_channel(&stuck, "°C", false).is_none());
        let mut moving = stuck.clone();
        moving[7] = 85.0625;
        assert!(moves(&moving) && !moves(&stuck));
        assert!(unusable_channel(&moving, "°C", true).is_none());
        let mut dead = vec![f64::NAN; 10];
        dead[0] = 20.0;
        assert_eq!(
            unusable_channel(&dead, "°C", false).as_deref(),
            Some("reads in 1 of the 10 rows")
        );
    }

    use super::*;

    #[test]
    fn ljung_box_tells_white_noise_from_a_slow_wave() {
        let mut g = tcomp_numerics::rng::Rng::paired(3);
        let white: Vec<f64> = (0..800).map(|_| g.normal()).collect();
        let (_, _, p) = ljung_box(&white, 10, 1).unwrap();
        assert!(p > 0.01, "white noise rejected, p = {p}");
        let wave: Vec<f64> = (0..800)
            .map(|k| (k as f64 / 40.0).sin() + 0.3 * g.normal())
            .collect();
        let (_, _, p) = ljung_box(&wave, 10, 1).unwrap();
        assert!(p < 1e-6, "slow wave passed as white, p = {p}");
    }

    #[test]
    fn chi2_tail_matches_known_quantiles() {
        // 95th percentile of χ²(10) is 18.307
        assert!((chi2_sf(18.307, 10.0) - 0.05).abs() < 0.003);
        assert!((chi2_sf(2.558, 10.0) - 0.99).abs() < 0.003);
    }
}

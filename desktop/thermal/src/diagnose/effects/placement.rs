//! Which candidate effects of the machine-file diagnosis apply to these
//! runs, and where the located ones (a sensor's offset or lag, one
//! bearing's extra heat, a chiller's start) are placed: on the nominal
//! residual of the fit rows.

use super::effect_fit::{ActiveSet, Cand, Evaluator};
use crate::diagnose::runs::{Kind, Prepared};
use crate::sim::{Effect, ALL_EFFECT_NAMES};

/// Whether the runs have a displacement channel, and a temperature one.
fn channel_kinds(ps: &[Prepared]) -> (bool, bool) {
    let has = |kind: fn(&Kind) -> bool| ps.iter().any(|p| p.channels.iter().any(|c| kind(&c.kind)));
    (
        has(|k| matches!(k, Kind::Disp(_))),
        has(|k| matches!(k, Kind::Temp(_))),
    )
}

/// Candidates applicable to this machine and these runs; the sensor
/// effects are placed where the nominal residual is (fit rows only).
pub fn candidates(ev: &Evaluator, res0: &[Vec<Vec<f64>>], only: &[String]) -> Vec<Cand> {
    let (m, ps) = (ev.m, ev.runs);
    let (has_disp, has_temp) = channel_kinds(ps);
    let flows = ps
        .iter()
        .any(|p| (0..p.rows()).any(|k| m.coolant_flows(p.inputs.rpm[k], p.inputs.coolant[k])));
    let mut out = Vec::new();
    for &k in ALL_EFFECT_NAMES.iter() {
        if !only.is_empty() && !only.iter().any(|o| o == k) {
            continue;
        }
        let ok = match k {
            "coolant" => {
                !m.coolant_nodes.is_empty()
                    && (ps.iter().any(|p| p.inputs.coolant.iter().any(|c| *c > 0.5))
                        || (m.coolant.is_some() && flows))
            }
            "chiller" => m.coolant.as_ref().is_some_and(|c| c.tank_c > 0.0),
            "ballscrew" => {
                !m.ballscrew_nodes.is_empty()
                    && ps.iter().any(|p| p.inputs.feed.iter().any(|f| *f > 0.0))
            }
            "bending" => m.bending.is_some() && has_disp,
            "sensor_lag" | "sensor_offset" => has_temp,
            "bearing_nonlinear" => !m.bnl_nodes.is_empty(),
            "convection" => m.area.iter().any(|a| *a > 0.0),
            _ => true,
        };
        if !ok {
            continue;
        }
        match k {
            "sensor_offset" => out.extend(locate_offset(ps, res0)),
            "sensor_lag" => {
                // every sensor lagging (one thermometer model), and the one
                // sensor whose residual looks most like −τ·d(prediction)/dt
                out.push(Cand::new(k));
                if let Some(sensor) = locate_lag(ev, res0) {
                    out.push(Cand {
                        sensor,
                        ..Cand::new(k)
                    });
                }
            }
            "bearing_nonlinear" => out.push(Cand {
                node: locate_heat(ev, res0),
                ..Cand::new(k)
            }),
            "chiller" => out.push(Cand {
                init: chiller_refine(ev, chiller_init(ev)),
                ..Cand::new(k)
            }),
            _ => out.push(Cand::new(k)),
        }
    }
    out
}

/// Least-squares gain (noise units, fit rows) of the nominal residual on
/// the change `with` − nominal of every channel.
fn gain_on(ev: &Evaluator, res0: &[Vec<Vec<f64>>], with: &[Effect]) -> f64 {
    let (mut rd, mut dd) = (0.0, 0.0);
    for ((p, rr), nom) in ev.runs.iter().zip(res0).zip(&ev.nominal) {
        let Ok(out) = crate::sim::simulate(ev.m, &p.inputs, with, 1) else {
            return 0.0;
        };
        for (c, r) in p.channels.iter().zip(rr) {
            let (a, b) = match c.kind {
                Kind::Temp(i) => (&out.temps[i], &nom.temps[i]),
                Kind::Disp(i) => (&out.disp[i], &nom.disp[i]),
            };
            for k in 0..r.len() {
                if p.is_fit(k) && r[k].is_finite() {
                    let d = (a[k] - b[k]) / c.s;
                    rd += r[k] / c.s * d;
                    dd += d * d;
                }
            }
        }
    }
    if dd > 0.0 && rd > 0.0 {
        rd * rd / dd
    } else {
        0.0
    }
}

/// Where extra speed-dependent bearing heat fits the residual best: one
/// bearing node (returned) or all of them (empty).
fn locate_heat(ev: &Evaluator, res0: &[Vec<Vec<f64>>]) -> String {
    let nodes = &ev.m.bnl_nodes;
    if nodes.len() < 2 {
        return String::new();
    }
    let probe = |node: Option<String>| Effect::BearingNonlinear {
        k_w: 10.0,
        p: 2.5,
        node,
    };
    let mut best = (String::new(), gain_on(ev, res0, &[probe(None)]));
    for &i in nodes {
        let name = ev.m.names[i].clone();
        let g = gain_on(ev, res0, &[probe(Some(name.clone()))]);
        if g > best.1 {
            best = (name, g);
        }
    }
    best.0
}

/// Refine the chiller's start: a thermostat's phase runs away over many
/// cycles, so the cycle time (the power at a fixed load share) is scanned
/// finely, then the load share, on the fit rows' criterion.
fn chiller_refine(ev: &Evaluator, init: Vec<f64>) -> Vec<f64> {
    if init.len() != 3 {
        return init;
    }
    // the scans' trials in batches (they share the freedom's pass over B̃)
    let mut start = ActiveSet::new();
    let mut j = |vs: &[[f64; 3]]| -> Vec<f64> {
        let sets: Vec<Vec<Effect>> = vs
            .iter()
            .map(|v| {
                vec![Effect::Chiller {
                    band_c: v[0],
                    power_w: v[1],
                    load_frac: v[2],
                }]
            })
            .collect();
        ev.j_fit_many(&sets, &mut start)
    };
    let first = [init[0], init[1], init[2]];
    let mut best = (first, j(&[first])[0]);
    let mut keep_best = |best: &mut ([f64; 3], f64), vs: &[[f64; 3]]| {
        for (v, f) in vs.iter().zip(j(vs)) {
            if f < best.1 {
                *best = (*v, f);
            }
        }
    };
    // power × 0.8 … 1.25, log-spaced (≈ 1.1 % apart)
    let powers: Vec<[f64; 3]> = (0..=40)
        .map(|i| {
            let scale = (0.8f64.ln() + (1.25f64 / 0.8).ln() * i as f64 / 40.0).exp();
            [init[0], init[1] * scale, init[2]]
        })
        .collect();
    keep_best(&mut best, &powers);
    let base = best.0;
    let shares: Vec<[f64; 3]> = (0..=10)
        .map(|i| {
            [
                base[0],
                base[1],
                (base[2] - 0.1 + 0.02 * i as f64).clamp(0.05, 0.95),
            ]
        })
        .collect();
    keep_best(&mut best, &shares);
    best.0.to_vec()
}

/// Start values of a cycling chiller from the coolant sensor (a sensor on
/// `coolant`): its swing is the band; the mean rise and fall rates give
/// the chiller's power and the tank's load. Empty without such a sensor.
fn chiller_init(ev: &Evaluator) -> Vec<f64> {
    use crate::sim::Probe;
    let Some(circ) = ev.m.coolant.as_ref() else {
        return vec![];
    };
    let (mut vals, mut up, mut down, mut n_up, mut n_down, mut air) =
        (Vec::new(), 0.0, 0.0, 0usize, 0usize, Vec::new());
    for p in ev.runs {
        for c in &p.channels {
            let Kind::Temp(i) = c.kind else { continue };
            if ev.m.sensor_probe[i] != Probe::Coolant {
                continue;
            }
            // slopes over 2 min (the 1/16 °C steps hide single differences)
            let w = ((120.0 / p.inputs.dt).round() as usize).max(1);
            for k in 0..c.meas.len() {
                if !p.is_fit(k) || !c.meas[k].is_finite() {
                    continue;
                }
                vals.push(c.meas[k]);
                air.push(p.inputs.ambient[k]);
                if k >= w && c.meas[k - w].is_finite() && p.is_fit(k - w) {
                    let sl = (c.meas[k] - c.meas[k - w]) / (w as f64 * p.inputs.dt);
                    if sl > 0.0 {
                        up += sl;
                        n_up += 1;
                    } else if sl < 0.0 {
                        down -= sl;
                        n_down += 1;
                    }
                }
            }
        }
    }
    if vals.len() < 20 || n_up == 0 || n_down == 0 || circ.tank_c <= 0.0 {
        return vec![];
    }
    vals.sort_by(|a, b| a.total_cmp(b));
    let q = |f: f64| vals[((vals.len() - 1) as f64 * f).round() as usize];
    let band = (q(0.98) - q(0.02)).max(0.1);
    let (s_r, s_f) = (up / n_up as f64, down / n_down as f64);
    let mean_air = air.iter().sum::<f64>() / air.len() as f64;
    let power = circ.tank_c * (s_r + s_f);
    let load = circ.tank_c * s_r - circ.tank_g_amb * (mean_air - circ.supply_c);
    vec![band, power, (load / power).clamp(0.05, 0.95)]
}

/// Where a sensor bias is: per sensor, a constant offset over all runs,
/// and per run the onset (any fit row) after which the fit-row residual
/// shifts most, scored in noise units less ln n per located choice.
fn locate_offset(ps: &[Prepared], res0: &[Vec<Vec<f64>>]) -> Option<Cand> {
    let mut best: Option<(Cand, f64)> = None;
    let mut consider = |c: Cand, score: f64| {
        if best.as_ref().is_none_or(|b| score > b.1) {
            best = Some((c, score));
        }
    };
    let n_all: usize = ps.iter().map(|p| p.rows()).sum();
    let pen = (n_all.max(2) as f64).ln();
    // constant over all runs
    let mut acc: std::collections::BTreeMap<String, (f64, usize, f64)> = Default::default();
    for (p, rr) in ps.iter().zip(res0) {
        for (c, r) in p.channels.iter().zip(rr) {
            if let Kind::Temp(_) = c.kind {
                let e = acc.entry(c.name.clone()).or_insert((0.0, 0, c.s));
                for (k, v) in r.iter().enumerate() {
                    if p.is_fit(k) && v.is_finite() {
                        e.0 += v;
                        e.1 += 1;
                    }
                }
            }
        }
    }
    for (name, (sum, n, s)) in acc {
        if n > 0 {
            consider(
                Cand {
                    sensor: name,
                    ..Cand::new("sensor_offset")
                },
                sum * sum / n as f64 / (s * s),
            );
        }
    }
    // a step in one run
    if ps.len() > 1 || ps.iter().any(|p| p.rows() > 20) {
        for (p, rr) in ps.iter().zip(res0) {
            for (c, r) in p.channels.iter().zip(rr) {
                if !matches!(c.kind, Kind::Temp(_)) {
                    continue;
                }
                // suffix sums over fit rows
                let nr = r.len();
                let (mut sum, mut n) = (0.0, 0usize);
                let mut best_k = (0usize, 0.0f64);
                for k in (0..nr).rev() {
                    if p.is_fit(k) && r[k].is_finite() {
                        sum += r[k];
                        n += 1;
                    }
                    if n >= 3 {
                        let sc = sum * sum / n as f64 / (c.s * c.s);
                        if sc > best_k.1 {
                            best_k = (k, sc);
                        }
                    }
                }
                let (k0, sc) = best_k;
                let at_s = if k0 == 0 {
                    0.0
                } else {
                    k0 as f64 * p.inputs.dt
                };
                let run = (ps.len() > 1).then(|| p.name.clone());
                let cand = Cand {
                    sensor: c.name.clone(),
                    at_s,
                    run,
                    ..Cand::new("sensor_offset")
                };
                let extra = cand.located() as f64 - 1.0;
                consider(cand, sc - extra * pen);
            }
        }
    }
    best.map(|b| b.0)
}

/// The sensor whose fit-row residual is best explained by a lag: the
/// least-squares τ of r ≈ −τ·dŷ/dt, its gain in noise units.
fn locate_lag(ev: &Evaluator, res0: &[Vec<Vec<f64>>]) -> Option<String> {
    let mut acc: std::collections::BTreeMap<String, (f64, f64, f64)> = Default::default();
    for ((p, rr), out) in ev.runs.iter().zip(res0).zip(&ev.nominal) {
        let dt = p.inputs.dt;
        for (c, r) in p.channels.iter().zip(rr) {
            let Kind::Temp(i) = c.kind else { continue };
            let y = &out.temps[i];
            let e = acc.entry(c.name.clone()).or_insert((0.0, 0.0, c.s));
            for k in 1..r.len().min(y.len()) {
                if p.is_fit(k) && r[k].is_finite() {
                    let d = -(y[k] - y[k - 1]) / dt;
                    e.0 += r[k] * d;
                    e.1 += d * d;
                }
            }
        }
    }
    acc.into_iter()
        .filter(|(_, (rd, dd, _))| *dd > 0.0 && *rd > 0.0)
        .map(|(n, (rd, dd, s))| (n, rd * rd / dd / (s * s)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|b| b.0)
}

/// The effects these runs and this machine file cannot decide, with why
/// (the machine-file mode's `untestable`; `diagnose fit` has its own).
pub fn untestable(
    m: &crate::sim::Machine,
    ps: &[Prepared],
    only: &[String],
) -> Vec<(String, String)> {
    let (has_disp, has_temp) = channel_kinds(ps);
    let coolant_on = ps.iter().any(|p| p.inputs.coolant.iter().any(|c| *c > 0.5));
    let flows = ps
        .iter()
        .any(|p| (0..p.rows()).any(|k| m.coolant_flows(p.inputs.rpm[k], p.inputs.coolant[k])));
    let feed = ps.iter().any(|p| p.inputs.feed.iter().any(|f| *f > 0.0));
    let mut out = Vec::new();
    for &k in ALL_EFFECT_NAMES.iter() {
        if !only.is_empty() && !only.iter().any(|o| o == k) {
            continue;
        }
        let why = match k {
            "coolant" if m.coolant_nodes.is_empty() => {
                Some("the machine file names no coolant site ([effects] coolant_nodes)")
            }
            "coolant" if !(coolant_on || (m.coolant.is_some() && flows)) => Some(
                "the coolant never flows in these runs (no coolant_on, no flow by the file's rule)",
            ),
            "chiller" if !m.coolant.as_ref().is_some_and(|c| c.tank_c > 0.0) => {
                Some("the machine file has no coolant tank (coolant.tank_c_j_per_k)")
            }
            "ballscrew" if m.ballscrew_nodes.is_empty() => {
                Some("the machine file names no ball-screw site ([effects] ballscrew_nodes)")
            }
            "ballscrew" if !feed => Some("no feed activity in these runs"),
            "bending" if m.bending.is_none() => {
                Some("the machine file names no bending pair ([effects] bending)")
            }
            "bending" if !has_disp => Some("no displacement column in these runs"),
            "sensor_lag" | "sensor_offset" if !has_temp => {
                Some("no temperature sensor column in these runs")
            }
            "bearing_nonlinear" if m.bnl_nodes.is_empty() => {
                Some("the machine file names no bearing site ([effects] bearing_nodes)")
            }
            "convection" if !m.area.iter().any(|a| *a > 0.0) => {
                Some("no node has an area_m2 (convection acts through it)")
            }
            _ => None,
        };
        if let Some(w) = why {
            out.push((k.to_string(), w.to_string()));
        }
    }
    out
}

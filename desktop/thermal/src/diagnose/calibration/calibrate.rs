//! Calibration of a machine file written from the design before the effect
//! search: a design's numbers are never exact, and a nominal whose heat
//! gains, conductances, losses or displacement lengths are off by 10–20 %
//! leaves a residual that any candidate effect with a free level (ball-screw
//! heat, a sensor offset, convection) will happily absorb. So the nominal's
//! uncertain parameters are first fitted on the fit rows, each as a log
//! scale factor θ on its design value inside its tolerance (the machine
//! file's `[tolerance]`, ±25 % by default: θ ∈ [ln(1 − tol), ln(1 + tol)])
//! with a Gaussian prior (one σ = half the tolerance), by
//! Gauss–Newton on the diagnosis' own criterion (per-channel unknown
//! variance, iteratively reweighted) plus the prior. The effect search then
//! works against the calibrated nominal. Whatever the calibration absorbs
//! (a different convection level, a heat source's gain, a displacement
//! lever) is then no gap and cannot be named: the report says so.

use anyhow::Result;
use serde_json::{json, Value};

use super::knobs::{apply, knobs, Knob};
use crate::diagnose::effects::Evaluator;
use crate::diagnose::runs::Prepared;
use crate::sim::Machine;
use tcomp_numerics::stats::block_means;

/// Gauss–Newton iterations.
const ITERS: usize = 3;

/// The calibrated nominal and what the calibration did.
pub struct Calibration {
    pub machine: Machine,
    pub json: Value,
    pub note: String,
    pub sims: usize,
    /// The design values it moved and their ln factors.
    pub(crate) knobs: Vec<Knob>,
    pub theta: Vec<f64>,
}

/// Per channel fit-row SSE and count, and the weighted residual vector
/// (fit rows, every `stride`-th) of a machine.
struct Eval {
    r: Vec<f64>,
    j: f64,
}

fn eval(
    m: &Machine,
    ps: &[Prepared],
    stride: usize,
    w: Option<&[f64]>,
) -> Result<(Eval, Vec<f64>)> {
    let ev = Evaluator::new(m, ps)?;
    let res = ev.residuals(&[])?;
    let st = ev.stats_of(&res);
    // weights: 1 / (SSE/n + (0.1 s)²) per channel, the criterion's own
    let w_now: Vec<f64> = st
        .ch
        .iter()
        .map(|c| {
            let n = c.n_fit.max(1) as f64;
            1.0 / (c.sse_fit / n + (0.1 * c.s).powi(2))
        })
        .collect();
    let w = w.unwrap_or(&w_now);
    let mut r = Vec::new();
    let mut ci = 0;
    for (p, rr) in ps.iter().zip(&res) {
        for ch in rr {
            let sw = (w[ci] * stride as f64).sqrt();
            for (k, v) in ch.iter().enumerate() {
                if k % stride == 0 && p.is_fit(k) {
                    r.push(if v.is_finite() { v * sw } else { 0.0 });
                }
            }
            ci += 1;
        }
    }
    Ok((Eval { r, j: st.j_fit() }, w_now))
}

/// Rows per run the calibration simulates (block-averaged inputs; the
/// exact zero-order hold keeps a coarse step exact for constant inputs and
/// the design's slow parameters need no finer grid).
const CAL_ROWS: usize = 480;

/// A run on a coarser grid: inputs block-averaged (coolant by majority),
/// measurements and the fit/held flag taken at each block's first row.
fn coarsen(p: &Prepared, max_rows: usize) -> Prepared {
    let n = p.rows();
    let f = n.div_ceil(max_rows.max(10)).max(1);
    if f == 1 {
        return p.clone();
    }
    let rows: Vec<usize> = (0..n).step_by(f).collect();
    let avg = |v: &[f64]| block_means(v, f);
    let mut q = p.clone();
    q.inputs.dt = p.inputs.dt * f as f64;
    q.inputs.rpm = avg(&p.inputs.rpm);
    q.inputs.feed = avg(&p.inputs.feed);
    q.inputs.ambient = avg(&p.inputs.ambient);
    q.inputs.coolant = avg(&p.inputs.coolant)
        .into_iter()
        .map(|c| if c >= 0.5 { 1.0 } else { 0.0 })
        .collect();
    for c in q.channels.iter_mut() {
        c.meas = rows.iter().map(|&r| c.meas[r]).collect();
    }
    q.held = rows.iter().map(|&r| p.held[r]).collect();
    q.decimation = p.decimation * f;
    q
}

/// Calibrate the machine's uncertain parameters on the fit rows.
pub fn calibrate(m: &Machine, full: &[Prepared], threads: usize) -> Result<Calibration> {
    let t0 = std::time::Instant::now();
    let ps: Vec<Prepared> = full.iter().map(|p| coarsen(p, CAL_ROWS)).collect();
    let ps = &ps[..];
    let ks = knobs(m);
    let nk = ks.len();
    let rows: usize = ps
        .iter()
        .map(|p| (0..p.rows()).filter(|&k| p.is_fit(k)).count())
        .sum();
    let stride = rows.div_ceil(1500).max(1);
    let prec: Vec<f64> = ks.iter().map(|k| 1.0 / k.sigma().powi(2)).collect();
    let (lo, hi): (Vec<f64>, Vec<f64>) = ks.iter().map(Knob::bounds).unzip();
    let prior = |th: &[f64]| th.iter().zip(&prec).map(|(t, p)| t * t * p).sum::<f64>();
    let mut theta = vec![0.0; nk];
    let (e0, _) = eval(m, ps, stride, None)?;
    let j_design = e0.j;
    let mut j_cur = e0.j + prior(&theta);
    let mut sims = 1usize;
    let h = 0.03;
    for _ in 0..ITERS {
        let cur = apply(m, &ks, &theta);
        let (base, w) = eval(&cur, ps, stride, None)?;
        // Jacobian of the weighted residual by forward differences
        let cols: Vec<Result<Vec<f64>>> =
            crate::diagnose::effects::par_map(&(0..nk).collect::<Vec<_>>(), threads, |&i| {
                let mut t = theta.clone();
                t[i] += h;
                let (e, _) = eval(&apply(m, &ks, &t), ps, stride, Some(&w))?;
                Ok(e.r.iter().zip(&base.r).map(|(a, b)| (a - b) / h).collect())
            });
        sims += nk + 1;
        let cols = cols.into_iter().collect::<Result<Vec<_>>>()?;
        // normal equations of  |r − J δ|² + Σ (θ + δ)²/σ², θ + δ inside
        // the tolerance: a box-constrained step
        let mut a = nalgebra::DMatrix::<f64>::zeros(nk, nk);
        let mut g = vec![0.0; nk];
        for i in 0..nk {
            for j in i..nk {
                let v: f64 = cols[i].iter().zip(&cols[j]).map(|(x, y)| x * y).sum();
                a[(i, j)] = v;
                a[(j, i)] = v;
            }
            a[(i, i)] += prec[i];
            // r(θ + δ) ≈ r + J δ (J = ∂r/∂θ of the weighted residual)
            g[i] =
                -cols[i].iter().zip(&base.r).map(|(x, y)| x * y).sum::<f64>() - prec[i] * theta[i];
        }
        let dlo: Vec<f64> = (0..nk).map(|i| lo[i] - theta[i]).collect();
        let dhi: Vec<f64> = (0..nk).map(|i| hi[i] - theta[i]).collect();
        // exact (active set, from the unconstrained step): the capped
        // sweeps from 0 ended unsettled along the near-collinear knobs
        let free = a.clone().cholesky().map_or_else(
            || vec![0.0; nk],
            |c| {
                c.solve(&nalgebra::DVector::from_column_slice(&g))
                    .as_slice()
                    .to_vec()
            },
        );
        let delta = super::boxqp::box_qp_exact(&a, &g, &dlo, &dhi, &free).0;
        // step halving on the criterion (data + prior)
        let mut step = 1.0;
        let mut moved = false;
        for _ in 0..4 {
            let t: Vec<f64> = (0..nk)
                .map(|i| (theta[i] + step * delta[i]).clamp(lo[i], hi[i]))
                .collect();
            let (e, _) = eval(&apply(m, &ks, &t), ps, stride, None)?;
            sims += 1;
            let j = e.j + prior(&t);
            if j < j_cur {
                j_cur = j;
                theta = t;
                moved = true;
                break;
            }
            step *= 0.5;
        }
        if !moved {
            break;
        }
    }
    let cal = apply(m, &ks, &theta);
    if std::env::var_os("TCOMP_DIAG_TIMING").is_some() {
        eprintln!(
            "diagnose timing: calibration {nk} knobs, {sims} coarse sims ({} rows per run), {:.3} s",
            ps.first().map_or(0, |p| p.rows()),
            t0.elapsed().as_secs_f64()
        );
    }
    // held-out gap by design and calibrated (noise units, µm, °C)
    let st_d = Evaluator::new(m, full)?.stats(&[])?;
    let st_c = Evaluator::new(&cal, full)?.stats(&[])?;
    sims += 2;
    let mut moved: Vec<(usize, f64)> = theta.iter().copied().enumerate().collect();
    moved.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let on_bound: Vec<String> = theta
        .iter()
        .enumerate()
        .filter(|(i, t)| {
            let (l, h) = ks[*i].bounds();
            **t <= l + 1e-6 || **t >= h - 1e-6
        })
        .map(|(i, t)| format!("{} ×{:.2}", ks[i].name, t.exp()))
        .collect();
    let r4 = crate::diagnose::signal::r4;
    let json = json!({
        "method": "each uncertain design value (capacity, loss to ambient, link and jacket conductance per element; heat gain per heated node (sources, bearings and motor loss on it, its bearings' viscous term f0 a gain of its own; per driver when one node carries heat); displacement length per term) scaled by exp(θ), θ fitted on the fit rows by Gauss–Newton on the diagnosis criterion plus a Gaussian prior",
        "bounds": "each design value within its tolerance (machine file [tolerance], default ±25 %): factor 1 − tol … 1 + tol; prior one σ = half the tolerance (ln)",
        "tolerances": tol_summary(&ks),
        "parameters": nk,
        "criterion_design": r4(j_design),
        "criterion_calibrated": r4(j_cur - prior(&theta)),
        "held_out_norm_gap_design": r4(st_d.m_held().sqrt()),
        "held_out_norm_gap_calibrated": r4(st_c.m_held().sqrt()),
        "gap_um_design": st_d.gap_held(true).map(|g| r4(g.0)),
        "gap_um_calibrated": st_c.gap_held(true).map(|g| r4(g.0)),
        "gap_c_design": st_d.gap_held(false).map(|g| r4(g.0)),
        "gap_c_calibrated": st_c.gap_held(false).map(|g| r4(g.0)),
        "largest_changes": moved.iter().take(8).map(|&(i, t)| json!({"name": ks[i].name, "factor": r4(t.exp())})).collect::<Vec<_>>(),
        "on_bound": on_bound,
        "absorbed": "an effect that acts like a change of these parameters (a different convection level or loss, a node's heat within its tolerance, a displacement lever) is absorbed by the calibration: it is no gap and is not named",
    });
    let note = format!(
        "machine file calibrated on the fit rows within its tolerances ({nk} design values, {}): held-out gap {:.2} → {:.2} (noise units){}",
        tol_summary(&ks),
        st_d.m_held().sqrt(),
        st_c.m_held().sqrt(),
        if on_bound.is_empty() {
            String::new()
        } else {
            format!("; on a bound: {}", on_bound.join(", "))
        }
    );
    Ok(Calibration {
        machine: cal,
        json,
        note,
        sims,
        knobs: ks,
        theta,
    })
}

/// The tolerances in use, by group (distinct values).
fn tol_summary(ks: &[Knob]) -> String {
    let mut by: std::collections::BTreeMap<&str, Vec<f64>> = Default::default();
    for k in ks {
        let v = by.entry(k.group).or_default();
        if !v.iter().any(|x| (x - k.tol).abs() < 1e-9) {
            v.push(k.tol);
        }
    }
    by.iter()
        .map(|(g, v)| {
            let t: Vec<String> = v.iter().map(|x| format!("±{:.0} %", x * 100.0)).collect();
            format!("{g} {}", t.join("/"))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::super::knobs::design_value;
    use super::*;

    /// The first simulator's turning centre with these tolerances.
    fn turning_center(tolerances: &[(&str, f64)]) -> Machine {
        let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/machines/turning-center-16.toml");
        let mut spec = Machine::load(&p).unwrap().spec;
        for &(k, t) in tolerances {
            spec.tolerance.insert(k.into(), t);
        }
        Machine::compile(spec).unwrap()
    }

    #[test]
    fn a_heated_node_takes_its_own_tolerance_else_its_driver_s() {
        let m = turning_center(&[("heat:spindle", 0.1), ("heat:rear_bearing", 0.4)]);
        let ks = knobs(&m);
        let tol = |name: &str| ks.iter().find(|k| k.name == name).map(|k| k.tol);
        assert_eq!(tol("heat at rear_bearing"), Some(0.4));
        assert_eq!(tol("heat at front_bearing"), Some(0.1));
        // one gain per heated node: no driver gain on top of them
        assert!(ks.iter().all(|k| !k.name.starts_with("spindle heat")));
    }

    #[test]
    fn a_bearing_s_viscous_term_is_a_knob_of_its_own_that_scales_only_f0() {
        let m = turning_center(&[
            ("heat:spindle", 0.1),
            ("heat:rear_bearing", 0.4),
            ("heat:front_bearing:f0", 0.3),
        ]);
        let ks = knobs(&m);
        let knob = |name: &str| ks.iter().find(|k| k.name == name).unwrap();
        let front = knob("viscous bearing friction (f0) at front_bearing");
        let rear = knob("viscous bearing friction (f0) at rear_bearing");
        // its own key, else its node's, else the driver's
        assert_eq!(front.tol, 0.3);
        assert_eq!(rear.tol, 0.4);
        assert_eq!(front.element.as_deref(), Some("front_bearing:f0"));
        // the two knobs of a node split its bearing heat at n_max
        let load = knob("heat at front_bearing");
        let i = m
            .spec
            .bearings
            .iter()
            .position(|b| b.node == "front_bearing")
            .unwrap();
        let b = &m.spec.bearings[i];
        let whole = b.heat_w(m.spec.n_max_rpm);
        let parts = design_value(&m, front) + design_value(&m, load);
        assert!((parts - whole).abs() < 1e-9 * whole, "{parts} vs {whole}");
        assert!(design_value(&m, front) > 0.0 && design_value(&m, load) > 0.0);
        // applied, the viscous knob moves f0 only; the node's knob f1 only
        let fi = ks.iter().position(|k| k.name == front.name).unwrap();
        let li = ks.iter().position(|k| k.name == load.name).unwrap();
        let mut th = vec![0.0; ks.len()];
        th[fi] = 0.2f64.ln_1p();
        let a = apply(&m, &ks, &th);
        assert!((a.spec.bearings[i].f0 - 1.2 * b.f0).abs() < 1e-12);
        assert_eq!(a.spec.bearings[i].f1, b.f1);
        let mut th = vec![0.0; ks.len()];
        th[li] = 0.2f64.ln_1p();
        let a = apply(&m, &ks, &th);
        assert_eq!(a.spec.bearings[i].f0, b.f0);
        assert!((a.spec.bearings[i].f1 - 1.2 * b.f1).abs() < 1e-12);
    }
}

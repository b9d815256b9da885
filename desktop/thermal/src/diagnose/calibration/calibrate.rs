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

use crate::diagnose::effects::Evaluator;
use crate::diagnose::runs::Prepared;
use crate::sim::Machine;
use tcomp_numerics::stats::block_means;

/// Above this many element parameters, elements of a kind share one factor.
const MAX_KNOBS: usize = 160;
/// Gauss–Newton iterations.
const ITERS: usize = 3;

/// What a knob scales.
#[derive(Clone, Debug)]
pub(crate) enum Target {
    Capacity(Vec<usize>),
    Loss(Vec<usize>),
    Link(Vec<usize>),
    Jacket(Vec<usize>),
    Heat {
        sources: Vec<usize>,
        bearings: Vec<usize>,
        motor: bool,
        terms: Terms,
    },
    Term(usize, Vec<usize>),
}

/// Which terms of its bearings' Palmgren friction a heat knob scales: the
/// viscous term (f0, heat ∝ n^(5/3)) and the load term (f1, heat ∝ n) are
/// two design numbers, each with its tolerance and its own speed law. One
/// gain on both kept the file's split between them exact: a lubrication
/// factor 30 % low then read as an extra heat of speed law ≈ n^1.4 on a
/// healthy machine (cross model, design file σ 15 %).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Terms {
    Both,
    Viscous,
    Load,
}

#[derive(Clone, Debug)]
pub(crate) struct Knob {
    pub name: String,
    target: Target,
    /// Its tolerance group (`sim::machine::tolerance::GROUPS`).
    pub group: &'static str,
    /// Its element key within the group (None: the whole group).
    pub element: Option<String>,
    /// Its tolerance (fraction): θ ∈ [ln(1 − tol), ln(1 + tol)].
    pub tol: f64,
    /// The element keys whose tolerance applies, first named first, when
    /// the file names none for `element` (a heated node: its driver,
    /// `spindle` or `feed`; a node's viscous term: the node, its driver).
    tol_from: Vec<String>,
}

impl Knob {
    fn new(name: String, target: Target, group: &'static str, element: Option<String>) -> Knob {
        Knob {
            name,
            target,
            group,
            element,
            tol: 0.0,
            tol_from: Vec::new(),
        }
    }
    /// Bounds of θ (ln factor) inside the tolerance.
    pub fn bounds(&self) -> (f64, f64) {
        ((1.0 - self.tol).ln(), (1.0 + self.tol).ln())
    }
    /// Prior spread of θ: half the tolerance (the bound is 2 σ).
    pub fn sigma(&self) -> f64 {
        (0.5 * (1.0 + self.tol).ln()).max(1e-6)
    }
}

/// Knobs by how fine they are: `common` always apply; `element` (one per
/// element) when they fit under `MAX_KNOBS` together with `common`,
/// otherwise `grouped` (one per kind of element).
#[derive(Default)]
struct KnobSets {
    common: Vec<Knob>,
    element: Vec<Knob>,
    grouped: Vec<Knob>,
}

impl KnobSets {
    fn chosen(self) -> Vec<Knob> {
        let mut out = self.common;
        if self.element.len() + out.len() <= MAX_KNOBS {
            out.extend(self.element);
        } else {
            out.extend(self.grouped.into_iter().filter(|k| match &k.target {
                Target::Capacity(v) | Target::Loss(v) | Target::Link(v) | Target::Jacket(v) => {
                    !v.is_empty()
                }
                Target::Term(_, v) => !v.is_empty(),
                _ => true,
            }));
        }
        out
    }
}

fn node_name(m: &Machine, i: usize) -> String {
    m.names.get(i).cloned().unwrap_or_else(|| format!("#{i}"))
}

/// Capacities and losses: per lumped node; rod slices share one each.
fn add_node_knobs(m: &Machine, sets: &mut KnobSets) {
    let n_lumped = m.spec.nodes.len();
    let rod: Vec<usize> = (n_lumped..m.n).collect();
    let lumped_c: Vec<usize> = (0..n_lumped).filter(|&i| m.c[i] > 0.0).collect();
    let lumped_g: Vec<usize> = (0..n_lumped).filter(|&i| m.g_amb[i] > 0.0).collect();
    for &i in &lumped_c {
        let n = node_name(m, i);
        let t = Target::Capacity(vec![i]);
        sets.element
            .push(Knob::new(format!("c_j_per_k {n}"), t, "capacity", Some(n)));
    }
    let t = Target::Capacity(lumped_c);
    sets.grouped.push(Knob::new(
        "c_j_per_k (all nodes)".into(),
        t,
        "capacity",
        None,
    ));
    for &i in &lumped_g {
        let n = node_name(m, i);
        let t = Target::Loss(vec![i]);
        sets.element
            .push(Knob::new(format!("g_amb_w_per_k {n}"), t, "film", Some(n)));
    }
    let t = Target::Loss(lumped_g);
    sets.grouped.push(Knob::new(
        "g_amb_w_per_k (all nodes)".into(),
        t,
        "film",
        None,
    ));
    if !rod.is_empty() {
        let t = Target::Capacity(rod.clone());
        let rod_name = Some("rod".to_string());
        sets.common.push(Knob::new(
            "rod capacity".into(),
            t,
            "capacity",
            rod_name.clone(),
        ));
        let rg: Vec<usize> = rod.iter().copied().filter(|&i| m.g_amb[i] > 0.0).collect();
        if !rg.is_empty() {
            sets.common.push(Knob::new(
                "rod g_amb".into(),
                Target::Loss(rg),
                "film",
                rod_name,
            ));
        }
    }
}

/// Conductances: per link between lumped nodes; the rod's links share one.
fn add_link_knobs(m: &Machine, sets: &mut KnobSets) {
    let n_lumped = m.spec.nodes.len();
    let (mut rod_links, mut lumped_links) = (Vec::new(), Vec::new());
    for (k, &(a, b, g)) in m.links.iter().enumerate() {
        if g <= 0.0 {
            continue;
        }
        if a >= n_lumped && b >= n_lumped {
            rod_links.push(k);
        } else {
            lumped_links.push(k);
            let (na, nb) = (node_name(m, a), node_name(m, b));
            sets.element.push(Knob::new(
                format!("link {na}–{nb}"),
                Target::Link(vec![k]),
                "link",
                Some(format!("{na}-{nb}")),
            ));
        }
    }
    let t = Target::Link(lumped_links);
    sets.grouped
        .push(Knob::new("g_w_per_k (all links)".into(), t, "link", None));
    if !rod_links.is_empty() {
        let t = Target::Link(rod_links);
        sets.common.push(Knob::new(
            "rod conduction".into(),
            t,
            "link",
            Some("rod".into()),
        ));
    }
}

/// The coolant jacket's conductances, per jacketed node.
fn add_jacket_knobs(m: &Machine, sets: &mut KnobSets) {
    let Some(c) = &m.coolant else {
        return;
    };
    let js: Vec<usize> = (0..c.jacket.len())
        .filter(|&j| c.jacket[j].1 > 0.0)
        .collect();
    for &j in &js {
        let n = node_name(m, c.jacket[j].0);
        let t = Target::Jacket(vec![j]);
        sets.element
            .push(Knob::new(format!("jacket {n}"), t, "jacket", Some(n)));
    }
    if !js.is_empty() {
        let t = Target::Jacket(js);
        sets.grouped
            .push(Knob::new("jacket (all)".into(), t, "jacket", None));
    }
}

/// Heat gains: one per heated node (`add_heat_node_knobs`) when more than
/// one node carries heat, else one per driver (the spindle-driven sources,
/// bearings and motor loss; the feed-driven sources). A drawing's heat
/// numbers are off per source (each bearing's friction factors, each loss),
/// not only per driver: with one gain per driver the split between sources
/// was taken as exact and a lone bearing 20 % off read as an extra bearing
/// heat on a healthy machine. The per-node gain is bounded by the
/// tolerance, so an effect that needs more (or another speed law) still
/// shows — as a heat effect or, released, as "heat source stronger than
/// designed".
fn add_heat_knobs(m: &Machine, sets: &mut KnobSets) {
    if add_heat_node_knobs(m, sets) {
        return;
    }
    let driven_by = |driver: crate::sim::machine::Driver| -> Vec<usize> {
        (0..m.spec.sources.len())
            .filter(|&s| m.spec.sources[s].driver == driver && m.spec.sources[s].w_at_nmax > 0.0)
            .collect()
    };
    let spindle = driven_by(crate::sim::machine::Driver::Spindle);
    let feed = driven_by(crate::sim::machine::Driver::Feed);
    let motor = m.motor_node.is_some() && m.spec.motor_loss_frac * m.spec.rated_power_w > 0.0;
    if !spindle.is_empty() || !m.spec.bearings.is_empty() || motor {
        let t = Target::Heat {
            sources: spindle,
            bearings: (0..m.spec.bearings.len()).collect(),
            motor,
            terms: Terms::Both,
        };
        sets.common.push(Knob::new(
            "spindle heat (all spindle-driven sources, bearings, motor)".into(),
            t,
            "heat",
            Some("spindle".into()),
        ));
    }
    if !feed.is_empty() {
        let t = Target::Heat {
            sources: feed,
            bearings: vec![],
            motor: false,
            terms: Terms::Both,
        };
        sets.common.push(Knob::new(
            "feed heat (all feed-driven sources)".into(),
            t,
            "heat",
            Some("feed".into()),
        ));
    }
}

/// One heat gain per node that carries heat (its sources of either driver,
/// its bearings, the motor loss) when more than one node does: with one,
/// the driver gains already cover it. Its tolerance falls back to its
/// driver's (`heat:spindle`, `heat:feed`) when the file names none for it.
/// The viscous term (f0) of a node's bearings is a knob of its own
/// (`heat:<node>:f0`, tolerance falling back to the node's, then the
/// driver's) when the node has other heat: see [`Terms`].
fn add_heat_node_knobs(m: &Machine, sets: &mut KnobSets) -> bool {
    use crate::sim::machine::Driver;
    // a node's sources, bearings and whether the motor loss sits on it
    type NodeHeat = (Vec<usize>, Vec<usize>, bool);
    let heat_at = |i: usize| -> NodeHeat {
        let sources = (0..m.spec.sources.len())
            .filter(|&s| {
                m.spec.sources[s].w_at_nmax > 0.0
                    && node_index(m, &m.spec.sources[s].node) == Some(i)
            })
            .collect();
        let bearings = (0..m.spec.bearings.len())
            .filter(|&b| node_index(m, &m.spec.bearings[b].node) == Some(i))
            .collect();
        let motor = m.motor_node == Some(i) && m.spec.motor_loss_frac * m.spec.rated_power_w > 0.0;
        (sources, bearings, motor)
    };
    let heated: Vec<(usize, NodeHeat)> = (0..m.n)
        .map(|i| (i, heat_at(i)))
        .filter(|(_, (s, b, motor))| !s.is_empty() || !b.is_empty() || *motor)
        .collect();
    if heated.len() < 2 {
        return false;
    }
    for (i, (sources, bearings, motor)) in heated {
        let spindle_driven = motor
            || !bearings.is_empty()
            || sources
                .iter()
                .any(|&s| m.spec.sources[s].driver == Driver::Spindle);
        let n = node_name(m, i);
        let driver = if spindle_driven { "spindle" } else { "feed" };
        let b = &m.spec.bearings;
        let viscous: Vec<usize> = bearings
            .iter()
            .copied()
            .filter(|&j| b[j].f0 > 0.0)
            .collect();
        let other_heat =
            !sources.is_empty() || motor || bearings.iter().any(|&j| b[j].f1 * b[j].load_n > 0.0);
        // the viscous term its own knob when the node has other heat
        let split = !viscous.is_empty() && other_heat;
        if split {
            let t = Target::Heat {
                sources: Vec::new(),
                bearings: viscous,
                motor: false,
                terms: Terms::Viscous,
            };
            let mut k = Knob::new(
                format!("viscous bearing friction (f0) at {n}"),
                t,
                "heat",
                Some(format!("{n}:f0")),
            );
            k.tol_from = vec![n.clone(), driver.into()];
            sets.common.push(k);
        }
        let t = Target::Heat {
            sources,
            bearings,
            motor,
            terms: if split { Terms::Load } else { Terms::Both },
        };
        let mut k = Knob::new(format!("heat at {n}"), t, "heat", Some(n));
        k.tol_from = vec![driver.into()];
        sets.common.push(k);
    }
    true
}

fn node_index(m: &Machine, name: &str) -> Option<usize> {
    m.names.iter().position(|n| n == name)
}

/// Displacement: per term, or one lever per direction.
fn add_term_knobs(m: &Machine, sets: &mut KnobSets) {
    for (d, terms) in m.dir_terms.iter().enumerate() {
        let dir = m.dir_cols.get(d).cloned().unwrap_or_default();
        let dir_name = m
            .spec
            .directions
            .get(d)
            .map_or(dir.clone(), |x| x.name.clone());
        let live: Vec<usize> = (0..terms.len()).filter(|&t| terms[t].1 != 0.0).collect();
        for &t in &live {
            let n = node_name(m, terms[t].0);
            sets.element.push(Knob::new(
                format!("{dir} term {n}"),
                Target::Term(d, vec![t]),
                "length",
                Some(format!("{dir_name}:{n}")),
            ));
        }
        let t = Target::Term(d, live);
        sets.grouped
            .push(Knob::new(format!("{dir} (all terms)"), t, "length", None));
    }
}

/// The calibration's knobs, each with its tolerance from the file (a knob
/// whose tolerance is 0 is exact: no knob).
pub(crate) fn knobs(m: &Machine) -> Vec<Knob> {
    let mut sets = KnobSets::default();
    add_node_knobs(m, &mut sets);
    add_link_knobs(m, &mut sets);
    add_jacket_knobs(m, &mut sets);
    add_heat_knobs(m, &mut sets);
    add_term_knobs(m, &mut sets);
    let tol = &m.spec.tolerance;
    let mut ks = sets.chosen();
    for k in ks.iter_mut() {
        // a heated node's own key, else its driver's (`heat:spindle`)
        let named = |e: &str| tol.contains_key(&format!("{}:{e}", k.group));
        let element = match &k.element {
            Some(e) if !named(e) && !k.tol_from.is_empty() => k
                .tol_from
                .iter()
                .find(|f| named(f))
                .or(k.tol_from.last())
                .map(String::as_str),
            e => e.as_deref(),
        };
        k.tol = crate::sim::machine::tolerance::of(tol, k.group, element);
    }
    ks.retain(|k| k.tol > 0.0);
    ks
}

/// The design value a knob scales (summed over its elements; heat: W at
/// full drive — sources, bearings at n_max, motor loss; length: |mm|).
pub(crate) fn design_value(m: &Machine, k: &Knob) -> f64 {
    match &k.target {
        Target::Capacity(v) => v.iter().map(|&i| m.c[i]).sum(),
        Target::Loss(v) => v.iter().map(|&i| m.g_amb[i]).sum(),
        Target::Link(v) => v.iter().map(|&i| m.links[i].2).sum(),
        Target::Jacket(v) => m
            .coolant
            .as_ref()
            .map_or(0.0, |c| v.iter().map(|&j| c.jacket[j].1).sum()),
        Target::Heat {
            sources,
            bearings,
            motor,
            terms,
        } => {
            let n_max = m.spec.n_max_rpm;
            let src: f64 = sources.iter().map(|&s| m.spec.sources[s].w_at_nmax).sum();
            let brg: f64 = bearings
                .iter()
                .map(|&b| {
                    let mut b = m.spec.bearings[b].clone();
                    match terms {
                        Terms::Both => {}
                        Terms::Viscous => b.f1 = 0.0,
                        Terms::Load => b.f0 = 0.0,
                    }
                    b.heat_w(n_max)
                })
                .sum();
            let mot = if *motor {
                m.spec.motor_loss_frac * m.spec.rated_power_w
            } else {
                0.0
            };
            src + brg + mot
        }
        Target::Term(d, v) => v.iter().map(|&t| m.dir_terms[*d][t].1.abs()).sum(),
    }
}

pub(crate) fn apply(m: &Machine, ks: &[Knob], theta: &[f64]) -> Machine {
    let mut c = m.clone();
    for (k, &t) in ks.iter().zip(theta) {
        if t == 0.0 {
            continue;
        }
        let f = t.exp();
        match &k.target {
            Target::Capacity(v) => v.iter().for_each(|&i| c.c[i] *= f),
            Target::Loss(v) => v.iter().for_each(|&i| c.g_amb[i] *= f),
            Target::Link(v) => v.iter().for_each(|&i| c.links[i].2 *= f),
            Target::Jacket(v) => {
                if let Some(circ) = c.coolant.as_mut() {
                    v.iter().for_each(|&j| circ.jacket[j].1 *= f);
                }
            }
            Target::Heat {
                sources,
                bearings,
                motor,
                terms,
            } => {
                sources
                    .iter()
                    .for_each(|&s| c.spec.sources[s].w_at_nmax *= f);
                for &b in bearings {
                    if *terms != Terms::Load {
                        c.spec.bearings[b].f0 *= f;
                    }
                    if *terms != Terms::Viscous {
                        c.spec.bearings[b].f1 *= f;
                    }
                }
                if *motor {
                    c.spec.motor_loss_frac *= f;
                }
            }
            Target::Term(d, v) => v.iter().for_each(|&t| c.dir_terms[*d][t].1 *= f),
        }
    }
    c
}

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
    use super::*;

    /// The first simulator's turning centre with these tolerances.
    fn turning_center(tolerances: &[(&str, f64)]) -> Machine {
        let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../machines/turning-center-16.toml");
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

//! The calibration's knobs: which design values of a machine file its
//! tolerances let the calibration move (node capacities and losses, links,
//! jackets, heat gains, displacement terms), each a log factor on its design
//! value, how many (elements of a kind share one factor past
//! [`MAX_KNOBS`]), and the machine with a set of factors applied.
//! [`super::calibrate`] fits them.

use crate::sim::Machine;

/// Above this many element parameters, elements of a kind share one factor.
const MAX_KNOBS: usize = 160;

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

/// One knob per node of `nodes` (element) and one for them all (grouped).
fn per_node_knobs(
    m: &Machine,
    sets: &mut KnobSets,
    nodes: Vec<usize>,
    key: &str,
    group: &'static str,
    target: fn(Vec<usize>) -> Target,
) {
    for &i in &nodes {
        let n = node_name(m, i);
        let name = format!("{key} {n}");
        sets.element
            .push(Knob::new(name, target(vec![i]), group, Some(n)));
    }
    let name = format!("{key} (all nodes)");
    sets.grouped
        .push(Knob::new(name, target(nodes), group, None));
}

/// Capacities and losses: per lumped node; rod slices share one each.
fn add_node_knobs(m: &Machine, sets: &mut KnobSets) {
    let n_lumped = m.spec.nodes.len();
    let rod: Vec<usize> = (n_lumped..m.n).collect();
    let lumped_c: Vec<usize> = (0..n_lumped).filter(|&i| m.c[i] > 0.0).collect();
    let lumped_g: Vec<usize> = (0..n_lumped).filter(|&i| m.g_amb[i] > 0.0).collect();
    per_node_knobs(m, sets, lumped_c, "c_j_per_k", "capacity", Target::Capacity);
    per_node_knobs(m, sets, lumped_g, "g_amb_w_per_k", "film", Target::Loss);
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

//! Machine descriptions (TOML, documented in `examples/machines/README.md`)
//! and their compilation into a lumped thermal network.

use anyhow::{anyhow, bail, Context, Result};
use std::path::Path;

use super::limits;

pub mod spec;
pub mod tolerance;

pub use spec::{
    BearingSpec, BendingSite, CoolantSpec, DirectionSpec, Driver, EffectSites, Flow, JacketSpec,
    LinkSpec, MachineSpec, NodeSpec, Noise, RodEnd, RodSpec, SensorSpec, SourceSpec, TermSpec,
    ALPHA_STEEL,
};

/// Where a sensor reads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Probe {
    Node(usize),
    Ambient,
    /// The coolant of the `[coolant]` circuit.
    Coolant,
}

/// A compiled `[coolant]` circuit.
#[derive(Clone, Debug)]
pub struct Circuit {
    pub supply_c: f64,
    pub flows: Flow,
    /// (node, conductance while flowing [W/K])
    pub jacket: Vec<(usize, f64)>,
    pub tank_c: f64,
    pub tank_g_amb: f64,
}

/// The compiled network: node `i < n_lumped` are lumped nodes, then rod
/// slices. All temperatures absolute [°C].
#[derive(Clone, Debug)]
pub struct Machine {
    pub spec: MachineSpec,
    pub names: Vec<String>,
    pub n: usize,
    pub c: Vec<f64>,
    pub g_amb: Vec<f64>,
    pub amb_offset: Vec<f64>,
    pub area: Vec<f64>,
    /// Symmetric links (i, j, g).
    pub links: Vec<(usize, usize, f64)>,
    pub motor_node: Option<usize>,
    pub bearing_nodes: Vec<usize>,
    /// Where `bearing_nonlinear` acts (`effects.bearing_nodes`, else the bearings).
    pub bnl_nodes: Vec<usize>,
    pub source_nodes: Vec<usize>,
    pub coolant: Option<Circuit>,
    pub sensor_cols: Vec<String>,
    pub sensor_probe: Vec<Probe>,
    pub dir_cols: Vec<String>,
    /// Per direction: (node, α·L [µm/K]).
    pub dir_terms: Vec<Vec<(usize, f64)>>,
    pub coolant_nodes: Vec<usize>,
    pub ballscrew_nodes: Vec<usize>,
    /// (a, b, direction index)
    pub bending: Option<(usize, usize, usize)>,
}

/// Column name of a sensor (`T01` kept, `spindle` → `T_spindle`).
pub fn sensor_column(name: &str) -> String {
    if tcomp_data::runcsv::is_temperature_column(name) {
        name.to_string()
    } else {
        format!("T_{name}")
    }
}

/// The network's nodes (lumped, then rod slices) and links.
struct Network {
    names: Vec<String>,
    c: Vec<f64>,
    g_amb: Vec<f64>,
    area: Vec<f64>,
    amb_offset: Vec<f64>,
    links: Vec<(usize, usize, f64)>,
    /// Indexes of the rod's slices (empty without a rod).
    rod_range: std::ops::Range<usize>,
}

/// Nodes and links of the spec: the lumped nodes, the rod cut into slices
/// linked in a chain and to its end nodes, then the links; checked for
/// duplicate or reserved names, capacities and a path to ambient.
fn compile_network(spec: &MachineSpec) -> Result<Network> {
    let mut names: Vec<String> = spec.nodes.iter().map(|n| n.name.clone()).collect();
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            bail!("node `{n}` defined twice");
        }
        if n == "ambient" || n == "rod" || n.starts_with("rod:") {
            bail!("node name `{n}` is reserved");
        }
    }
    let mut c: Vec<f64> = spec.nodes.iter().map(|n| n.c_j_per_k).collect();
    let mut g_amb: Vec<f64> = spec.nodes.iter().map(|n| n.g_amb_w_per_k).collect();
    let mut area: Vec<f64> = spec.nodes.iter().map(|n| n.area_m2).collect();
    let mut amb_offset: Vec<f64> = spec.nodes.iter().map(|n| n.amb_offset_c).collect();
    let n_lumped = names.len();
    let mut links = Vec::new();
    let mut rod_range = n_lumped..n_lumped;
    if let Some(rod) = &spec.rod {
        let ns = rod.segments;
        let l = rod.length_mm * 1e-3;
        let d = rod.diameter_mm * 1e-3;
        let acs = std::f64::consts::PI * d * d / 4.0;
        let dl = l / ns as f64;
        let g_seg = rod.k_w_per_mk * acs / dl;
        let c_seg = rod.rho_kg_m3 * rod.cp_j_per_kgk * acs * dl;
        let a_seg = std::f64::consts::PI * d * dl;
        for i in 0..ns {
            names.push(format!("rod:{i}"));
            c.push(c_seg);
            g_amb.push(rod.g_amb_w_per_k / ns as f64);
            area.push(a_seg);
            amb_offset.push(0.0);
            if i > 0 {
                links.push((n_lumped + i - 1, n_lumped + i, g_seg));
            }
        }
        rod_range = n_lumped..n_lumped + ns;
    }
    let find = |r: &str, what: &str| find_node(&names, r, what);
    if let Some(rod) = &spec.rod {
        if let Some(f) = &rod.front {
            links.push((find(&f.node, "rod.front")?, rod_range.start, f.g_w_per_k));
        }
        if let Some(r) = &rod.rear {
            links.push((find(&r.node, "rod.rear")?, rod_range.end - 1, r.g_w_per_k));
        }
    }
    for l in &spec.links {
        let a = find(&l.a, "link.a")?;
        let b = find(&l.b, "link.b")?;
        if a == b || l.g_w_per_k < 0.0 {
            bail!("link {}–{}: needs two different nodes and g ≥ 0", l.a, l.b);
        }
        links.push((a, b, l.g_w_per_k));
    }
    for (i, ci) in c.iter().enumerate() {
        if !(*ci > 0.0) {
            bail!("node `{}`: heat capacity must be > 0", names[i]);
        }
    }
    if g_amb.iter().all(|g| *g <= 0.0) {
        bail!("no node has g_amb_w_per_k > 0: the network has no path to ambient");
    }
    Ok(Network {
        names,
        c,
        g_amb,
        area,
        amb_offset,
        links,
        rod_range,
    })
}

/// Index of node `r` (`what` names the reference in the error).
fn find_node(names: &[String], r: &str, what: &str) -> Result<usize> {
    names
        .iter()
        .position(|x| x == r)
        .ok_or_else(|| anyhow!("{what}: unknown node `{r}`"))
}

/// Each sensor's CSV column and what it reads.
fn compile_sensors(spec: &MachineSpec, names: &[String]) -> Result<(Vec<String>, Vec<Probe>)> {
    let mut sensor_cols = Vec::new();
    let mut sensor_probe = Vec::new();
    for s in &spec.sensors {
        let col = sensor_column(&s.name);
        if sensor_cols.contains(&col) {
            bail!("sensor `{}` defined twice", s.name);
        }
        sensor_cols.push(col);
        sensor_probe.push(if s.node == "ambient" {
            Probe::Ambient
        } else if s.node == "coolant" && spec.coolant.is_some() {
            if names.iter().any(|n| n == "coolant") {
                bail!("node name `coolant` is reserved when [coolant] is given");
            }
            Probe::Coolant
        } else {
            Probe::Node(find_node(names, &s.node, &format!("sensor {}", s.name))?)
        });
    }
    Ok((sensor_cols, sensor_probe))
}

/// A direction's terms: (node, α·L [µm/K]).
type Terms = Vec<(usize, f64)>;

/// Each direction's CSV column and terms (node, α·L [µm/K]); a `rod`
/// term is spread evenly over the rod's slices.
fn compile_directions(
    spec: &MachineSpec,
    names: &[String],
    rod_range: &std::ops::Range<usize>,
) -> Result<(Vec<String>, Vec<Terms>)> {
    let alpha_um = spec.alpha_per_k * 1e3; // µm per (mm·K)
    let mut dir_cols = Vec::new();
    let mut dir_terms = Vec::new();
    for d in &spec.directions {
        dir_cols.push(format!("d{}_um", d.name));
        let mut terms = Vec::new();
        for t in &d.terms {
            if t.node == "rod" {
                if rod_range.is_empty() {
                    bail!("direction {}: term `rod` but no [rod]", d.name);
                }
                let per = t.length_mm / rod_range.len() as f64;
                for i in rod_range.clone() {
                    terms.push((i, alpha_um * per));
                }
            } else {
                let node = find_node(names, &t.node, &format!("direction {}", d.name))?;
                terms.push((node, alpha_um * t.length_mm));
            }
        }
        dir_terms.push(terms);
    }
    Ok((dir_cols, dir_terms))
}

fn compile_circuit(c: &CoolantSpec, names: &[String]) -> Result<Circuit> {
    let mut jacket = Vec::new();
    for j in &c.jacket {
        let i = find_node(names, &j.node, "coolant.jacket")?;
        if jacket.iter().any(|(k, _)| *k == i) {
            bail!("coolant.jacket: node `{}` listed twice", j.node);
        }
        jacket.push((i, j.g_w_per_k));
    }
    Ok(Circuit {
        supply_c: c.supply_c,
        flows: c.flows,
        jacket,
        tank_c: c.tank_c_j_per_k,
        tank_g_amb: c.tank_g_amb_w_per_k,
    })
}

/// (node a, node b, direction index) of the bending site.
fn compile_bending(
    b: &BendingSite,
    directions: &[DirectionSpec],
    names: &[String],
) -> Result<(usize, usize, usize)> {
    let di = directions
        .iter()
        .position(|d| d.name == b.direction)
        .ok_or_else(|| anyhow!("effects.bending: unknown direction `{}`", b.direction))?;
    Ok((
        find_node(names, &b.a, "effects.bending.a")?,
        find_node(names, &b.b, "effects.bending.b")?,
        di,
    ))
}

impl Machine {
    pub fn load(path: &Path) -> Result<Machine> {
        let text = limits::read_toml_text(path, "machine file")?;
        Machine::from_toml(&text).with_context(|| format!("in machine file {}", path.display()))
    }

    /// Parse, check every value against its physical range (see
    /// [`MachineSpec::validate`]) and compile.
    pub fn from_toml(text: &str) -> Result<Machine> {
        let spec: MachineSpec = toml::from_str(text).map_err(|e| limits::toml_error(text, &e))?;
        spec.validate()?;
        tolerance::check(&spec)?;
        Machine::compile(spec)
    }

    pub fn to_toml(&self) -> Result<String> {
        Ok(toml::to_string(&self.spec)?)
    }

    pub fn compile(spec: MachineSpec) -> Result<Machine> {
        if spec.nodes.is_empty() {
            bail!("machine `{}` has no [[node]]", spec.name);
        }
        spec.check_sizes()?;
        let Network {
            names,
            c,
            g_amb,
            area,
            amb_offset,
            links,
            rod_range,
        } = compile_network(&spec)?;
        let n = names.len();
        let find = |r: &str, what: &str| find_node(&names, r, what);
        let motor_node = match &spec.motor_node {
            Some(m) => Some(find(m, "motor_node")?),
            None => None,
        };
        let bearing_nodes = spec
            .bearings
            .iter()
            .map(|b| find(&b.node, "bearing.node"))
            .collect::<Result<Vec<_>>>()?;
        let source_nodes = spec
            .sources
            .iter()
            .map(|s| find(&s.node, "source.node"))
            .collect::<Result<Vec<_>>>()?;
        let (sensor_cols, sensor_probe) = compile_sensors(&spec, &names)?;
        let (dir_cols, dir_terms) = compile_directions(&spec, &names, &rod_range)?;
        let coolant_nodes = spec
            .effects
            .coolant_nodes
            .iter()
            .map(|x| find(x, "effects.coolant_nodes"))
            .collect::<Result<Vec<_>>>()?;
        let ballscrew_nodes = spec
            .effects
            .ballscrew_nodes
            .iter()
            .map(|x| find(x, "effects.ballscrew_nodes"))
            .collect::<Result<Vec<_>>>()?;
        let bnl_nodes = if spec.effects.bearing_nodes.is_empty() {
            bearing_nodes.clone()
        } else {
            spec.effects
                .bearing_nodes
                .iter()
                .map(|x| find(x, "effects.bearing_nodes"))
                .collect::<Result<Vec<_>>>()?
        };
        let coolant = match &spec.coolant {
            Some(c) => Some(compile_circuit(c, &names)?),
            None => None,
        };
        let bending = match &spec.effects.bending {
            Some(b) => Some(compile_bending(b, &spec.directions, &names)?),
            None => None,
        };
        Ok(Machine {
            spec,
            names,
            n,
            c,
            g_amb,
            amb_offset,
            area,
            links,
            motor_node,
            bearing_nodes,
            bnl_nodes,
            source_nodes,
            coolant,
            sensor_cols,
            sensor_probe,
            dir_cols,
            dir_terms,
            coolant_nodes,
            ballscrew_nodes,
            bending,
        })
    }

    /// Whether the `[coolant]` circuit flows with these inputs.
    pub fn coolant_flows(&self, rpm: f64, coolant_on: f64) -> bool {
        match &self.coolant {
            Some(c) => match c.flows {
                Flow::Spindle => rpm.abs() > 0.0,
                Flow::CoolantOn => coolant_on > 0.5,
                Flow::Always => true,
            },
            None => false,
        }
    }

    /// Nominal heat of the feed-driven sources per node [W], added to `q`.
    pub fn heat_feed(&self, feed: f64, q: &mut [f64]) {
        if feed <= 0.0 {
            return;
        }
        for (s, &node) in self.spec.sources.iter().zip(&self.source_nodes) {
            if s.driver == Driver::Feed {
                q[node] += s.w_at_nmax * feed.powf(s.exponent);
            }
        }
    }

    /// Nominal spindle-driven heat input per node [W] at speed `n_rpm`
    /// (feed-driven sources: [`Machine::heat_feed`]).
    pub fn heat_nominal(&self, n_rpm: f64, q: &mut [f64]) {
        q.iter_mut().for_each(|v| *v = 0.0);
        let n = n_rpm.abs();
        if n <= 0.0 {
            return;
        }
        if let Some(m) = self.motor_node {
            q[m] += self.spec.motor_loss_frac * self.spec.rated_power_w * (n / self.spec.n_max_rpm);
        }
        for (b, &node) in self.spec.bearings.iter().zip(&self.bearing_nodes) {
            q[node] += b.heat_w(n);
        }
        for (s, &node) in self.spec.sources.iter().zip(&self.source_nodes) {
            if s.driver == Driver::Spindle {
                q[node] += s.w_at_nmax * (n / self.spec.n_max_rpm).powf(s.exponent);
            }
        }
    }
}

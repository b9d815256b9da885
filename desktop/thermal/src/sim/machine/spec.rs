//! What a machine file says: the TOML's tables as written, with their
//! defaults and the range checks of every value. `machine.rs` compiles
//! them into the network.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::sim::limits;

/// Linear expansion coefficient of steel [1/K].
pub const ALPHA_STEEL: f64 = 11.5e-6;

fn one() -> f64 {
    1.0
}
fn d_nmax() -> f64 {
    12000.0
}
fn d_k() -> f64 {
    45.0
}
fn d_rho() -> f64 {
    7850.0
}
fn d_cp() -> f64 {
    460.0
}
fn d_alpha() -> f64 {
    ALPHA_STEEL
}
fn d_qc() -> f64 {
    0.0625
}
fn d_nt() -> f64 {
    0.02
}
fn d_nd() -> f64 {
    0.2
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Gaussian noise on temperature readings before quantisation [°C].
    #[serde(default = "d_nt")]
    pub temp_c: f64,
    /// Quantisation step of temperature readings [°C] (DS18B20: 1/16).
    #[serde(default = "d_qc")]
    pub quant_c: f64,
    /// Gaussian noise on displacement readings [µm].
    #[serde(default = "d_nd")]
    pub disp_um: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Noise {
            temp_c: d_nt(),
            quant_c: d_qc(),
            disp_um: d_nd(),
        }
    }
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    pub name: String,
    /// Heat capacity [J/K].
    pub c_j_per_k: f64,
    /// Nominal conductance to ambient / foundation [W/K].
    #[serde(default)]
    pub g_amb_w_per_k: f64,
    /// Surface exposed to air [m²] (used only by the `convection` effect).
    #[serde(default)]
    pub area_m2: f64,
    /// Offset of this node's sink temperature relative to ambient [°C].
    #[serde(default)]
    pub amb_offset_c: f64,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    pub a: String,
    pub b: String,
    pub g_w_per_k: f64,
}

/// Rolling bearing with Palmgren friction torque.
#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct BearingSpec {
    pub node: String,
    /// Pitch diameter [mm].
    pub dm_mm: f64,
    /// Lubrication factor f0 (grease / oil-air, 1..4).
    pub f0: f64,
    /// Load factor f1 (angular contact ≈ 0.001·(P0/C0)^0.33).
    pub f1: f64,
    /// Equivalent load P [N].
    pub load_n: f64,
    /// Lubricant kinematic viscosity ν [mm²/s = cSt].
    pub nu_cst: f64,
}

impl BearingSpec {
    /// Friction torque [N·mm] (Palmgren): M = f1·P·dm + M0 with
    /// M0 = 1e-7·f0·(ν·n)^(2/3)·dm³ for ν·n ≥ 2000, else 160e-7·f0·dm³.
    pub fn torque_nmm(&self, n_rpm: f64) -> f64 {
        let n = n_rpm.abs();
        if n <= 0.0 {
            return 0.0;
        }
        let vn = self.nu_cst * n;
        let m0 = if vn >= 2000.0 {
            1e-7 * self.f0 * vn.powf(2.0 / 3.0) * self.dm_mm.powi(3)
        } else {
            160e-7 * self.f0 * self.dm_mm.powi(3)
        };
        self.f1 * self.load_n * self.dm_mm + m0
    }

    /// Heat [W]: Q = 1.047e-4 · n · M.
    pub fn heat_w(&self, n_rpm: f64) -> f64 {
        1.047e-4 * n_rpm.abs() * self.torque_nmm(n_rpm)
    }
}

/// What drives a generic heat source.
#[derive(Deserialize, Serialize, Clone, Copy, Debug, Default, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Driver {
    /// Q = w_at_nmax · (n / n_max)^exponent (spindle losses).
    #[default]
    Spindle,
    /// Q = w_at_nmax · feed_activity^exponent (ball-screw nut, axis drive).
    Feed,
}

/// Generic heat source Q = w_at_nmax · (drive)^exponent, the drive being
/// n / n_max (`driver = "spindle"`, the default) or `feed_activity`
/// (`driver = "feed"`); `w_at_nmax` is the heat at full drive.
#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    pub node: String,
    pub w_at_nmax: f64,
    #[serde(default = "one")]
    pub exponent: f64,
    #[serde(default)]
    pub driver: Driver,
}

/// When the coolant of a `[coolant]` circuit flows.
#[derive(Deserialize, Serialize, Clone, Copy, Debug, Default, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Flow {
    /// While the spindle turns (pump switched with the spindle).
    #[default]
    Spindle,
    /// While the run's `coolant_on` column is 1.
    CoolantOn,
    /// All the time.
    Always,
}

/// A coolant jacket: conductance from a node to the coolant while it flows.
#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct JacketSpec {
    pub node: String,
    pub g_w_per_k: f64,
}

/// A chiller-held coolant circuit: jackets exchange heat with coolant at
/// `supply_c` while it flows. The tank (capacity, loss to air) is used by
/// the `chiller` effect, which lets a thermostat cycle instead of holding.
/// A sensor with `node = "coolant"` reads the coolant.
#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct CoolantSpec {
    /// Chiller set point [°C] (absolute, not relative to ambient).
    pub supply_c: f64,
    #[serde(default)]
    pub flows: Flow,
    #[serde(default)]
    pub jacket: Vec<JacketSpec>,
    /// Heat capacity of the coolant in the tank [J/K].
    #[serde(default)]
    pub tank_c_j_per_k: f64,
    /// Tank loss to ambient air [W/K].
    #[serde(default)]
    pub tank_g_amb_w_per_k: f64,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct RodEnd {
    pub node: String,
    pub g_w_per_k: f64,
}

/// 1-D finite-difference spindle shaft: `segments` equal slices, slice 0 at
/// the front (tool side). Referenced as `rod:<i>` or `rod` (all slices).
#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct RodSpec {
    pub segments: usize,
    pub length_mm: f64,
    pub diameter_mm: f64,
    #[serde(default = "d_k")]
    pub k_w_per_mk: f64,
    #[serde(default = "d_rho")]
    pub rho_kg_m3: f64,
    #[serde(default = "d_cp")]
    pub cp_j_per_kgk: f64,
    /// Total nominal lateral conductance to ambient [W/K], shared by slices.
    #[serde(default)]
    pub g_amb_w_per_k: f64,
    pub front: Option<RodEnd>,
    pub rear: Option<RodEnd>,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// `T01` style names are used as the column name, others get `T_`.
    pub name: String,
    /// Node name, `rod:<i>`, or `ambient`.
    pub node: String,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct TermSpec {
    /// Node name, `rod:<i>` or `rod` (whole shaft).
    pub node: String,
    /// Effective length [mm]; sign gives the direction of growth.
    pub length_mm: f64,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct DirectionSpec {
    /// Column `d<name>_um`.
    pub name: String,
    pub terms: Vec<TermSpec>,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct BendingSite {
    pub a: String,
    pub b: String,
    pub direction: String,
}

/// Where the candidate effects act (the physics of the nominal model does
/// not use these).
#[derive(Deserialize, Serialize, Clone, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct EffectSites {
    #[serde(default)]
    pub coolant_nodes: Vec<String>,
    #[serde(default)]
    pub ballscrew_nodes: Vec<String>,
    /// Where `bearing_nonlinear` adds heat (default: the `[[bearing]]` nodes).
    #[serde(default)]
    pub bearing_nodes: Vec<String>,
    #[serde(default)]
    pub bending: Option<BendingSite>,
}

#[derive(Deserialize, Serialize, Clone, Debug)]
#[serde(deny_unknown_fields)]
pub struct MachineSpec {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Nominal ambient temperature [°C] (and the reference for expansion).
    pub ambient_c: f64,
    #[serde(default = "d_nmax")]
    pub n_max_rpm: f64,
    #[serde(default)]
    pub rated_power_w: f64,
    /// Motor loss at n_max as a fraction of rated power (loss ∝ speed).
    #[serde(default)]
    pub motor_loss_frac: f64,
    #[serde(default)]
    pub motor_node: Option<String>,
    #[serde(default = "d_alpha")]
    pub alpha_per_k: f64,
    #[serde(default)]
    pub noise: Noise,
    #[serde(rename = "node")]
    pub nodes: Vec<NodeSpec>,
    #[serde(rename = "link", default)]
    pub links: Vec<LinkSpec>,
    #[serde(rename = "bearing", default)]
    pub bearings: Vec<BearingSpec>,
    #[serde(rename = "source", default)]
    pub sources: Vec<SourceSpec>,
    #[serde(default)]
    pub rod: Option<RodSpec>,
    #[serde(rename = "sensor")]
    pub sensors: Vec<SensorSpec>,
    #[serde(rename = "direction", default)]
    pub directions: Vec<DirectionSpec>,
    #[serde(default)]
    pub coolant: Option<CoolantSpec>,
    #[serde(default)]
    pub effects: EffectSites,
    /// How far each design value may be off (`tolerance.rs`).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub tolerance: std::collections::BTreeMap<String, f64>,
}

impl MachineSpec {
    /// Sizes that set allocations (the dense network is n × n).
    pub(super) fn check_sizes(&self) -> Result<()> {
        let segments = self.rod.as_ref().map_or(0, |r| r.segments);
        if let Some(rod) = &self.rod {
            if !(2..=limits::MAX_ROD_SEGMENTS).contains(&rod.segments) {
                bail!(
                    "rod.segments = {}: allowed 2..={}",
                    rod.segments,
                    limits::MAX_ROD_SEGMENTS
                );
            }
        }
        limits::count(
            "network nodes ([[node]] and rod.segments)",
            self.nodes.len() + segments,
            limits::MAX_NODES,
        )?;
        limits::count("[[link]]", self.links.len(), limits::MAX_LINKS)?;
        limits::count("[[bearing]]", self.bearings.len(), limits::MAX_BEARINGS)?;
        limits::count("[[source]]", self.sources.len(), limits::MAX_SOURCES)?;
        limits::count("[[sensor]]", self.sensors.len(), limits::MAX_SENSORS)?;
        limits::count(
            "[[direction]]",
            self.directions.len(),
            limits::MAX_DIRECTIONS,
        )?;
        for d in &self.directions {
            limits::count(
                format_args!("terms in [[direction]] `{}`", d.name),
                d.terms.len(),
                limits::MAX_TERMS,
            )?;
        }
        limits::count(
            "effects.coolant_nodes",
            self.effects.coolant_nodes.len(),
            limits::MAX_NODES,
        )?;
        limits::count(
            "effects.ballscrew_nodes",
            self.effects.ballscrew_nodes.len(),
            limits::MAX_NODES,
        )?;
        limits::count(
            "effects.bearing_nodes",
            self.effects.bearing_nodes.len(),
            limits::MAX_NODES,
        )?;
        if let Some(c) = &self.coolant {
            limits::count("coolant.jacket", c.jacket.len(), limits::MAX_NODES)?;
        }
        Ok(())
    }

    /// Every number of a hand-written description must be finite, of the
    /// right sign and of a magnitude a machine tool can have; the bounds are
    /// generous (a 2000 t casting, a 1 MW spindle) and listed in
    /// `examples/machines/README.md`. Errors name the key and the range.
    pub fn validate(&self) -> Result<()> {
        use limits::{positive, within};
        let (t_lo, t_hi) = tcomp_data::runcsv::TEMPERATURE_RANGE_C;
        self.check_sizes()?;
        within("ambient_c", self.ambient_c, t_lo, t_hi, "°C")?;
        positive(
            "n_max_rpm",
            self.n_max_rpm,
            tcomp_data::runcsv::MAX_SPINDLE_RPM,
            "rpm",
        )?;
        within("rated_power_w", self.rated_power_w, 0.0, 1e6, "W")?;
        within("motor_loss_frac", self.motor_loss_frac, 0.0, 1.0, "")?;
        within("alpha_per_k", self.alpha_per_k, 0.0, 1e-4, "1/K")?;
        within("noise.temp_c", self.noise.temp_c, 0.0, 10.0, "°C")?;
        within("noise.quant_c", self.noise.quant_c, 0.0, 10.0, "°C")?;
        within("noise.disp_um", self.noise.disp_um, 0.0, 1e3, "µm")?;
        for n in &self.nodes {
            let key = |k: &str| format!("[[node]] `{}`: {k}", n.name);
            positive(key("c_j_per_k"), n.c_j_per_k, 1e9, "J/K")?;
            within(key("g_amb_w_per_k"), n.g_amb_w_per_k, 0.0, 1e6, "W/K")?;
            within(key("area_m2"), n.area_m2, 0.0, 1e4, "m²")?;
            within(key("amb_offset_c"), n.amb_offset_c, -100.0, 100.0, "°C")?;
        }
        for l in &self.links {
            let key = format!("[[link]] `{}`–`{}`: g_w_per_k", l.a, l.b);
            within(key, l.g_w_per_k, 0.0, 1e6, "W/K")?;
        }
        for b in &self.bearings {
            let key = |k: &str| format!("[[bearing]] on `{}`: {k}", b.node);
            positive(key("dm_mm"), b.dm_mm, 2_000.0, "mm")?;
            within(key("f0"), b.f0, 0.0, 10.0, "")?;
            within(key("f1"), b.f1, 0.0, 1.0, "")?;
            within(key("load_n"), b.load_n, 0.0, 1e7, "N")?;
            within(key("nu_cst"), b.nu_cst, 0.0, 1e5, "mm²/s")?;
        }
        for s in &self.sources {
            let key = |k: &str| format!("[[source]] on `{}`: {k}", s.node);
            within(key("w_at_nmax"), s.w_at_nmax, 0.0, 1e6, "W")?;
            within(key("exponent"), s.exponent, 0.0, 10.0, "")?;
        }
        if let Some(c) = &self.coolant {
            within("coolant.supply_c", c.supply_c, t_lo, t_hi, "°C")?;
            within("coolant.tank_c_j_per_k", c.tank_c_j_per_k, 0.0, 1e9, "J/K")?;
            within(
                "coolant.tank_g_amb_w_per_k",
                c.tank_g_amb_w_per_k,
                0.0,
                1e6,
                "W/K",
            )?;
            for j in &c.jacket {
                let key = format!("coolant.jacket `{}`: g_w_per_k", j.node);
                within(key, j.g_w_per_k, 0.0, 1e6, "W/K")?;
            }
        }
        if let Some(r) = &self.rod {
            positive("rod.length_mm", r.length_mm, 1e4, "mm")?;
            positive("rod.diameter_mm", r.diameter_mm, 2_000.0, "mm")?;
            positive("rod.k_w_per_mk", r.k_w_per_mk, 1_000.0, "W/(m·K)")?;
            positive("rod.rho_kg_m3", r.rho_kg_m3, 25_000.0, "kg/m³")?;
            positive("rod.cp_j_per_kgk", r.cp_j_per_kgk, 5_000.0, "J/(kg·K)")?;
            within("rod.g_amb_w_per_k", r.g_amb_w_per_k, 0.0, 1e6, "W/K")?;
            for (end, e) in [("rod.front", &r.front), ("rod.rear", &r.rear)] {
                if let Some(e) = e {
                    within(format!("{end}.g_w_per_k"), e.g_w_per_k, 0.0, 1e6, "W/K")?;
                }
            }
        }
        for d in &self.directions {
            for t in &d.terms {
                let key = format!("[[direction]] `{}`: length_mm of `{}`", d.name, t.node);
                within(key, t.length_mm, -1e5, 1e5, "mm")?;
            }
        }
        Ok(())
    }
}

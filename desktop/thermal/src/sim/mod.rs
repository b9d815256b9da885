//! Machine thermal simulator: a lumped thermal network (heat capacities,
//! conductances, motor loss and Palmgren bearing heat) with a 1-D
//! finite-difference spindle shaft, stepped with the exact zero-order-hold
//! discretisation in the network's modes (`modal.rs`: the same step as
//! `x ← Φx + Ψb`, stable for any step, in O(n)), thermal expansion
//! mapped to displacement per direction, DS18B20 quantisation and seeded
//! noise, and switchable candidate effects (`effects.rs`).

pub mod duty;
pub mod effects;
pub mod limits;
pub mod machine;
mod modal;

use anyhow::{bail, Result};
use tcomp_numerics::rng::Rng;

pub use duty::{Duty, Inputs};
pub use effects::{Effect, ALL_EFFECT_NAMES, EFFECT_NAMES};
pub use machine::{Machine, Probe};

use modal::Modes;
use nalgebra::{DMatrix, DVector};
use std::rc::Rc;
use tcomp_numerics::linalg::solve;

/// Noise-free simulator output at the output samples.
#[derive(Clone, Debug)]
pub struct SimOut {
    /// Per sensor (machine order), per sample [°C].
    pub temps: Vec<Vec<f64>>,
    /// Per direction (machine order), per sample [µm].
    pub disp: Vec<Vec<f64>>,
    /// Sample times [s].
    pub t: Vec<f64>,
}

/// Effects pre-digested for the stepping loop.
#[derive(Default)]
struct Active {
    h: f64,
    drift: Vec<(f64, f64, f64, f64)>,
    /// Lag per sensor [s] (0 = none).
    lag: Vec<f64>,
    /// (k, p, nodes)
    bnl: Vec<(f64, f64, Vec<usize>)>,
    cool: Option<(f64, f64, f64, f64)>,
    /// (band, power, load fraction) of a cycling chiller.
    chiller: Option<(f64, f64, f64)>,
    screw: f64,
    bend: f64,
    /// (sensor, offset, from time)
    offsets: Vec<(usize, f64, f64)>,
}

fn sensor_index(m: &Machine, sensor: &str, what: &str) -> Result<usize> {
    let col = machine::sensor_column(sensor);
    m.sensor_cols
        .iter()
        .position(|c| *c == col || c == sensor)
        .ok_or_else(|| anyhow::anyhow!("effect {what}: unknown sensor `{sensor}`"))
}

fn activate(m: &Machine, effects: &[Effect]) -> Result<Active> {
    let mut a = Active {
        lag: vec![0.0; m.sensor_cols.len()],
        ..Active::default()
    };
    for e in effects {
        e.validate()?;
        match e {
            Effect::Convection { h_w_per_m2k } => a.h += h_w_per_m2k,
            Effect::AmbientDrift {
                amp_c,
                phase_h,
                rate_c_per_h,
                period_h,
            } => a.drift.push((*amp_c, *phase_h, *rate_c_per_h, *period_h)),
            Effect::SensorLag { tau_s, sensor } => match sensor {
                Some(sn) => a.lag[sensor_index(m, sn, "sensor_lag")?] += tau_s,
                None => a.lag.iter_mut().for_each(|l| *l += tau_s),
            },
            Effect::Chiller {
                band_c,
                power_w,
                load_frac,
            } => {
                if !m.coolant.as_ref().is_some_and(|c| c.tank_c > 0.0) {
                    bail!(
                        "effect chiller: machine `{}` has no [coolant] circuit with tank_c_j_per_k > 0",
                        m.spec.name
                    );
                }
                a.chiller = Some((*band_c, *power_w, *load_frac));
            }
            Effect::BearingNonlinear { k_w, p, node } => {
                let at = match node {
                    Some(nn) => vec![m.names.iter().position(|x| x == nn).ok_or_else(|| {
                        anyhow::anyhow!("effect bearing_nonlinear: unknown node `{nn}`")
                    })?],
                    None => m.bnl_nodes.clone(),
                };
                a.bnl.push((*k_w, *p, at));
            }
            Effect::Coolant {
                g_w_per_k,
                offset_c,
                amp_c,
                period_s,
            } => {
                if m.coolant_nodes.is_empty() {
                    bail!(
                        "effect coolant: machine `{}` names no effects.coolant_nodes",
                        m.spec.name
                    );
                }
                a.cool = Some((*g_w_per_k, *offset_c, *amp_c, *period_s));
            }
            Effect::Ballscrew { k_w } => {
                if m.ballscrew_nodes.is_empty() {
                    bail!(
                        "effect ballscrew: machine `{}` names no effects.ballscrew_nodes",
                        m.spec.name
                    );
                }
                a.screw += k_w
            }
            Effect::Bending { k_um_per_k } => {
                if m.bending.is_none() {
                    bail!(
                        "effect bending: machine `{}` has no [effects.bending]",
                        m.spec.name
                    );
                }
                a.bend += k_um_per_k
            }
            Effect::SensorOffset {
                sensor,
                offset_c,
                at_s,
                ..
            } => {
                let i = sensor_index(m, sensor, "sensor_offset")?;
                a.offsets.push((i, *offset_c, *at_s));
            }
        }
    }
    Ok(a)
}

/// Ambient deviation of the drift terms at time `t` [s].
fn drift_at(d: &[(f64, f64, f64, f64)], t: f64) -> f64 {
    d.iter()
        .map(|&(amp, ph, rate, per)| {
            let w = 2.0 * std::f64::consts::PI / (per * 3600.0);
            let phi = 2.0 * std::f64::consts::PI * ph / per;
            amp * ((w * t + phi).sin() - phi.sin()) + rate * t / 3600.0
        })
        .sum()
}

/// Chiller sawtooth in [-amp/2, amp/2).
fn saw(t: f64, amp: f64, period: f64) -> f64 {
    amp * ((t / period).rem_euclid(1.0) - 0.5)
}

/// The conductance matrix `L + diag(g_amb)` (W/K) of the network.
fn conductance(m: &Machine, g_amb: &[f64]) -> DMatrix<f64> {
    let mut l = DMatrix::from_diagonal(&DVector::from_column_slice(&g_amb[..m.n]));
    for &(i, j, g) in &m.links {
        l[(i, i)] += g;
        l[(j, j)] += g;
        l[(i, j)] -= g;
        l[(j, i)] -= g;
    }
    l
}

/// Steady state of the network for heat `q` [W] and ambient `ta`
/// (coolant off): solves `(L + diag g) T = q + g (ta + offset)`.
pub fn steady_state(m: &Machine, q: &[f64], ta: f64, effects: &[Effect]) -> Result<Vec<f64>> {
    let act = activate(m, effects)?;
    let g_amb: Vec<f64> = (0..m.n).map(|i| m.g_amb[i] + act.h * m.area[i]).collect();
    let rhs: Vec<f64> = (0..m.n)
        .map(|i| q[i] + g_amb[i] * (ta + m.amb_offset[i]))
        .collect();
    solve(conductance(m, &g_amb), &rhs)
        .map_err(|e| anyhow::anyhow!("thermal network: {e} (a node without a path to ambient?)"))
}

/// Simulate without noise. Output every `stride`-th step, starting at row 0.
/// The machine starts in equilibrium with the first ambient at rest.
pub fn simulate(m: &Machine, inp: &Inputs, effects: &[Effect], stride: usize) -> Result<SimOut> {
    let stride = stride.max(1);
    let act = activate(m, effects)?;
    let dt = inp.dt;
    let net = Network::new(m, &act, dt)?;
    let ta0 = inp.ambient.first().copied().unwrap_or(m.spec.ambient_c);
    let mut state = State::new(m, &net.read, net.rest_state(ta0)?, net.supply);
    let k_total = inp.len();
    let mut rec = Recorder::new(m, act.bend, state.x.clone(), k_total.div_ceil(stride));
    for k in 0..k_total {
        let t = inp.time(k);
        if k % stride == 0 {
            let amb_now = inp.ambient[k] + drift_at(&act.drift, t);
            rec.record(t, amb_now, &state.x, &state.lin, state.t_cool);
        }
        if k + 1 == k_total {
            break;
        }
        net.step(inp, k, t, &mut state);
    }
    let mut out = rec.out;
    sensor_post(&act, &mut out, dt * stride as f64);
    Ok(out)
}

/// The network under the active effects: its conductances to ambient and
/// to the coolant, and its modes for every combination of coolant flows.
struct Network<'a> {
    m: &'a Machine,
    act: &'a Active,
    g_amb: Vec<f64>,
    /// Conductance to the coolant per node while the circuit flows (its jackets).
    g_jacket: Vec<f64>,
    /// Modes indexed by `flowing | cool_on << 1` (None: a state that cannot occur).
    modes: [Option<Rc<Modes>>; 4],
    /// The nodes whose temperature something reads: sensors, bending,
    /// coolant jackets (the directions read their lever-weighted sums).
    read: Vec<usize>,
    /// Coolant set point (0 without a circuit).
    supply: f64,
    n_screw: f64,
    feed_sources: bool,
}

/// What changes from step to step: the node temperatures (valid at the
/// read nodes), the modal state, the coolant tank and the scratch vectors
/// of the stepping loop.
struct State {
    x: DVector<f64>,
    /// Modal coordinates in the modes of `key`, which is None before the
    /// first step.
    z: Vec<f64>,
    key: Option<usize>,
    /// Heat per node that changes only with speed and feed [W], and its
    /// modal increment (`w_slow`) in the current modes.
    f_slow: Vec<f64>,
    w_slow: Vec<f64>,
    /// Whether `w_slow` must be mapped again.
    slow_dirty: bool,
    /// The step's modal increment, the outputs (scratch).
    w: Vec<f64>,
    outs: Vec<f64>,
    /// Per direction: Σ lever × temperature over its terms.
    lin: Vec<f64>,
    /// Spindle heat per node [W] at `last_rpm`.
    q: Vec<f64>,
    last_rpm: f64,
    last_feed: f64,
    /// Coolant temperature (the set point unless the chiller cycles).
    t_cool: f64,
    chiller_on: bool,
}

impl State {
    fn new(m: &Machine, read: &[usize], x: DVector<f64>, supply: f64) -> State {
        let n = x.len();
        State {
            outs: vec![0.0; read.len() + m.dir_terms.len()],
            lin: lever_sums(m, &x),
            z: vec![0.0; n],
            key: None,
            f_slow: vec![0.0; n],
            w_slow: vec![0.0; n],
            slow_dirty: true,
            w: vec![0.0; n],
            q: vec![0.0; n],
            x,
            last_rpm: f64::NAN,
            last_feed: f64::NAN,
            t_cool: supply,
            chiller_on: false,
        }
    }
}

impl<'a> Network<'a> {
    fn new(m: &'a Machine, act: &'a Active, dt: f64) -> Result<Network<'a>> {
        let n = m.n;
        let g_amb: Vec<f64> = (0..n).map(|i| m.g_amb[i] + act.h * m.area[i]).collect();
        // conductance to the coolant per node: the circuit's jackets while it
        // flows, the `coolant` effect while it is on; modes per combination
        let mut g_jacket = vec![0.0; n];
        if let Some(c) = &m.coolant {
            for &(i, g) in &c.jacket {
                g_jacket[i] += g;
            }
        }
        let mut g_cool = vec![0.0; n];
        if let Some((g, ..)) = act.cool {
            for &i in &m.coolant_nodes {
                g_cool[i] += g / m.coolant_nodes.len() as f64;
            }
        }
        let mut read: Vec<usize> = m
            .sensor_probe
            .iter()
            .filter_map(|p| match p {
                Probe::Node(i) => Some(*i),
                _ => None,
            })
            .chain(m.bending.iter().flat_map(|&(a, b, _)| [a, b]))
            .chain(
                m.coolant
                    .iter()
                    .flat_map(|c| c.jacket.iter().map(|&(i, _)| i)),
            )
            .collect();
        read.sort_unstable();
        read.dedup();
        let base = conductance(m, &g_amb);
        let mut modes: [Option<Rc<Modes>>; 4] = Default::default();
        for (key, slot) in modes.iter_mut().enumerate() {
            let (jacket, cool) = (key & 1 != 0, key & 2 != 0);
            if (jacket && m.coolant.is_none()) || (cool && act.cool.is_none()) {
                continue;
            }
            let mut k = base.clone();
            for i in 0..n {
                k[(i, i)] +=
                    (if jacket { g_jacket[i] } else { 0.0 }) + if cool { g_cool[i] } else { 0.0 };
            }
            *slot = Some(modal::cached(&modal::Spec {
                k: &k,
                c: &m.c,
                dt,
                g_amb: &g_amb,
                g_jacket: &g_jacket,
                g_cool: &g_cool,
                read: &read,
                dirs: &m.dir_terms,
            })?);
        }
        Ok(Network {
            m,
            act,
            g_amb,
            g_jacket,
            modes,
            read,
            supply: m.coolant.as_ref().map_or(0.0, |c| c.supply_c),
            n_screw: m.ballscrew_nodes.len().max(1) as f64,
            feed_sources: m
                .spec
                .sources
                .iter()
                .any(|s| s.driver == machine::Driver::Feed),
        })
    }

    /// Equilibrium at rest with ambient `ta0` (a circuit that flows
    /// `always` holds its jackets towards the supply).
    fn rest_state(&self, ta0: f64) -> Result<DVector<f64>> {
        let m = self.m;
        let (g_amb, g_jacket, supply) = (&self.g_amb, &self.g_jacket, self.supply);
        let at_rest = m
            .coolant
            .as_ref()
            .is_some_and(|c| c.flows == machine::Flow::Always);
        let g_rest: Vec<f64> = (0..m.n)
            .map(|i| g_amb[i] + if at_rest { g_jacket[i] } else { 0.0 })
            .collect();
        let rhs: Vec<f64> = (0..m.n)
            .map(|i| {
                g_amb[i] * (ta0 + m.amb_offset[i])
                    + if at_rest { g_jacket[i] * supply } else { 0.0 }
            })
            .collect();
        Ok(DVector::from_vec(
            solve(conductance(m, &g_rest), &rhs)
                .map_err(|e| anyhow::anyhow!("thermal network: {e}"))?,
        ))
    }

    /// Spindle heat per node [W] at speed `rpm`: the nominal sources and
    /// the `bearing_nonlinear` extra.
    fn spindle_heat(&self, rpm: f64, q: &mut [f64]) {
        self.m.heat_nominal(rpm, q);
        if rpm > 0.0 {
            let n_max = self.m.spec.n_max_rpm;
            for (kw, p, at) in &self.act.bnl {
                let extra = kw * (rpm / n_max).powf(*p);
                for &bn in at {
                    q[bn] += extra;
                }
            }
        }
    }

    /// One step from row `k` (time `t`) to the next.
    fn step(&self, inp: &Inputs, k: usize, t: f64, s: &mut State) {
        let dt = inp.dt;
        let tm = t + 0.5 * dt;
        let rpm = inp.rpm[k];
        if rpm != s.last_rpm {
            self.spindle_heat(rpm, &mut s.q);
            s.last_rpm = rpm;
            s.slow_dirty = true;
        }
        if inp.feed[k] != s.last_feed {
            s.last_feed = inp.feed[k];
            s.slow_dirty = true;
        }
        let ta = inp.ambient[k] + drift_at(&self.act.drift, tm);
        let (flowing, cool_on, tc) = self.coolant_state(inp, k, tm, ta);
        let key = usize::from(flowing) | (usize::from(cool_on) << 1);
        // a state the network was not built for cannot occur (`coolant_state`
        // turns each flow on only where its modes exist): keep the base
        let key = if self.modes[key].is_some() { key } else { 0 };
        let Some(modes) = self.modes[key].as_deref() else {
            return;
        };
        match s.key {
            None => s.z = modes.to_modes(s.x.as_slice(), &self.m.c),
            Some(old) if old != key => {
                if let Some(from) = self.modes[old].as_deref() {
                    s.z = from.in_other(modes, &s.z);
                }
                s.slow_dirty = true;
            }
            _ => {}
        }
        s.key = Some(key);
        if s.slow_dirty {
            self.slow_heat(inp, k, s);
            modes.heat(&s.f_slow, &mut s.w_slow);
            s.slow_dirty = false;
        }
        // the jackets see the tank as it was at the step's start
        let t_jacket = if flowing { s.t_cool } else { 0.0 };
        let tc = if cool_on { tc } else { 0.0 };
        for (i, w) in s.w.iter_mut().enumerate() {
            *w = s.w_slow[i]
                + ta * modes.per_ambient[i]
                + t_jacket * modes.per_jacket[i]
                + tc * modes.per_cool[i];
        }
        self.chiller_step(s, ta, flowing, dt);
        modes.step(&mut s.z, &s.w);
        modes.outputs(&s.z, &mut s.outs);
        let (temps, lin) = s.outs.split_at(self.read.len());
        for (&i, &v) in self.read.iter().zip(temps) {
            s.x[i] = v;
        }
        s.lin.copy_from_slice(lin);
    }

    /// The heat [W] per node of row `k` that changes only with the speed
    /// and the feed: the spindle's, the ambient offsets', the feed's and
    /// the ballscrew effect's.
    fn slow_heat(&self, inp: &Inputs, k: usize, s: &mut State) {
        let m = self.m;
        for i in 0..m.n {
            s.f_slow[i] = s.q[i] + self.g_amb[i] * m.amb_offset[i];
        }
        if self.feed_sources && inp.feed[k] > 0.0 {
            m.heat_feed(inp.feed[k], &mut s.f_slow);
        }
        if self.act.screw != 0.0 && inp.feed[k] != 0.0 {
            for &i in &m.ballscrew_nodes {
                s.f_slow[i] += self.act.screw * inp.feed[k] / self.n_screw;
            }
        }
    }

    /// Whether the circuit flows in row `k` (mid-step time `tm`, ambient
    /// `ta`), whether the `coolant` effect is on, and its supply [°C].
    fn coolant_state(&self, inp: &Inputs, k: usize, tm: f64, ta: f64) -> (bool, bool, f64) {
        let m = self.m;
        let flowing = m.coolant_flows(inp.rpm[k], inp.coolant[k]);
        match self.act.cool {
            Some((_, off, amp, per)) => {
                let on = if m.coolant.is_some() {
                    flowing
                } else {
                    inp.coolant[k] > 0.5
                };
                (flowing, on, ta + off + saw(tm, amp, per))
            }
            None => (flowing, false, 0.0),
        }
    }

    /// The tank under a cycling chiller over one step of `dt` (its time
    /// constant is hours: the jackets' heat is taken at the step's start;
    /// the thermostat switches at the exact crossing of its band within
    /// the step). Nothing without a chiller.
    fn chiller_step(&self, s: &mut State, ta: f64, flowing: bool, dt: f64) {
        let (Some((band, power, load)), Some(c)) = (self.act.chiller, self.m.coolant.as_ref())
        else {
            return;
        };
        let mut g_in = 0.0;
        let mut q_in = c.tank_g_amb * ta + load * power;
        if flowing {
            for &(i, g) in &c.jacket {
                g_in += g;
                q_in += g * s.x[i];
            }
        }
        let g_tot = c.tank_g_amb + g_in;
        let (lo, hi) = (self.supply - band / 2.0, self.supply + band / 2.0);
        let mut rem = dt;
        for _ in 0..3 {
            let slope =
                (q_in - g_tot * s.t_cool - if s.chiller_on { power } else { 0.0 }) / c.tank_c;
            let end = s.t_cool + slope * rem;
            if s.chiller_on && slope < 0.0 && end < lo {
                rem -= (lo - s.t_cool) / slope;
                s.t_cool = lo;
                s.chiller_on = false;
            } else if !s.chiller_on && slope > 0.0 && end > hi {
                rem -= (hi - s.t_cool) / slope;
                s.t_cool = hi;
                s.chiller_on = true;
            } else {
                s.t_cool = end;
                break;
            }
        }
    }
}

/// The output samples of a simulation as they are taken.
struct Recorder<'a> {
    m: &'a Machine,
    /// Gain of the `bending` effect.
    bend: f64,
    /// Node temperatures at the start and each direction's lever sum of
    /// them: displacements are rises from them.
    x0: DVector<f64>,
    lin0: Vec<f64>,
    out: SimOut,
}

impl<'a> Recorder<'a> {
    fn new(m: &'a Machine, bend: f64, x0: DVector<f64>, n_out: usize) -> Recorder<'a> {
        Recorder {
            m,
            bend,
            lin0: lever_sums(m, &x0),
            x0,
            out: SimOut {
                // (not `vec![Vec::with_capacity(..); k]`: its clones start empty
                // and grew by reallocation, row by row)
                temps: (0..m.sensor_cols.len())
                    .map(|_| Vec::with_capacity(n_out))
                    .collect(),
                disp: (0..m.dir_cols.len())
                    .map(|_| Vec::with_capacity(n_out))
                    .collect(),
                t: Vec::with_capacity(n_out),
            },
        }
    }

    /// Sensor readings and displacements at time `t` for node temperatures
    /// `x` (read at the sensors' and bending's nodes) and the directions'
    /// lever sums `lin`.
    fn record(&mut self, t: f64, amb_now: f64, x: &DVector<f64>, lin: &[f64], t_cool: f64) {
        let (m, x0) = (self.m, &self.x0);
        self.out.t.push(t);
        for (s, probe) in m.sensor_probe.iter().enumerate() {
            self.out.temps[s].push(match probe {
                Probe::Node(i) => x[*i],
                Probe::Ambient => amb_now,
                Probe::Coolant => t_cool,
            });
        }
        for d in 0..m.dir_terms.len() {
            let mut v = lin[d] - self.lin0[d];
            if let Some((a, bn, di)) = m.bending {
                if di == d {
                    v += self.bend * ((x[a] - x0[a]) - (x[bn] - x0[bn]));
                }
            }
            self.out.disp[d].push(v);
        }
    }
}

/// Per direction: Σ lever × temperature over its terms, for node
/// temperatures `x`.
fn lever_sums(m: &Machine, x: &DVector<f64>) -> Vec<f64> {
    m.dir_terms
        .iter()
        .map(|terms| terms.iter().map(|&(i, al)| al * x[i]).sum())
        .collect()
}

/// Sensor lag (first-order, exact for a signal linear between samples)
/// and offsets, on output sampled every `h` seconds.
fn sensor_post(act: &Active, out: &mut SimOut, h: f64) {
    for (s, &tau) in out.temps.iter_mut().zip(&act.lag) {
        if tau > 0.0 && !s.is_empty() {
            let e = (-h / tau).exp();
            let c = 1.0 - tau / h * (1.0 - e);
            let mut y = s[0];
            let mut xp = s[0];
            for v in s.iter_mut() {
                let xn = *v;
                y = e * y + (1.0 - e) * xp + (xn - xp) * c;
                xp = xn;
                *v = y;
            }
        }
    }
    for &(i, off, from) in &act.offsets {
        for (v, t) in out.temps[i].iter_mut().zip(&out.t) {
            if *t >= from {
                *v += off;
            }
        }
    }
}

/// Apply the sensor effects among `effects` (`sensor_lag`,
/// `sensor_offset`) to an output without them, sampled every `h` seconds:
/// the same as simulating with them, without re-simulating the network.
pub fn apply_sensor_effects(
    m: &Machine,
    effects: &[Effect],
    out: &mut SimOut,
    h: f64,
) -> Result<()> {
    let sensor: Vec<Effect> = effects
        .iter()
        .filter(|e| e.is_sensor_only())
        .cloned()
        .collect();
    let act = activate(m, &sensor)?;
    sensor_post(&act, out, h);
    Ok(())
}

/// Round to the DS18B20 step (1/16 °C by default).
pub fn quantize(v: f64, step: f64) -> f64 {
    if step > 0.0 {
        (v / step).round() * step
    } else {
        v
    }
}

/// Add the machine's sensor noise and quantisation (deterministic for `seed`).
pub fn add_noise(m: &Machine, out: &mut SimOut, seed: u64) {
    let mut g = Rng::paired(seed);
    let nz = &m.spec.noise;
    for s in out.temps.iter_mut() {
        for v in s.iter_mut() {
            *v = quantize(*v + nz.temp_c * g.normal(), nz.quant_c);
        }
    }
    for d in out.disp.iter_mut() {
        for v in d.iter_mut() {
            *v = ((*v + nz.disp_um * g.normal()) * 1e4).round() / 1e4;
        }
    }
}

/// Build a run file from inputs and output (output sampled every `stride`).
pub fn to_run(
    m: &Machine,
    inp: &Inputs,
    out: &SimOut,
    stride: usize,
    meta: &[(&str, String)],
) -> Result<tcomp_data::runcsv::Run> {
    let stride = stride.max(1);
    let mut run = tcomp_data::runcsv::Run {
        meta: Vec::new(),
        columns: Vec::new(),
        data: Vec::new(),
    };
    run.set_meta("machine", &m.spec.name);
    run.set_meta("source", "simulated");
    run.set_meta("sample_period_s", &format!("{}", inp.dt * stride as f64));
    for (k, v) in meta {
        run.set_meta(k, v);
    }
    let pick =
        |v: &[f64]| -> Vec<Option<f64>> { v.iter().step_by(stride).map(|x| Some(*x)).collect() };
    run.push_column("time_s", out.t.iter().map(|t| Some(*t)).collect())?;
    run.push_column("spindle_rpm", pick(&inp.rpm))?;
    run.push_column("feed_activity", pick(&inp.feed))?;
    run.push_column("coolant_on", pick(&inp.coolant))?;
    for (c, v) in m.sensor_cols.iter().zip(&out.temps) {
        run.push_column(c, v.iter().map(|x| Some(*x)).collect())?;
    }
    for (c, v) in m.dir_cols.iter().zip(&out.disp) {
        run.push_column(c, v.iter().map(|x| Some(*x)).collect())?;
    }
    Ok(run)
}

/// Options of `tcomp sim`.
pub struct SimOptions {
    pub effects: Vec<Effect>,
    pub seed: u64,
    pub hours: Option<f64>,
    /// Output sample period [s] (a multiple of the 1 s step).
    pub sample_period_s: Option<f64>,
    pub noise: bool,
}

/// Simulate a machine under a duty cycle into a run file (what `tcomp sim` does).
pub fn sim_run(m: &Machine, duty: &Duty, opt: &SimOptions) -> Result<tcomp_data::runcsv::Run> {
    let dt = 1.0;
    if let Some(p) = opt.sample_period_s {
        limits::within("--sample-period", p, 1.0, limits::MAX_SAMPLE_PERIOD_S, "s")?;
    }
    if let Some(h) = opt.hours {
        limits::positive("--hours", h, limits::MAX_SIM_HOURS, "h")?;
    }
    let duration_s = opt
        .hours
        .map_or(duty.end_s - duty.t.first().copied().unwrap_or(0.0), |h| {
            h * 3600.0
        });
    if !(duration_s <= limits::MAX_SIM_HOURS * 3600.0) {
        bail!(
            "duty `{}` lasts {:.1} h: at most {} h (give --hours)",
            duty.name,
            duration_s / 3600.0,
            limits::MAX_SIM_HOURS
        );
    }
    // A period taken from a duty CSV's sampling (not asked for) is only raised to the step.
    let period = opt
        .sample_period_s
        .or(duty.sample_period_s)
        .unwrap_or(1.0)
        .clamp(1.0, limits::MAX_SAMPLE_PERIOD_S);
    let stride = (period / dt).round().max(1.0) as usize;
    if ((stride as f64) * dt - period).abs() > 1e-9 {
        bail!("sample period {period} s is not a multiple of the 1 s step");
    }
    let rows = (duration_s / dt).ceil() as usize / stride;
    if rows > limits::MAX_SIM_ROWS {
        bail!(
            "{rows} output rows at {period} s: at most {} (raise --sample-period or lower --hours)",
            limits::MAX_SIM_ROWS
        );
    }
    let inp = duty.inputs(dt, opt.hours.map(|h| h * 3600.0), m.spec.ambient_c);
    let mut out = simulate(m, &inp, &opt.effects, stride)?;
    if opt.noise {
        add_noise(m, &mut out, opt.seed);
    }
    let eff = if opt.effects.is_empty() {
        "none".to_string()
    } else {
        opt.effects
            .iter()
            .map(|e| e.to_spec())
            .collect::<Vec<_>>()
            .join(" ")
    };
    to_run(
        m,
        &inp,
        &out,
        stride,
        &[
            (
                "run",
                format!("{}-{}-seed{}", m.spec.name, duty.name, opt.seed),
            ),
            ("duty", duty.name.clone()),
            ("seed", opt.seed.to_string()),
            ("effects", eff),
            ("ambient", format!("{} °C nominal", m.spec.ambient_c)),
        ],
    )
}

//! A design file as a user writes it from drawings (issue 27): every design
//! number of a machine file multiplied by its own lognormal factor, drawn
//! from a seed so each benchmark case's file is reproducible.

use anyhow::Result;
use tcomp_numerics::rng::Rng;
use tcomp_thermal::sim::machine::MachineSpec;
use tcomp_thermal::sim::Machine;

/// Spread of the design error: σ of the natural log of each factor (a
/// factor of e^{±0.15} ≈ ×0.86…×1.16 at one σ), the "σ = 15 %".
pub const DESIGN_SIGMA: f64 = 0.15;

/// Calls `f(key, value)` on every design number of `spec`: node capacities,
/// losses and surface areas, link conductances, the motor loss fraction,
/// bearing friction factors (f0, f1: the heat gain of each term), source
/// heat gains, the rod's conductivity, specific heat, loss and end
/// conductances, the coolant jackets and tank, and every displacement
/// length. Zero values (a part the design leaves out) are skipped, and so
/// are what a drawing states exactly or is not a scale: temperatures
/// (ambient, supply, offsets), speeds, exponents, geometry the losses are
/// stated per (bearing diameter, load, viscosity, rod size and density, α)
/// and the sensor noise.
pub fn visit_design_numbers(spec: &mut MachineSpec, f: &mut dyn FnMut(&str, &mut f64)) {
    let mut v = |key: String, x: &mut f64| {
        if *x != 0.0 {
            f(&key, x);
        }
    };
    v("motor_loss_frac".into(), &mut spec.motor_loss_frac);
    for n in &mut spec.nodes {
        v(format!("node {} c_j_per_k", n.name), &mut n.c_j_per_k);
        v(
            format!("node {} g_amb_w_per_k", n.name),
            &mut n.g_amb_w_per_k,
        );
        v(format!("node {} area_m2", n.name), &mut n.area_m2);
    }
    for l in &mut spec.links {
        v(format!("link {}-{} g_w_per_k", l.a, l.b), &mut l.g_w_per_k);
    }
    for b in &mut spec.bearings {
        v(format!("bearing {} f0", b.node), &mut b.f0);
        v(format!("bearing {} f1", b.node), &mut b.f1);
    }
    for (i, s) in spec.sources.iter_mut().enumerate() {
        v(format!("source {i} {} w_at_nmax", s.node), &mut s.w_at_nmax);
    }
    if let Some(r) = &mut spec.rod {
        v("rod k_w_per_mk".into(), &mut r.k_w_per_mk);
        v("rod cp_j_per_kgk".into(), &mut r.cp_j_per_kgk);
        v("rod g_amb_w_per_k".into(), &mut r.g_amb_w_per_k);
        if let Some(e) = &mut r.front {
            v("rod front g_w_per_k".into(), &mut e.g_w_per_k);
        }
        if let Some(e) = &mut r.rear {
            v("rod rear g_w_per_k".into(), &mut e.g_w_per_k);
        }
    }
    if let Some(c) = &mut spec.coolant {
        v("coolant tank_c_j_per_k".into(), &mut c.tank_c_j_per_k);
        v(
            "coolant tank_g_amb_w_per_k".into(),
            &mut c.tank_g_amb_w_per_k,
        );
        for j in &mut c.jacket {
            v(
                format!("coolant jacket {} g_w_per_k", j.node),
                &mut j.g_w_per_k,
            );
        }
    }
    for d in &mut spec.directions {
        for (i, t) in d.terms.iter_mut().enumerate() {
            v(
                format!("direction {} term {i} {} length_mm", d.name, t.node),
                &mut t.length_mm,
            );
        }
    }
}

/// The design numbers of `spec` as (key, value), in visiting order.
pub fn design_numbers(spec: &MachineSpec) -> Vec<(String, f64)> {
    let mut s = spec.clone();
    let mut out = Vec::new();
    visit_design_numbers(&mut s, &mut |k, x| out.push((k.to_string(), *x)));
    out
}

/// `spec` with every design number multiplied by exp(σ·z), z standard
/// normal from `Rng::new(seed)` in visiting order; with the factors drawn
/// (key, factor). The motor loss fraction stays ≤ 1.
pub fn perturb_spec(
    spec: &MachineSpec,
    sigma: f64,
    seed: u64,
) -> (MachineSpec, Vec<(String, f64)>) {
    let mut g = Rng::new(seed);
    let mut s = spec.clone();
    let mut factors = Vec::new();
    visit_design_numbers(&mut s, &mut |k, x| {
        let f = (sigma * g.normal()).exp();
        *x *= f;
        factors.push((k.to_string(), f));
    });
    s.motor_loss_frac = s.motor_loss_frac.min(1.0);
    (s, factors)
}

/// A machine compiled from `perturb_spec` of `m`'s design (checked as a
/// hand-written file is), with the factors drawn (key, factor): the
/// scorer judges parameter findings against them (`file_truth.rs`).
pub fn perturb_machine(
    m: &Machine,
    sigma: f64,
    seed: u64,
) -> Result<(Machine, Vec<(String, f64)>)> {
    let (spec, factors) = perturb_spec(&m.spec, sigma, seed);
    spec.validate()?;
    Ok((Machine::compile(spec)?, factors))
}

/// The seed of case `case` of world `world` (0 open, 1 cross) under the
/// benchmark seed `seed`: every case its own file, the same on every run.
pub fn design_seed(seed: u64, world: u64, case: usize) -> u64 {
    seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (world << 40) ^ (case as u64 + 0xd5)
}

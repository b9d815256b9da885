//! The simulated five-axis machines the rotary order tests share
//! (`rotary_orders.rs`, `rotary_orders_posterior.rs`).

use tcomp_geometry::rotary::sim::{
    axis_of, random_rotary, simulate, CycleSetup, RPlan, RotarySizes,
};
use tcomp_geometry::rotary::{Axis5, RotaryModel};
use tcomp_geometry::rtest::RTestFile;
use tcomp_numerics::rng::Rng;

pub const NOISE_UM: f64 = 0.5;

/// A machine with harmonics 1 and 2 on both axes (the simulator's sizes),
/// plus a third harmonic on the axes in `third` with coefficients up to
/// ±`um` µm on the translations and ±`urad` µrad on the rotations; its
/// default-plan R-test files at σ 0.5 µm.
pub fn machine(seed: u64, third: &[Axis5], um: f64, urad: f64) -> (RotaryModel, Vec<RTestFile>) {
    let mut rng = Rng::new(seed);
    let plan = RPlan::default_plan();
    let sizes = RotarySizes {
        order_c: 2,
        order_a: 2,
        ..Default::default()
    };
    let mut truth = random_rotary(&plan, &sizes, false, &mut rng);
    for (name, f) in truth.components.iter_mut() {
        if !third.contains(&axis_of(name)) {
            continue;
        }
        let size = if ["EXC", "EYC", "EZC", "EXA", "EYA", "EZA"].contains(&name.as_str()) {
            um
        } else {
            urad
        };
        f.cos.push(rng.range(-size, size));
        f.sin.push(rng.range(-size, size));
    }
    let setup = CycleSetup {
        noise_um: NOISE_UM,
        ..Default::default()
    };
    let files = simulate(&truth, None, &plan, &setup, &mut rng).unwrap();
    (truth, files)
}

//! The `bench` mode: instruction counts (QEMU `-icount shift=0`) of the
//! calibration loop, the math core's evaluation and one compensator step,
//! printed as one JSON line.

use core::fmt::Write as _;
use thermocomp_core::limits::{MAX_AXES, MAX_SENSORS};
use thermocomp_core::{Compensator, Model, StepInput};

use crate::host_files::{golden, load_model};
use crate::{cycles, exit_code, log};

#[embassy_executor::task]
pub async fn bench(golden_path: Option<&'static str>, model_path: Option<&'static str>) {
    const RUNS: u32 = 2000;
    let known = cycles::instructions_x100(RUNS, cycles::known_loop);
    let mut line: heapless::String<600> = heapless::String::new();
    let _ = write!(
        line,
        "{{\"method\":\"qemu -icount shift=0, SysTick at 25 MHz = 40 insn/count, {} runs\",\"known_loop_3000_insn_x100\":{}",
        RUNS, known
    );
    if let Some(model) = golden_path
        .and_then(golden::load)
        .and_then(thermocomp_core::golden::image)
        .and_then(|b| Model::parse(b).ok())
    {
        // The seed's configuration (one 5-11-1 network and one position-
        // dependent table), the network alone, then the whole demo model.
        let mut seed_config = model.clone();
        seed_config.nets.truncate(1);
        seed_config.tables.truncate(1);
        let mut net_only = seed_config.clone();
        net_only.tables.clear();
        let (net, _, norm, _) = bench_model(net_only);
        let (seed, _, _, seed_corrections) = bench_model(seed_config);
        let (eval, step, _, _) = bench_model(model);
        let _ = write!(
            line,
            ",\"normalise_5_inputs_1_axis_insn_x100\":{},\"net_5_11_1_insn_x100\":{},\"net_plus_table_insn_x100\":{},\"net_plus_table_corrections_only_insn_x100\":{},\"demo_evaluate_insn_x100\":{},\"demo_step_insn_x100\":{},\"compensator_ram_bytes\":{},\"model_ram_bytes\":{}",
            norm, net, seed, seed_corrections, eval, step, core::mem::size_of::<Compensator>(), core::mem::size_of::<Model>()
        );
    }
    // A fitted model exported by tcomp (e.g. the FL_THERMAL demo model).
    if let Some(model) = model_path.and_then(load_model) {
        // Its volumetric section (issue 14), if it has one.
        let vol = model
            .volumetric
            .as_ref()
            .map(|v| (bench_volumetric(v), v.terms.len(), v.sensors.len()));
        // And its five-axis section (issue 31): the whole evaluation, kind 3 + kind 4.
        let five = model
            .volumetric
            .as_ref()
            .zip(model.five_axis.as_ref())
            .map(|(v, f)| (bench_five_axis(v, f), f.order));
        let (eval, step, _, _) = bench_model(model);
        let _ = write!(
            line,
            ",\"image_model_evaluate_insn_x100\":{},\"image_model_step_insn_x100\":{}",
            eval, step
        );
        if let Some((insn, terms, sensors)) = vol {
            let _ = write!(
                line,
                ",\"volumetric_evaluate_insn_x100\":{},\"volumetric_terms\":{},\"volumetric_sensors\":{}",
                insn, terms, sensors
            );
        }
        if let Some((insn, order)) = five {
            let _ = write!(
                line,
                ",\"five_axis_evaluate_insn_x100\":{},\"five_axis_order\":{}",
                insn, order
            );
        }
    }
    log!("{}}}", line);
    crate::finish(exit_code::OK)
}

/// Instructions of one volumetric evaluation (section kind 3: every term,
/// x, y and z) at a third of each stroke, 200 mm of tool and every sensor
/// 5 K above its reference, averaged over many calls.
fn bench_volumetric(v: &thermocomp_core::volumetric::Volumetric) -> u64 {
    const RUNS: u32 = 500;
    let mut positions = [0i32; MAX_AXES];
    for k in 0..3 {
        if let Some(p) = positions.get_mut(usize::from(v.slots[k])) {
            *p = v.origin_um[k] + v.stroke_um[k] / 3;
        }
    }
    let temps: heapless::Vec<Option<i32>, { thermocomp_core::volumetric::MAX_VOL_SENSORS }> = v
        .sensors
        .iter()
        .map(|s| Some(s.sensor.ref_temp + 80))
        .collect();
    cycles::instructions_x100(RUNS, || {
        core::hint::black_box(v.evaluate(
            core::hint::black_box(&positions),
            core::hint::black_box(200_000),
            core::hint::black_box(&temps),
        ));
    })
}

/// Instructions of one evaluation of the volumetric correction with its
/// five-axis part (kind 3 at the pose of [`bench_volumetric`], plus the
/// rotary chain at A = 30°, C = 45°).
fn bench_five_axis(
    v: &thermocomp_core::volumetric::Volumetric,
    f: &thermocomp_core::five_axis::FiveAxis,
) -> u64 {
    const RUNS: u32 = 500;
    let mut positions = [0i32; MAX_AXES];
    for k in 0..3 {
        if let Some(p) = positions.get_mut(usize::from(v.slots[k])) {
            *p = v.origin_um[k] + v.stroke_um[k] / 3;
        }
    }
    let temps: heapless::Vec<Option<i32>, { thermocomp_core::volumetric::MAX_VOL_SENSORS }> = v
        .sensors
        .iter()
        .map(|s| Some(s.sensor.ref_temp + 80))
        .collect();
    cycles::instructions_x100(RUNS, || {
        core::hint::black_box(thermocomp_core::five_axis::evaluate(
            v,
            f,
            core::hint::black_box(&positions),
            core::hint::black_box(200_000),
            core::hint::black_box([30_000, 45_000]),
            core::hint::black_box(&temps),
        ));
    })
}

/// Instructions of one full evaluation (all networks and tables) and of one
/// compensator step (features, lag filters for one step, evaluation, limits)
/// at mid-range inputs, averaged over many calls.
fn bench_model(model: Model) -> (u64, u64, u64, u64) {
    const RUNS: u32 = 500;
    // Mid-range features, Q8 of the raw unit as the compensator hands them.
    let features: heapless::Vec<i32, 16> =
        model.inputs.iter().map(|i| (i.min + i.max) << 7).collect();
    let positions = [0i32; MAX_AXES];
    let eval = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(model.evaluate(core::hint::black_box(&features), &positions));
    });
    let norm = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(model.normalise(core::hint::black_box(&features), &positions));
    });
    let corrections = cycles::instructions_x100(RUNS, || {
        core::hint::black_box(
            model.evaluate_corrections(core::hint::black_box(&features), &positions),
        );
    });

    let temps = [Some(400i32); MAX_SENSORS];
    let n = model.sensors.len();
    let mut comp = Compensator::new(Some(model));
    let mut now = 0u64;
    let step = cycles::instructions_x100(RUNS, || {
        now += 1000;
        let input = StepInput {
            now_ms: now,
            temps: &temps[..n],
            spindle_rpm: 6000,
            positions: &positions,
            stale: false,
        };
        core::hint::black_box(comp.step(core::hint::black_box(&input)));
    });
    (eval, step, norm, corrections)
}

//! The `bench` mode: instruction counts (QEMU `-icount shift=0`) of the
//! calibration loop, the math core's evaluation and one compensator step,
//! printed as one JSON line.

use core::fmt::Write as _;
use thermocomp_core::limits::{MAX_AXES, MAX_SENSORS};
use thermocomp_core::{Compensator, Model, StepInput};

use crate::cycles;
use crate::exit::{exit_code, finish};
use crate::host_files::{golden, load_model};
use crate::semihost::log;

#[embassy_executor::task]
pub async fn bench(golden_path: Option<&'static str>, model_path: Option<&'static str>) {
    const RUNS: u32 = 2000;
    let known = cycles::instructions_x100(RUNS, cycles::known_loop);
    let mut line: heapless::String<760> = heapless::String::new();
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
    let (verify_insn, ok, calibration) = bench_signature();
    let _ = write!(
        line,
        ",\"ed25519_verify_2048_bytes_insn\":{},\"ed25519_verify_ok\":{},\"time_driver_known_loop_x1000_insn\":{}",
        verify_insn, ok, calibration
    );
    log!("{}}}", line);
    finish(exit_code::OK)
}

/// Issue 30: instructions of one Ed25519 verification (what a commit with
/// a stored signing key costs) of a 2,048-byte message, the size of a
/// typical image. Millions of instructions, beyond SysTick's 1 ms wrap, so
/// timed on the time driver's 1 ms clock (1 ns of virtual time per
/// instruction under `-icount shift=0`) over 32 runs (±1 ms in 64 ms); the calibration loop
/// timed the same way (1000 × 3,000 instructions) checks the method.
/// Test vector: seed 00 01 … 1f, message byte i = (7i + 3) mod 256, signed
/// by another implementation (Python `cryptography`); `src/keys.rs`
/// checks it on the host too.
fn bench_signature() -> (u64, bool, u64) {
    const RUNS: u64 = 32;
    let message: [u8; 2048] = core::array::from_fn(|i| ((7 * i + 3) % 256) as u8);
    let t = embassy_time::Instant::now();
    let mut ok = true;
    for _ in 0..RUNS {
        ok &= thermocomp::keys::verify(&BENCH_PUBLIC_KEY, &message, &BENCH_SIGNATURE);
    }
    let verify = t.elapsed().as_micros() * 1000 / RUNS;
    let t = embassy_time::Instant::now();
    for _ in 0..1000 {
        cycles::known_loop();
    }
    let calibration = t.elapsed().as_micros() * 1000;
    (verify, ok, calibration)
}

const BENCH_PUBLIC_KEY: [u8; 32] = [
    0x03, 0xa1, 0x07, 0xbf, 0xf3, 0xce, 0x10, 0xbe, 0x1d, 0x70, 0xdd, 0x18, 0xe7, 0x4b, 0xc0, 0x99,
    0x67, 0xe4, 0xd6, 0x30, 0x9b, 0xa5, 0x0d, 0x5f, 0x1d, 0xdc, 0x86, 0x64, 0x12, 0x55, 0x31, 0xb8,
];
const BENCH_SIGNATURE: [u8; 64] = [
    0x5b, 0xd0, 0x0a, 0xd8, 0xe1, 0x27, 0x3e, 0x22, 0x4b, 0x4f, 0x2d, 0xd0, 0x8b, 0xb7, 0x2f, 0x89,
    0xbb, 0x14, 0xa3, 0x0c, 0x83, 0xf5, 0x47, 0x62, 0x24, 0xcb, 0x32, 0x1f, 0x4d, 0x35, 0x0c, 0x8b,
    0xa5, 0x68, 0xaa, 0xb5, 0xb6, 0xe5, 0xe4, 0xf9, 0xc4, 0x16, 0xac, 0x58, 0xf6, 0xf8, 0xad, 0xd6,
    0x69, 0x1b, 0x04, 0xb3, 0xe5, 0x65, 0xc2, 0xc1, 0xed, 0x46, 0xd5, 0x25, 0xdc, 0xba, 0x11, 0x01,
];

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

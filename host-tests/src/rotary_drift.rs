//! The drifting rotary machine the QEMU five-axis tests serve
//! (`qemu_export_rotary_drift`, `qemu_predict_image`): a simulated
//! table-tilting machine over an 18-cycle warm-up, its lines and R-test
//! cycles identified with drift (`identify-rotary --drift`), exported the
//! way `tcomp export --geometry … --rotary … --run …` does (the drift
//! sensors T01..T03 on channels 0, 1, 2 join the volumetric section; the
//! five-axis section in its R-test location mode), a trace of five held-out
//! cool-down states for the board to replay, and 20 five-axis poses.

use std::path::Path;

use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
use tcomp_geometry::board5::FiveAxisOptions;
use tcomp_geometry::errors::GeometricErrors;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::rotary::board::{add_drift_sensors, rotary_section};
use tcomp_geometry::rotary::check::{linear_case, CASE_STROKE};
use tcomp_geometry::rotary::identify::{identify_rotary, RotaryOptions};
use tcomp_geometry::rotary::sim::{
    random_rotary, simulate, warmup_temps, CycleSetup, RPlan, RotarySizes, SENSORS,
};
use tcomp_geometry::rotary::{Linear, RotaryModel};
use tcomp_geometry::volumetric::build;
use tcomp_numerics::rng::Rng;
use thermocomp_core::five_axis::FIVE_AXIS_RTEST_LOCATION;

/// Warm-up cycles of the simulated R-test measurements.
pub const CYCLES: usize = 18;
/// Hours after the warm-up's end: the held-out cool-down states.
pub const COOL_H: [f64; 5] = [0.1, 0.3, 0.6, 1.0, 2.0];

/// The held-out states on T01..T03 (ctable, trunnion, bed), 80 rows each,
/// written to `path` as the board's replay trace.
pub fn trace(path: &Path) {
    let end = CYCLES as f64 * CycleSetup::default().cycle_period_s;
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03\n");
    for (k, h) in COOL_H.iter().enumerate() {
        let t = warmup_temps(end + h * 3600.0, Some(end));
        for i in 0..80 {
            csv += &format!("{},6000", (80 * k + i) * 15);
            for v in &t {
                csv += &format!(",{v:.4}");
            }
            csv += "\n";
        }
    }
    std::fs::write(path, csv).unwrap();
}

/// 20 poses: x, y, z, tool (µm), A, C (0.001°).
pub fn poses() -> Vec<[i32; 6]> {
    (0..20i32)
        .map(|i| {
            [
                100_000 + 31_000 * i,
                600_000 - 23_000 * i,
                80_000 + 21_000 * i,
                60_000 + 7_000 * i,
                -90_000 + 9_473 * i,
                (17_321 * i + 5_000) % 360_000,
            ]
        })
        .collect()
}

/// The machine (truth) and what was identified from its simulated files.
pub struct DriftCase {
    pub structure: Structure,
    /// The linear axes' true errors and the identified ones.
    pub lin_truth: GeometricErrors,
    pub lin_id: GeometricErrors,
    /// The true rotary machine (with drift) and the identified model.
    pub truth: RotaryModel,
    pub model: RotaryModel,
    /// The drift sensors' names, in the trace's and the section's order.
    pub sensors: Vec<String>,
}

impl DriftCase {
    pub fn linear_truth(&self) -> Linear<'_> {
        Linear {
            structure: &self.structure,
            errors: &self.lin_truth,
        }
    }
}

/// The machine of seed 331, its lines and warm-up R-test cycles,
/// identified with drift on the three sensors.
pub fn identify() -> DriftCase {
    let mut rng = Rng::new(331);
    let (structure, lin_truth, lin_id) = linear_case(CASE_STROKE, 0.5, &mut rng).unwrap();
    let plan = RPlan::default_plan();
    let truth = random_rotary(&plan, &RotarySizes::default(), true, &mut rng);
    let setup = CycleSetup {
        thermal_cycles: CYCLES,
        ..Default::default()
    };
    let lt = Linear {
        structure: &structure,
        errors: &lin_truth,
    };
    let files = simulate(&truth, Some(lt), &plan, &setup, &mut rng).unwrap();
    let sensors: Vec<String> = SENSORS.iter().map(|s| s.0.to_string()).collect();
    let o = RotaryOptions {
        sensors: sensors.clone(),
        ..Default::default()
    };
    let li = Linear {
        structure: &structure,
        errors: &lin_id,
    };
    let model = identify_rotary(&files, Some(li), &o).unwrap().model;
    assert!(model.unobservable.is_empty() && model.drift.len() == 3);
    DriftCase {
        structure,
        lin_truth,
        lin_id,
        truth,
        model,
        sensors,
    }
}

/// The image of `case` written to `path` (the drift sensors on channels
/// 0, 1, 2 = T01..T03), as the board parses it.
pub fn export(case: &DriftCase, path: &Path) -> thermocomp_core::Model {
    let mut poly = build(&case.structure, CASE_STROKE, &case.lin_id, None).unwrap();
    add_drift_sensors(&mut poly, &case.model).unwrap();
    assert_eq!(poly.sensors, case.sensors);
    let opts = BoardOptions {
        channels: vec![0, 1, 2],
        slots: [0, 1, 2],
        origin_mm: [0.0; 3],
        tool_max_mm: 500.0,
        max_correction_um: 500.0,
    };
    let v = quantize(&poly, &opts).unwrap();
    let report = quantisation_report(&poly, &v, &opts);
    let five_opts = FiveAxisOptions {
        max_correction_um: 500.0,
        ..Default::default()
    };
    let five = rotary_section(&case.model, &v, &poly.sensors, &five_opts, false).unwrap();
    assert_eq!(
        (five.0.flags, five.0.n_sensors),
        (FIVE_AXIS_RTEST_LOCATION, 3)
    );
    assert!(five.1.max_error_um <= five.1.bound_um, "{:?}", five.1);
    let float = thermocomp_core::float::demo_model(1);
    tcomp_model::export::export_five(&float, Some((v, report)), Some(five), path, None).unwrap();
    thermocomp_core::Model::parse(&std::fs::read(path).unwrap()).unwrap()
}

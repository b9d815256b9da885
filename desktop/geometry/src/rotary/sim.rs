//! Simulated R-test cycles (docs/formats/rtest.md) of a table-tilting
//! five-axis machine with random location and component errors, optional
//! linear drift of the location errors with sensor temperatures over a
//! warm-up, and the pose plan (`tcomp geometry plan-rotary`).
//!
//! Readings come from the exact chain (`rotary::tool_tip_error`, with the
//! linear axes' exact error when given); the identification uses the
//! first-order sensitivities. Every reading, the zeroing row's too, carries
//! N(0, σ²) per direction; the file is then zeroed at its first row.

use std::collections::BTreeMap;

use super::model::{
    rtcp_position, tool_tip_error, Axis5, Drift, Linear, Location, Pose, RotaryModel,
    COMPONENT_NAMES,
};
use crate::five_axis::Fourier;
use crate::rtest::{RTestFile, RTestRow, Source};
use tcomp_numerics::rng::Rng;

/// Where the turntable sits and where the nest goes.
#[derive(Clone, Debug, PartialEq)]
pub struct RPlan {
    pub pivot_a_mm: [f64; 3],
    pub offset_c_mm: [f64; 3],
    /// Nest positions (workpiece frame) and the tool used with each.
    pub nests: Vec<([f64; 3], [f64; 3])>,
    /// (A, C) of one cycle, the zeroing pose (0, 0) first.
    pub poses: Vec<(f64, f64)>,
}

impl RPlan {
    /// The default plan: three nests, not collinear, at three radii, three
    /// heights and three directions from the C axis (the tilts of C need
    /// height, the positions of A need x spread, rtest.md's known cases
    /// need three); per cycle a C sweep at A = 0 (every 15°), A sweeps at
    /// C = 0°, 90°, 180°, 270° (every 10° over ±110°: the A tilts BOA, COA
    /// need lever arms along x both ways, and over ±90° alone their
    /// uncertainty doubles: a half turn barely separates the location's
    /// whirl from the error motions'), C sweeps at A = ±60° (every 45°),
    /// back to the zero pose: 129 poses.
    pub fn default_plan() -> RPlan {
        let mut poses = vec![(0.0, 0.0)];
        poses.extend((1..24).map(|k| (0.0, 15.0 * k as f64)));
        for c in [0.0, 90.0, 180.0, 270.0] {
            poses.extend((-11..=11).filter(|k| *k != 0).map(|k| (10.0 * k as f64, c)));
        }
        poses.extend((0..8).map(|k| (-60.0, 45.0 * k as f64)));
        poses.extend((0..8).map(|k| (60.0, 45.0 * k as f64)));
        poses.push((0.0, 0.0));
        RPlan {
            pivot_a_mm: [400.0, 350.0, 400.0],
            offset_c_mm: [0.0, 0.0, 120.0],
            nests: vec![
                ([200.0, 0.0, 60.0], [0.0, 0.0, 100.0]),
                ([-150.0, 130.0, 140.0], [0.0, 0.0, 60.0]),
                ([-100.0, -170.0, 20.0], [0.0, 0.0, 140.0]),
            ],
            poses,
        }
    }
}

/// Sizes of a random rotary machine (peak values).
#[derive(Clone, Copy, Debug)]
pub struct RotarySizes {
    pub offset_um: f64,
    pub tilt_urad: f64,
    /// Error motions: radial and axial [µm], tilt and angular positioning [µrad].
    pub motion_um: f64,
    pub motion_urad: f64,
    /// Harmonics of C's and A's component errors.
    pub order_c: usize,
    pub order_a: usize,
    /// Drift per kelvin (with temperatures): offsets µm/K, tilts µrad/K.
    pub drift_um_per_k: f64,
    pub drift_urad_per_k: f64,
}

impl Default for RotarySizes {
    fn default() -> Self {
        RotarySizes {
            offset_um: 20.0,
            tilt_urad: 30.0,
            motion_um: 3.0,
            motion_urad: 10.0,
            order_c: 3,
            order_a: 2,
            drift_um_per_k: 1.0,
            drift_urad_per_k: 2.0,
        }
    }
}

/// The simulated temperature sensors and their warm-up: T = 20 + rise·(1 − e^(−t/τ)).
pub const SENSORS: [(&str, f64, f64); 3] = [
    ("ctable", 6.0, 1200.0),
    ("trunnion", 4.0, 3600.0),
    ("bed", 2.0, 9000.0),
];

/// Temperatures at `t_s` of a warm-up that started at 0 s; after
/// `stop_s` (if any) the machine cools down with the same time constants.
pub fn warmup_temps(t_s: f64, stop_s: Option<f64>) -> Vec<f64> {
    SENSORS
        .iter()
        .map(|(_, rise, tau)| match stop_s {
            Some(stop) if t_s > stop => {
                let top = rise * (1.0 - (-stop / tau).exp());
                20.0 + top * (-(t_s - stop) / tau).exp()
            }
            _ => 20.0 + rise * (1.0 - (-t_s / tau).exp()),
        })
        .collect()
}

/// A random rotary machine on `plan`'s turntable, in the canonical convention.
pub fn random_rotary(plan: &RPlan, s: &RotarySizes, thermal: bool, rng: &mut Rng) -> RotaryModel {
    let mut r = |x: f64| rng.range(-x, x);
    let location = Location::from_array(std::array::from_fn(|i| {
        if matches!(i, 2 | 3 | 6 | 7) {
            r(s.tilt_urad)
        } else {
            r(s.offset_um)
        }
    }));
    let mut components = BTreeMap::new();
    for (i, name) in COMPONENT_NAMES.iter().enumerate() {
        let order = if i < 6 { s.order_c } else { s.order_a };
        let size = if i % 6 < 3 {
            s.motion_um
        } else {
            s.motion_urad
        };
        // decaying harmonics: the k-th at most size/k
        let f = Fourier {
            cos: (1..=order).map(|k| r(size / k as f64)).collect(),
            sin: (1..=order).map(|k| r(size / k as f64)).collect(),
        };
        components.insert(name.to_string(), f);
    }
    let drift = if thermal {
        SENSORS
            .iter()
            .map(|(name, _, _)| Drift {
                sensor: name.to_string(),
                reference_c: 20.0,
                per_kelvin: Location::from_array(std::array::from_fn(|i| {
                    if matches!(i, 2 | 3 | 6 | 7) {
                        r(s.drift_urad_per_k)
                    } else {
                        r(s.drift_um_per_k)
                    }
                })),
            })
            .collect()
    } else {
        Vec::new()
    };
    RotaryModel {
        pivot_a_mm: plan.pivot_a_mm,
        offset_c_mm: plan.offset_c_mm,
        location,
        drift,
        components,
        unobservable: Vec::new(),
        ..Default::default()
    }
    .canonical()
}

/// How the cycles are run.
#[derive(Clone, Copy, Debug)]
pub struct CycleSetup {
    pub noise_um: f64,
    /// Seconds per pose (move, settle, read).
    pub pose_s: f64,
    /// With temperatures: the warm-up's cycles (the nest moved in turn
    /// through the plan's positions, one file per cycle); 0: one cold cycle
    /// per nest, no temperature columns.
    pub thermal_cycles: usize,
    /// Seconds between the starts of two cycles.
    pub cycle_period_s: f64,
}

impl Default for CycleSetup {
    fn default() -> Self {
        CycleSetup {
            noise_um: 0.5,
            pose_s: 5.0,
            thermal_cycles: 0,
            cycle_period_s: 900.0,
        }
    }
}

/// One simulated cycle of nest `k` starting at `start_s`.
fn cycle(
    m: &RotaryModel,
    lin: Option<Linear>,
    plan: &RPlan,
    k: usize,
    start_s: Option<f64>,
    setup: &CycleSetup,
    rng: &mut Rng,
) -> anyhow::Result<RTestFile> {
    let (noise_um, pose_s) = (setup.noise_um, setup.pose_s);
    let (nest, tool) = plan.nests[k];
    let mut rows = Vec::with_capacity(plan.poses.len());
    let mut zero = [0.0; 3];
    for (i, &(a, c)) in plan.poses.iter().enumerate() {
        let pos = rtcp_position(m.pivot_a_mm, m.offset_c_mm, nest, tool, a, c);
        let time_s = start_s.map(|t| t + pose_s * i as f64);
        let temps = time_s.map(|t| warmup_temps(t, None)).unwrap_or_default();
        let named: BTreeMap<String, f64> = (SENSORS.iter().map(|s| s.0.to_string()))
            .zip(temps.iter().copied())
            .collect();
        let loc = m.location_at(&named)?;
        let pose = Pose {
            pos_mm: pos,
            a_deg: a,
            c_deg: c,
            tool_mm: tool,
        };
        let e = tool_tip_error(m, &loc, lin, &pose);
        let read: [f64; 3] = std::array::from_fn(|d| e[d] + noise_um * rng.normal());
        if i == 0 {
            zero = read;
        }
        rows.push(RTestRow {
            pos_mm: pos,
            a_deg: a,
            c_deg: c,
            // written with 4 decimals: round here so the file is the truth
            d_um: std::array::from_fn(|d| ((read[d] - zero[d]) * 1e4).round() / 1e4),
            time_s,
            temps,
        });
    }
    Ok(RTestFile {
        name: String::new(),
        pivot_a_mm: m.pivot_a_mm,
        offset_c_mm: m.offset_c_mm,
        nest_mm: nest,
        tool_mm: tool,
        source: Source::Simulated,
        sensors_ppm_per_k: None,
        other_meta: vec![("nest".into(), format!("N{}", k + 1))],
        sensors: if start_s.is_some() {
            SENSORS.iter().map(|s| s.0.to_string()).collect()
        } else {
            Vec::new()
        },
        rows,
    })
}

/// The R-test files of `plan` on machine `m` (names `N1.csv` … or, with
/// temperatures, `C01_N1.csv` …).
pub fn simulate(
    m: &RotaryModel,
    lin: Option<Linear>,
    plan: &RPlan,
    setup: &CycleSetup,
    rng: &mut Rng,
) -> anyhow::Result<Vec<RTestFile>> {
    let mut out = Vec::new();
    if setup.thermal_cycles == 0 {
        for k in 0..plan.nests.len() {
            let mut f = cycle(m, lin, plan, k, None, setup, rng)?;
            f.name = format!("N{}.csv", k + 1);
            out.push(f);
        }
        return Ok(out);
    }
    for j in 0..setup.thermal_cycles {
        let k = j % plan.nests.len();
        let start = setup.cycle_period_s * j as f64;
        let mut f = cycle(m, lin, plan, k, Some(start), setup, rng)?;
        f.name = format!("C{:02}_N{}.csv", j + 1, k + 1);
        out.push(f);
    }
    Ok(out)
}

/// Which rotary axis a component name belongs to.
pub fn axis_of(name: &str) -> Axis5 {
    if name.ends_with('A') {
        Axis5::A
    } else {
        Axis5::C
    }
}

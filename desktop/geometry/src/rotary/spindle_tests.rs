use crate::adequacy::StatedNoise;
use crate::rotary::identify::{identify_rotary, RotaryOptions};
use crate::rotary::model::{
    location_shift_of_offset, rtcp_position, spindle_offset_um, tool_tip_error, Pose, RotaryModel,
    Spindle,
};
use crate::rotary::sim::{random_rotary, simulate, CycleSetup, RPlan, RotarySizes};
use crate::rtest::RTestFile;
use nalgebra::Vector3;
use tcomp_numerics::rng::Rng;

const TILT: [f64; 2] = [24.0, -17.0];

/// The default plan's three nests, each measured with every tool of `tools`.
fn plan(tools: &[f64]) -> RPlan {
    let mut p = RPlan::default_plan();
    let nests: Vec<[f64; 3]> = p.nests.iter().map(|(n, _)| *n).collect();
    p.nests = (nests.iter())
        .flat_map(|n| tools.iter().map(move |l| (*n, [0.0, 0.0, *l])))
        .collect();
    p
}

/// A random machine whose spindle is tilted by [`TILT`] relative to the
/// lines' frame (reference tool zero: `location` is the true one), and its
/// R-test files (σ 0.5 µm).
fn machine(tools: &[f64], seed: u64) -> (RotaryModel, Vec<RTestFile>) {
    let p = plan(tools);
    let mut rng = Rng::new(seed);
    let mut truth = random_rotary(&p, &RotarySizes::default(), false, &mut rng);
    truth.spindle = Some(Spindle {
        about_x_urad: TILT[0],
        about_y_urad: TILT[1],
        reference_tool_mm: [0.0; 3],
    });
    let files = simulate(&truth, None, &p, &CycleSetup::default(), &mut rng).unwrap();
    (truth, files)
}

fn noise() -> StatedNoise {
    StatedNoise::new(Some(0.5)).unwrap()
}

#[test]
fn two_tool_lengths_give_the_spindle_direction_within_three_sigma() {
    for seed in [5, 6] {
        let (truth, files) = machine(&[100.0, 200.0], seed);
        let mut id = identify_rotary(&files, None, &RotaryOptions::default()).unwrap();
        id.assess(noise()).unwrap();
        assert_eq!(id.spindle.status, "identified", "{}", id.spindle.why);
        assert_eq!(id.spindle.tools_mm.len(), 2);
        for (k, t) in id.spindle.angles.iter().enumerate() {
            let (v, s) = (t.value.unwrap(), t.sigma.unwrap());
            assert!(s > 0.0 && s < 5.0, "seed {seed} {}: σ {s}", t.name);
            assert!(
                (v - TILT[k]).abs() <= 3.0 * s,
                "seed {seed} {}: {v} ± {s} vs {}",
                t.name,
                TILT[k]
            );
        }
        // the reported location errors are the true ones (lines' frame)
        let tl = truth.location.to_array();
        for (k, t) in id.location.iter().enumerate() {
            let (v, s) = (t.value.unwrap(), t.sigma.unwrap());
            assert!(
                (v - tl[k]).abs() <= 3.0 * s,
                "seed {seed} {}: {v} ± {s} vs {}",
                t.name,
                tl[k]
            );
        }
        // the model keeps them as they appear at the files' mean tool
        let sp = id.model.spindle.expect("model without its spindle");
        assert_eq!(sp.reference_tool_mm, [0.0, 0.0, 150.0]);
        let back = id
            .model
            .location_for_tool(&id.model.location, [0.0; 3])
            .to_array();
        for (k, t) in id.location.iter().enumerate() {
            assert!((back[k] - t.value.unwrap()).abs() < 1e-9, "{}", t.name);
        }
        assert!(id.adequate.unwrap(), "{}", id.adequacy.unwrap().failure);
    }
}

#[test]
fn one_tool_length_leaves_the_spindle_undetermined_and_in_the_location_errors() {
    let (truth, files) = machine(&[150.0], 7);
    let mut id = identify_rotary(&files, None, &RotaryOptions::default()).unwrap();
    id.assess(noise()).unwrap();
    assert_eq!(id.spindle.status, "undetermined");
    assert!(id.spindle.angles.is_empty());
    assert!(
        id.spindle.why.contains("not identifiable"),
        "{}",
        id.spindle.why
    );
    assert!(id.model.spindle.is_none());
    assert!(id.unobservable.is_empty(), "{:?}", id.unobservable);
    // what is reported is the location errors apparent at that tool
    let d = spindle_offset_um(TILT, Vector3::new(0.0, 0.0, 150.0));
    let apparent = truth
        .location
        .add_scaled(&location_shift_of_offset(d), 1.0)
        .to_array();
    for (k, t) in id.location.iter().enumerate() {
        let (v, s) = (t.value.unwrap(), t.sigma.unwrap());
        assert!(
            (v - apparent[k]).abs() <= 3.0 * s,
            "{}: {v} ± {s} vs apparent {}",
            t.name,
            apparent[k]
        );
    }
    assert!(id.adequate.unwrap());
}

#[test]
fn a_spindle_offset_reads_as_the_location_shift_at_its_reference_tool() {
    let p = plan(&[100.0]);
    let mut m = random_rotary(&p, &RotarySizes::default(), false, &mut Rng::new(9));
    let sp = Spindle {
        about_x_urad: 30.0,
        about_y_urad: -20.0,
        reference_tool_mm: [0.0; 3],
    };
    m.spindle = Some(sp);
    // the same machine with the tilt folded into the location at 180 mm
    let tool = [0.0, 0.0, 180.0];
    let mut folded = m.clone();
    folded.location = sp.move_location(&m.location, [0.0; 3], tool);
    folded.spindle = Some(Spindle {
        reference_tool_mm: tool,
        ..sp
    });
    let mut bare = folded.clone();
    bare.spindle = None;
    let nest = [150.0, -60.0, 70.0];
    let at = |mm: &RotaryModel, a: f64, c: f64, t: [f64; 3]| {
        let pos = rtcp_position(m.pivot_a_mm, m.offset_c_mm, nest, t, a, c);
        let pose = Pose {
            pos_mm: pos,
            a_deg: a,
            c_deg: c,
            tool_mm: t,
        };
        tool_tip_error(mm, &mm.location, None, &pose)
    };
    let c0 = at(&m, 0.0, 0.0, tool) - at(&folded, 0.0, 0.0, tool);
    // ε × t at 180 mm: −3.6 µm in x, −5.4 µm in y
    assert!((c0 - Vector3::new(-3.6, -5.4, 0.0)).norm() < 1e-6, "{c0}");
    for (a, c) in [(40.0, 0.0), (-80.0, 135.0), (100.0, 300.0)] {
        // relative to the zero pose (an R-test reading), all three agree at the reference tool
        let r = at(&m, a, c, tool) - at(&m, 0.0, 0.0, tool);
        let rf = at(&folded, a, c, tool) - at(&folded, 0.0, 0.0, tool);
        let rb = at(&bare, a, c, tool) - at(&bare, 0.0, 0.0, tool);
        assert!(r.norm() > 3.0);
        assert!(
            (r - rf).norm() < 2e-3 && (r - rb).norm() < 2e-3,
            "{r} {rf} {rb}"
        );
        // at another tool only the model with its spindle follows the machine
        let t2 = [0.0, 0.0, 60.0];
        let r2 = at(&m, a, c, t2) - at(&m, 0.0, 0.0, t2);
        let rf2 = at(&folded, a, c, t2) - at(&folded, 0.0, 0.0, t2);
        let rb2 = at(&bare, a, c, t2) - at(&bare, 0.0, 0.0, t2);
        assert!((r2 - rf2).norm() < 2e-3, "{r2} {rf2}");
        assert!((r2 - rb2).norm() > 0.5, "{r2} {rb2}");
    }
}

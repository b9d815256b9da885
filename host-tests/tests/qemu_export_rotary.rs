//! An identified rotary model, exported the way `tcomp export --geometry …
//! --rotary …` does (`tcomp_model::export::export_five` with
//! `rotary::board::rotary_section`), served by the bench board (issue 31):
//! a simulated machine's 14 lines and R-test files are identified, the
//! image written, uploaded to QEMU, and at 20 five-axis poses the served
//! correction equals the desktop's prediction from the written file
//! (`board5::predict5`) bit for bit and removes most of the true error.

use host_tests::qemu::{modbus_master as master, BenchBoard};
use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
use tcomp_geometry::board5::{predict5, FiveAxisOptions};
use tcomp_geometry::rotary::board::rotary_section;
use tcomp_geometry::rotary::check::{linear_case, CASE_STROKE};
use tcomp_geometry::rotary::identify::{identify_rotary, RotaryOptions};
use tcomp_geometry::rotary::sim::{random_rotary, simulate, CycleSetup, RPlan, RotarySizes};
use tcomp_geometry::rotary::{nominal_chain, tool_tip_error, Linear, Pose};
use tcomp_geometry::volumetric::build;
use tcomp_numerics::rng::Rng;
use thermocomp_core::five_axis::fstatus;

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn an_exported_rotary_model_is_served_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("thermocomp-5ax-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (t, m) = (dir.join("trace.csv"), dir.join("model.img"));
    let mut csv = String::from("time_s,spindle_rpm,T01\n");
    for i in 0..200u32 {
        csv += &format!("{},6000,20.0\n", i * 15);
    }
    std::fs::write(&t, csv).unwrap();

    // The machine, its lines and R-test files, identified.
    let mut rng = Rng::new(31);
    let (st, lin_truth, lin_id) = linear_case(CASE_STROKE, 0.5, &mut rng).unwrap();
    let plan = RPlan::default_plan();
    let truth = random_rotary(&plan, &RotarySizes::default(), false, &mut rng);
    let lt = Linear {
        structure: &st,
        errors: &lin_truth,
    };
    let li = Linear {
        structure: &st,
        errors: &lin_id,
    };
    let files = simulate(&truth, Some(lt), &plan, &CycleSetup::default(), &mut rng).unwrap();
    let id = identify_rotary(&files, Some(li), &RotaryOptions::default()).unwrap();
    assert!(id.model.unobservable.is_empty());

    // The export (`tcomp export --demo --geometry --rotary`).
    let poly = build(&st, CASE_STROKE, &lin_id, None).unwrap();
    let opts = BoardOptions {
        channels: vec![],
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
    let five = rotary_section(&id.model, &v, &poly.sensors, &five_opts, false).unwrap();
    assert_eq!(five.0.order, 4);
    let float = thermocomp_core::float::demo_model(1);
    tcomp_model::export::export_five(&float, Some((v, report)), Some(five), &m, None).unwrap();
    let model = thermocomp_core::Model::parse(&std::fs::read(&m).unwrap()).unwrap();

    let (_board, port) = BenchBoard::serve_tcp(&t, &m, &["150"]);
    let p_s = port.to_string();
    // 20 poses: x, y, z, tool (µm), A, C (0.001°).
    let poses: Vec<[i32; 6]> = (0..20i32)
        .map(|i| {
            [
                100_000 + 31_000 * i,
                600_000 - 23_000 * i,
                80_000 + 21_000 * i,
                60_000 + 7_000 * i,
                -90_000 + 9_473 * i,
                (17_321 * i) % 360_000,
            ]
        })
        .collect();
    let args: Vec<String> = poses
        .iter()
        .map(|a| format!("--at={},{},{},{},{},{}", a[0], a[1], a[2], a[3], a[4], a[5]))
        .collect();
    let mut a = vec!["volumetric", "--port", &p_s];
    a.extend(args.iter().map(|s| s.as_str()));
    let (mut before, mut after) = (0.0, 0.0);
    for (k, r) in master(&a).as_array().unwrap().iter().enumerate() {
        assert!(r.get("error").is_none(), "{r}");
        let at = poses[k];
        let want = predict5(
            &model,
            &[at[0], at[1], at[2], 0, 0, 0],
            at[3],
            [at[4], at[5]],
            &[],
        )
        .expect("the image has both sections");
        let ints = |key: &str| -> Vec<i64> {
            r[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap())
                .collect()
        };
        assert_eq!(
            ints("correction"),
            want.corrections.map(i64::from).to_vec(),
            "pose {k}"
        );
        assert_eq!(
            ints("rotary"),
            want.rotary.map(i64::from).to_vec(),
            "pose {k}"
        );
        assert_eq!(
            r["status"].as_u64().unwrap() as u16,
            want.status,
            "pose {k}"
        );
        assert_eq!(r["five_status"].as_u64().unwrap() as u16, fstatus::INCLUDED);
        // and what it does to the true tool-tip error (machine frame)
        let (ad, cd) = (f64::from(at[4]) / 1e3, f64::from(at[5]) / 1e3);
        let pose = Pose {
            pos_mm: [at[0], at[1], at[2]].map(|p| f64::from(p) / 1e3),
            a_deg: ad,
            c_deg: cd,
            tool_mm: [0.0, 0.0, f64::from(at[3]) / 1e3],
        };
        let rot = nominal_chain(truth.pivot_a_mm, truth.offset_c_mm, ad, cd).rotation;
        let e = rot * tool_tip_error(&truth, &truth.location, Some(lt), &pose);
        for d in 0..3 {
            before += e[d] * e[d];
            after += (e[d] - f64::from(want.corrections[d]) / 10.0).powi(2);
        }
    }
    let (before, after) = ((before / 20.0).sqrt(), (after / 20.0).sqrt());
    println!("20 poses served bit for bit; true tool tip {before:.2} → {after:.2} µm RMS");
    assert!(after < 0.15 * before, "{before} → {after}");
}

//! A rotary model whose location errors drift with temperature
//! (`identify-rotary --drift`), exported the way `tcomp export --geometry …
//! --rotary … --run …` does (the drift sensors join the volumetric
//! section; the five-axis section in its R-test location mode), served by
//! the bench board (issue 31 items 3 + 4): a machine simulated over an
//! 18-cycle warm-up, its lines and R-test cycles identified, the image
//! uploaded to QEMU while a trace replays five held-out temperature states
//! of the cool-down on the emulated DS18B20s. At 20 five-axis poses in at
//! least three of those states the served correction, rotary part and
//! status equal the desktop's prediction from the written file
//! (`board5::predict5`, at the temperatures the board reports it used) bit
//! for bit; the true tool-tip error (linear + rotary with its drift) is
//! printed before and after, and with the drift left out.

use std::collections::{BTreeMap, BTreeSet};

use host_tests::qemu::{modbus_master as master, BenchBoard};
use host_tests::rotary_drift::{export, identify, poses, trace};
use tcomp_geometry::board5::predict5;
use tcomp_geometry::rotary::{nominal_chain, tool_tip_error, Pose};
use thermocomp_core::five_axis::fstatus;
use thermocomp_core::volumetric::vstatus;

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn an_exported_drifting_rotary_model_is_served_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("thermocomp-5ax-drift-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (t, m) = (dir.join("trace.csv"), dir.join("model.img"));
    trace(&t);

    // The machine, its lines and warm-up R-test cycles, identified with
    // drift; the export with the drift sensors on channels 0, 1, 2 (T01..T03).
    let case = identify();
    let (truth, names, lt) = (&case.truth, &case.sensors, case.linear_truth());
    let model = export(&case, &m);
    let refs: Vec<Option<i32>> = (model.volumetric.as_ref().unwrap().sensors.iter())
        .map(|s| Some(s.sensor.ref_temp))
        .collect();

    let (board, port) = BenchBoard::serve_tcp(&t, &m, &["200"]);
    let p_s = port.to_string();
    let poses = poses();
    let args: Vec<String> = poses
        .iter()
        .map(|a| format!("--at={},{},{},{},{},{}", a[0], a[1], a[2], a[3], a[4], a[5]))
        .collect();
    let mut seen: BTreeMap<Vec<i32>, BTreeSet<usize>> = BTreeMap::new();
    let (mut before, mut after, mut no_drift, mut n) = (0.0, 0.0, 0.0, 0u32);
    let done = |seen: &BTreeMap<Vec<i32>, BTreeSet<usize>>| {
        seen.values().filter(|s| s.len() >= 20).count() >= 3
    };
    for _round in 0..60 {
        let mut a = vec!["volumetric", "--port", &p_s];
        a.extend(args.iter().map(|s| s.as_str()));
        for (k, r) in master(&a).as_array().unwrap().iter().enumerate() {
            assert!(r.get("error").is_none(), "{r}");
            let status = r["status"].as_u64().unwrap() as u16;
            if status & vstatus::SENSOR_FAULT != 0 || r["sequence"] != r["five_sequence"] {
                continue; // first cycle not in yet, or a cycle between the reads
            }
            let temps: Vec<i32> = r["temps_16"].as_array().unwrap()[..3]
                .iter()
                .map(|x| x.as_i64().unwrap() as i32)
                .collect();
            let at = poses[k];
            let positions = [at[0], at[1], at[2], 0, 0, 0];
            let t16: Vec<Option<i32>> = temps.iter().map(|v| Some(*v)).collect();
            let want = predict5(&model, &positions, at[3], [at[4], at[5]], &t16)
                .expect("the image has both sections");
            let ints = |key: &str| -> Vec<i64> {
                let v = r[key].as_array().unwrap();
                v.iter().map(|x| x.as_i64().unwrap()).collect()
            };
            let at_temps = format!("pose {k} at {temps:?}");
            assert_eq!(
                ints("correction"),
                want.corrections.map(i64::from).to_vec(),
                "{at_temps}"
            );
            assert_eq!(
                ints("rotary"),
                want.rotary.map(i64::from).to_vec(),
                "{at_temps}"
            );
            assert_eq!(status, want.status, "{at_temps}");
            assert_eq!(r["five_status"].as_u64().unwrap() as u16, fstatus::INCLUDED);
            if !seen.entry(temps.clone()).or_default().insert(k) {
                continue; // scored once per pose and state
            }
            // The true tool-tip error at the state the board read.
            let by_name = names
                .iter()
                .cloned()
                .zip(temps.iter().map(|v| f64::from(*v) / 16.0));
            let loc = truth.location_at(&by_name.collect()).unwrap();
            let (ad, cd) = (f64::from(at[4]) / 1e3, f64::from(at[5]) / 1e3);
            let pose = Pose {
                pos_mm: [at[0], at[1], at[2]].map(|p| f64::from(p) / 1e3),
                a_deg: ad,
                c_deg: cd,
                tool_mm: [0.0, 0.0, f64::from(at[3]) / 1e3],
            };
            let rot = nominal_chain(truth.pivot_a_mm, truth.offset_c_mm, ad, cd).rotation;
            let e = rot * tool_tip_error(truth, &loc, Some(lt), &pose);
            let frozen = predict5(&model, &positions, at[3], [at[4], at[5]], &refs).unwrap();
            for d in 0..3 {
                before += e[d] * e[d];
                after += (e[d] - f64::from(want.corrections[d]) / 10.0).powi(2);
                no_drift += (e[d] - f64::from(frozen.corrections[d]) / 10.0).powi(2);
            }
            n += 1;
        }
        if done(&seen) {
            break;
        }
    }
    let summary: Vec<_> = seen.iter().map(|(t, s)| (t.clone(), s.len())).collect();
    assert!(
        done(&seen),
        "poses per temperature state {summary:?}\n{}",
        board.log()
    );
    let rms = |v: f64| (v / f64::from(n)).sqrt();
    let (before, after, no_drift) = (rms(before), rms(after), rms(no_drift));
    println!(
        "served bit for bit, poses per held-out temperature state {summary:?}; true tool tip {before:.2} → {after:.2} µm RMS over {n} pose × state pairs ({no_drift:.2} µm with the drift left out)"
    );
    assert!(after < 0.15 * before, "{before} → {after}");
    assert!(after < no_drift, "the drift helps: {after} vs {no_drift}");
}

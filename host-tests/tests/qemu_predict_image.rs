//! `tcomp geometry predict --image` is what the bench board serves (issue
//! 49 item 4): the drifting rotary machine of `qemu_export_rotary_drift`
//! (lines and R-test cycles identified with drift, exported with both
//! sections, the drift sensors on T01..T03) is served by QEMU while a trace
//! replays held-out cool-down states. The board's served correction,
//! rotary part and status words are read over Modbus at 20 five-axis
//! poses; for each of at least 3 temperature states the real `tcomp`
//! binary is run on the user's files (the errors file, the rotary model,
//! a poses CSV with the state's temperatures as `T_<sensor>` columns, the
//! image) and its `served` figures must equal the board's bit for bit (in
//! the registers' integers) at every pose × state, its served − desktop
//! within its stated bound.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use host_tests::qemu::{modbus_master as master, tcomp_exe, BenchBoard};
use host_tests::rotary_drift::{export, identify, poses, trace};
use tcomp_geometry::rotary::check::CASE_STROKE;
use tcomp_geometry::study::ErrorsJson;
use thermocomp_core::volumetric::vstatus;

/// What the board served at one pose: correction and rotary part (0.1 µm,
/// input registers 180–185 and 336–341), status (186) and five-axis status.
#[derive(Clone, Debug, PartialEq)]
struct Served {
    correction: Vec<i64>,
    rotary: Vec<i64>,
    status: u64,
    five_status: u64,
}

/// Register integers from predict's µm figures (one decimal: 0.1 µm).
fn tenths(v: &serde_json::Value) -> Vec<i64> {
    let a = v.as_array().unwrap_or_else(|| panic!("not an array: {v}"));
    a.iter()
        .map(|x| {
            let t = x.as_f64().unwrap() * 10.0;
            assert!((t - t.round()).abs() < 1e-6, "{x} µm is not in 0.1 µm");
            t.round() as i64
        })
        .collect()
}

/// The poses CSV a user writes for one temperature state: mm, degrees,
/// °C (the board's 1/16 °C readings, exact in decimal).
fn poses_csv(path: &Path, names: &[String], temps_16: &[i32]) {
    let mut csv = String::from("id,x,y,z,a,c,tool");
    for n in names {
        csv += &format!(",T_{n}");
    }
    csv += "\n";
    for (k, p) in poses().iter().enumerate() {
        let mm = |v: i32| f64::from(v) / 1e3;
        csv += &format!(
            "p{k},{},{},{},{},{},{}",
            mm(p[0]),
            mm(p[1]),
            mm(p[2]),
            mm(p[4]),
            mm(p[5]),
            mm(p[3])
        );
        for t in temps_16 {
            csv += &format!(",{}", f64::from(*t) / 16.0);
        }
        csv += "\n";
    }
    std::fs::write(path, csv).unwrap();
}

/// `tcomp geometry predict … --image … --json` in `dir`; its JSON.
fn predict(dir: &Path, poses: &str) -> serde_json::Value {
    let out = Command::new(tcomp_exe())
        .current_dir(dir)
        .args(["geometry", "predict", "--model", "id.json", "--rotary"])
        .args(["rotary.json", "--poses", poses, "--image", "model.img"])
        .arg("--json")
        .output()
        .expect("run tcomp");
    assert!(
        out.status.success(),
        "tcomp geometry predict: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Poll the board at the 20 poses until at least 3 temperature states
/// have all of them; the served values by state (the board's 1/16 °C
/// readings) and pose. A pose read twice in one state must read the same.
fn read_board(port: u16, board: &BenchBoard) -> BTreeMap<Vec<i32>, BTreeMap<usize, Served>> {
    let p_s = port.to_string();
    let poses = poses();
    let args: Vec<String> = (poses.iter())
        .map(|a| format!("--at={},{},{},{},{},{}", a[0], a[1], a[2], a[3], a[4], a[5]))
        .collect();
    let mut seen: BTreeMap<Vec<i32>, BTreeMap<usize, Served>> = BTreeMap::new();
    let done = |s: &BTreeMap<Vec<i32>, BTreeMap<usize, Served>>| {
        s.values().filter(|p| p.len() == poses.len()).count() >= 3
    };
    for _round in 0..60 {
        let mut a = vec!["volumetric", "--port", &p_s];
        a.extend(args.iter().map(|s| s.as_str()));
        for (k, r) in master(&a).as_array().unwrap().iter().enumerate() {
            assert!(r.get("error").is_none(), "{r}");
            let status = r["status"].as_u64().unwrap();
            if status & u64::from(vstatus::SENSOR_FAULT) != 0 || r["sequence"] != r["five_sequence"]
            {
                continue; // first cycle not in yet, or a cycle between the reads
            }
            let temps: Vec<i32> = r["temps_16"].as_array().unwrap()[..3]
                .iter()
                .map(|x| x.as_i64().unwrap() as i32)
                .collect();
            let ints = |key: &str| -> Vec<i64> {
                (r[key].as_array().unwrap().iter())
                    .map(|x| x.as_i64().unwrap())
                    .collect()
            };
            let s = Served {
                correction: ints("correction"),
                rotary: ints("rotary"),
                status,
                five_status: r["five_status"].as_u64().unwrap(),
            };
            let state = seen.entry(temps.clone()).or_default();
            if let Some(before) = state.get(&k) {
                assert_eq!(before, &s, "pose {k} at {temps:?} read twice");
            }
            state.insert(k, s);
        }
        if done(&seen) {
            return seen;
        }
    }
    let summary: Vec<_> = seen.iter().map(|(t, s)| (t.clone(), s.len())).collect();
    panic!("poses per temperature state {summary:?}\n{}", board.log());
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm, pymodbus and target/<profile>/tcomp: scripts/test.sh"]
fn predict_with_the_image_is_what_the_board_serves_bit_for_bit() {
    let start = Instant::now();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    trace(&d.join("trace.csv"));
    let case = identify();
    export(&case, &d.join("model.img"));
    // The user's files: the linear errors (identify --json) and the rotary
    // model (identify-rotary --model-out) the image was exported from.
    let errors = ErrorsJson::from_errors(&case.lin_id, &case.structure, CASE_STROKE, 11);
    std::fs::write(d.join("id.json"), serde_json::to_string(&errors).unwrap()).unwrap();
    let rotary = serde_json::to_string(&case.model).unwrap();
    std::fs::write(d.join("rotary.json"), rotary).unwrap();

    let (board, port) = BenchBoard::serve_tcp(&d.join("trace.csv"), &d.join("model.img"), &["200"]);
    let seen = read_board(port, &board);
    drop(board);

    let n_poses = poses().len();
    let (mut states, mut compared, mut worst) = (0, 0, 0.0f64);
    for (i, (temps, served)) in seen.iter().enumerate() {
        if served.len() < n_poses {
            continue;
        }
        let file = format!("poses{i}.csv");
        poses_csv(&d.join(&file), &case.sensors, temps);
        let out = predict(d, &file);
        assert_eq!(out["image"]["compared"], "total", "{}", out["image"]);
        let rows = out["rows"].as_array().unwrap();
        assert_eq!(rows.len(), n_poses);
        for (k, r) in rows.iter().enumerate() {
            let at = format!("pose {k} at {temps:?} (1/16 °C)");
            let b = &served[&k];
            let p = &r["served"];
            assert_eq!(tenths(&p["correction_machine_um"]), b.correction, "{at}");
            assert_eq!(tenths(&p["rotary_part_machine_um"]), b.rotary, "{at}");
            assert_eq!(p["status"].as_u64(), Some(b.status), "{at}");
            assert_eq!(p["five_axis_status"].as_u64(), Some(b.five_status), "{at}");
            assert_eq!(r["within_bound"], true, "{at}: {r}");
            let diff = r["served_minus_desktop_um"].as_array().unwrap();
            worst = (diff.iter()).fold(worst, |m, x| m.max(x.as_f64().unwrap().abs()));
            compared += 1;
        }
        states += 1;
    }
    assert!(states >= 3, "{states} complete states");
    println!(
        "predict --image equals the board bit for bit at {compared} pose × state pairs ({n_poses} poses × {states} states); served − desktop at most {worst:.4} µm; {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

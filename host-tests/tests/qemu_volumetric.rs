//! The volumetric correction on the bench board (issue 14, "Done when":
//! the board serves it bit-exact with the desktop under QEMU). An image
//! exported by `tcomp export`'s own path with a volumetric section (two
//! sensors, per-kelvin terms, tool-length terms) is served while a warming
//! trace is replayed on the emulated DS18B20s; pymodbus writes positions
//! and tool lengths and reads input registers 180–199. Every served
//! correction equals the desktop's prediction (the core's evaluation, via
//! `tcomp_geometry::board::predict`) for the temperatures the board
//! reports it used, bit for bit, at several positions and temperatures.
use std::collections::BTreeSet;

use host_tests::qemu::{modbus_master as master, BenchBoard};
use tcomp_geometry::board::{predict, quantisation_report, quantize, BoardOptions};
use tcomp_geometry::volumetric::{VolTerm, VolumetricPoly};
use thermocomp_core::volumetric::vstatus;

/// Six sensors warming by whole 1/16 °C steps (T0c rises c + 1 sixteenths per row).
fn trace(path: &std::path::Path, rows: u32) {
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..rows {
        csv += &format!("{},6000", i * 15);
        for c in 0..6 {
            csv += &format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) / 16.0);
        }
        csv += "\n";
    }
    std::fs::write(path, csv).unwrap();
}

fn term(monomial: [u8; 4], sensor: Option<usize>, coef_um: [f64; 3]) -> VolTerm {
    VolTerm {
        monomial,
        sensor,
        coef_um,
    }
}

fn poly() -> VolumetricPoly {
    VolumetricPoly {
        structure: "XY/Z".into(),
        stroke_mm: [800.0, 500.0, 400.0],
        sensors: vec!["T01".into(), "T03".into()],
        t_ref_c: vec![20.0, 20.5],
        terms: vec![
            term([0, 0, 0, 0], None, [3.2, -1.5, 0.8]),
            term([1, 0, 0, 0], None, [12.0, 0.0, -4.0]),
            term([0, 1, 0, 1], None, [0.5, 2.0, -1.0]),
            term([1, 1, 1, 0], None, [-2.0, 3.0, 1.0]),
            term([2, 0, 1, 0], None, [0.7, -0.2, 1.3]),
            term([1, 0, 0, 0], Some(0), [0.8, -0.3, 0.1]),
            term([0, 0, 1, 1], Some(1), [0.2, 0.05, -0.4]),
            term([0, 0, 0, 0], Some(1), [0.5, 0.5, -0.25]),
        ],
        max_fit_error_um: 0.0,
        unobservable_terms: Vec::new(),
        unobservable_accepted: false,
        // A hand-made section: no identification behind it to judge.
        adequate: None,
        adequacy: None,
    }
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn the_served_volumetric_correction_equals_the_desktop_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("thermocomp-vol-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (t, m) = (dir.join("trace.csv"), dir.join("model.img"));
    trace(&t, 800);
    let p = poly();
    let opts = BoardOptions {
        channels: vec![0, 2],
        slots: [0, 1, 2],
        origin_mm: [0.0, 0.0, -400.0],
        tool_max_mm: 500.0,
        max_correction_um: 200.0,
    };
    let v = quantize(&p, &opts).unwrap();
    let report = quantisation_report(&p, &v, &opts);
    assert!(report.max_error_um <= report.bound_um, "{report:?}");
    let summary = tcomp_model::export::export_with(
        &thermocomp_core::float::demo_model(1),
        Some((v, report)),
        &m,
    )
    .unwrap();
    assert!(summary.volumetric.is_some());
    let model = thermocomp_core::Model::parse(&std::fs::read(&m).unwrap()).unwrap();
    let n_terms = model.volumetric.as_ref().unwrap().terms.len();

    let (board, port) = BenchBoard::serve_tcp(&t, &m, &["150"]);
    let p_s = port.to_string();
    // Before the PLC writes positions: not available, and the reason.
    let w = master(&["inputs", "--port", &p_s, "--addr", "180", "--count", "20"]);
    let w: Vec<u64> = w
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap())
        .collect();
    assert_eq!(&w[0..6], &[0x8000, 0, 0x8000, 0, 0x8000, 0], "{w:x?}");
    assert_eq!(
        w[6] & u64::from(vstatus::NO_POSITIONS),
        u64::from(vstatus::NO_POSITIONS)
    );
    assert_eq!(w[7], n_terms as u64);

    let points = [
        [0, 0, -400_000, 0],
        [400_000, 250_000, -200_000, 120_000],
        [800_000, 500_000, 0, 500_000],
        [123_456, 7, -399_999, 33_333],
        [650_000, 90_000, -30_000, 250_000],
        [900_000, -5_000, 10_000, 600_000], // beyond the strokes and the tool scale
    ];
    let args: Vec<String> = points
        .iter()
        .map(|a| format!("--at={},{},{},{}", a[0], a[1], a[2], a[3]))
        .collect();
    let mut temps_seen = BTreeSet::new();
    let mut compared = 0;
    let mut distinct = BTreeSet::new();
    for _round in 0..40 {
        let mut a = vec!["volumetric", "--port", &p_s];
        a.extend(args.iter().map(|s| s.as_str()));
        for r in master(&a).as_array().unwrap() {
            assert!(r.get("error").is_none(), "{r}");
            let status = r["status"].as_u64().unwrap() as u16;
            if status & vstatus::SENSOR_FAULT != 0 {
                continue; // the bench's first acquisition cycle is not in yet
            }
            let at: Vec<i32> = r["at"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap() as i32)
                .collect();
            let temps: Vec<i32> = r["temps_16"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap() as i32)
                .collect();
            // The temperatures it used are a row of the trace (T01, T03).
            let row = temps[0] - 320;
            assert!(
                row >= 0 && temps[1] == 320 + 3 * row,
                "temperatures {temps:?} are not a trace row"
            );
            assert_eq!(&temps[2..4], &[-32768, -32768], "two sensors only");
            let positions = [at[0], at[1], at[2], 0, 0, 0];
            let want = predict(&model, &positions, at[3], &[Some(temps[0]), Some(temps[1])])
                .expect("the image has a section");
            let got: Vec<i64> = r["correction"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap())
                .collect();
            assert_eq!(
                got,
                want.corrections.map(i64::from).to_vec(),
                "at {at:?}, temperatures {temps:?}"
            );
            // The board's own bits beyond the core's: none (fresh PLC write, fresh sensors).
            assert_eq!(status, want.status, "at {at:?}");
            assert_eq!(r["tool_um"].as_i64().unwrap(), i64::from(want.tool_um));
            temps_seen.insert(temps[0]);
            distinct.insert(got);
            compared += 1;
        }
        if temps_seen.len() >= 4 && compared >= 24 {
            break;
        }
    }
    assert!(
        temps_seen.len() >= 4 && compared >= 24,
        "compared {compared} at temperatures {temps_seen:?}\n{}",
        board.log()
    );
    assert!(
        distinct.len() >= 10,
        "corrections really differ: {distinct:?}"
    );
}

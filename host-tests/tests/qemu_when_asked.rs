//! The board asks for references (issue 51, item 3) on the QEMU bench
//! board, driven by the real mbpoll through the README demo's PLC script
//! (`scripts/demo_references.py run --when-asked`): the PLC probes only
//! while input register 23 asks. On a synthetic trace whose model error is
//! known (served correction + 3 µm) and whose spindle changes speed twice,
//! every reference the PLC takes is one the board asked for, each
//! speed-change request comes the settling time after a change, the gap
//! between references never exceeds the interval by more than the PLC's
//! polling delay, and the served error falls well below the model's own.
use host_tests::qemu::{
    demo_references_script as script, demo_temps as temps, export_demo, one_board, BenchBoard,
};
use serde_json::Value;

const ROWS: u32 = 1500;
const ROW_S: u32 = 15;
const ERROR_UM: f64 = 3.0;
/// Holding registers 46–48: settle 15 min, interval 1 h, step 500 rpm.
const SETTLE_S: f64 = 900.0;
const INTERVAL_S: f64 = 3600.0;
/// The spindle's speed changes (trace time, s).
const CHANGES_S: [f64; 2] = [2.25 * 3600.0, 4.5 * 3600.0];

fn rpm(t: f64) -> u32 {
    match t {
        t if t < CHANGES_S[0] => 3000,
        t if t < CHANGES_S[1] => 6000,
        _ => 2000,
    }
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and mbpoll: scripts/test.sh"]
fn the_plc_probes_when_the_board_asks() {
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-asked-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (plain, measured, probe, img, report) = (
        dir.join("plain.csv"),
        dir.join("measured.csv"),
        dir.join("probe.csv"),
        dir.join("v1.img"),
        dir.join("report.json"),
    );
    let header = "time_s,spindle_rpm,T01,T02,T03,T04,T05,T06";
    let row = |i: u32| {
        let t = i * ROW_S;
        format!("{t},{}{}", rpm(f64::from(t)), temps(i))
    };
    let mut csv = format!("{header}\n");
    for i in 0..ROWS {
        csv += &format!("{}\n", row(i));
    }
    std::fs::write(&plain, csv).unwrap();
    export_demo(1, 1, &img);
    let rows = tcomp_model::replay::replay_files(&plain, &img).unwrap();
    let mut csv = format!("# a synthetic run\n{header},dch1_um\n");
    for (i, r) in rows.iter().enumerate() {
        let m = f64::from(r.out.corrections[0]) / 10.0 + ERROR_UM;
        csv += &format!("{},{m:.1}\n", row(i as u32));
    }
    std::fs::write(&measured, csv).unwrap();
    let out = script(&[
        "trace",
        measured.to_str().unwrap(),
        probe.to_str().unwrap(),
        "--column",
        "dch1_um",
        "--noise-um",
        "0",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let board = BenchBoard::serve("pty", &probe, &img, &["10"]);
    let pty = board.pty();
    let out = script(&[
        "run",
        "--pty",
        &pty,
        "--trace",
        probe.to_str().unwrap(),
        "--column",
        "dch1_um",
        "--when-asked",
        "900:3600:500",
        "--json",
        report.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}\n{}",
        String::from_utf8_lossy(&out.stderr),
        board.log()
    );
    let r: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let refs = r["references"].as_array().unwrap();
    // Every reference was asked for and accepted (no chip, no noise).
    assert!(refs.len() >= 5, "{text}");
    for x in refs {
        assert_eq!(x["result"], 0, "{x}: {text}");
    }
    let asked = |x: &Value| x["asked_at_s"].as_f64().unwrap();
    let reasons: Vec<&str> = refs.iter().map(|x| x["wanted"].as_str().unwrap()).collect();
    assert!(reasons.contains(&"speed change"), "{text}");
    assert!(reasons.contains(&"interval"), "{text}");
    // A speed-change request comes the settling time after a change; the
    // PLC sees it within its polling delay (a few rows of trace time).
    let slack = 20.0 * f64::from(ROW_S);
    for x in refs.iter().filter(|x| x["wanted"] == "speed change") {
        let t = asked(x);
        let since = CHANGES_S
            .iter()
            .filter(|&&c| c <= t)
            .map(|c| t - c)
            .fold(f64::INFINITY, f64::min);
        assert!(
            (SETTLE_S..=SETTLE_S + slack).contains(&since),
            "{x}: {text}"
        );
    }
    // Never more than the interval between references (plus the delay).
    // (The first one: the interval after the PLC set the probe direction,
    // when the board's rule started, some way into the trace.)
    for pair in refs.windows(2) {
        let gap = asked(&pair[1]) - asked(&pair[0]);
        assert!(gap <= INTERVAL_S + slack, "{}: {text}", pair[1]);
    }
    let whole = &r["figures"]["whole trace"];
    let without = whole["mae_without_um"].as_f64().unwrap();
    assert!((without - ERROR_UM).abs() < 1e-6, "{whole}");
    assert!(
        whole["mae_with_um"].as_f64().unwrap() < 0.75 * without,
        "{whole}: {text}"
    );
}

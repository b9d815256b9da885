//! The README demo's probe-reference part (`scripts/demo_references.py`,
//! which `scripts/demo.sh` runs) against the QEMU bench board with the real
//! mbpoll on a pty, on a short synthetic trace whose model error is known:
//! the measured displacement is the model's served correction + 3 µm, and
//! the probe at the gauge reads it (no noise), with a chip (+50 µm) on the
//! gauge for one hour. The script must commission the board, take hourly
//! references, see the chip refused, and report the error without
//! references as exactly the model's 3 µm and with them clearly below.
use host_tests::qemu::{
    demo_references_script as script, demo_temps as temps, export_demo, one_board, BenchBoard,
};
use serde_json::Value;

const ROWS: u32 = 1500;
const ROW_S: u32 = 15;
/// The model's error the references must learn, µm.
const ERROR_UM: f64 = 3.0;

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and mbpoll: scripts/test.sh"]
fn the_demo_reference_script_learns_a_known_model_error_over_mbpoll() {
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-demo-refs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (plain, measured, probe, img, report) = (
        dir.join("plain.csv"),
        dir.join("measured.csv"),
        dir.join("probe.csv"),
        dir.join("v1.img"),
        dir.join("report.json"),
    );
    let header = "time_s,spindle_rpm,T01,T02,T03,T04,T05,T06";
    let mut csv = format!("{header}\n");
    for i in 0..ROWS {
        csv += &format!("{},3000{}\n", i * ROW_S, temps(i));
    }
    std::fs::write(&plain, csv).unwrap();
    export_demo(1, 1, &img);
    let rows = tcomp_model::replay::replay_files(&plain, &img).unwrap();
    // The measured displacement of direction 0: its served correction + 3 µm.
    let mut csv = format!("# a synthetic run\n{header},dch1_um\n");
    for (i, r) in rows.iter().enumerate() {
        let i = i as u32;
        let m = f64::from(r.out.corrections[0]) / 10.0 + ERROR_UM;
        csv += &format!("{},3000{},{m:.1}\n", i * ROW_S, temps(i));
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
        "--chip",
        "3:1:50",
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
        "--every-s",
        "3600",
        "--split-s",
        "10800",
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

    // The references as the board reported them: the chip hour refused and
    // counted, every other one accepted with an innovation the model's error
    // (3 µm) bounds from above, within the ADC's rounding.
    let refs = r["references"].as_array().unwrap();
    let chip = |t: f64| (3.0 * 3600.0..4.0 * 3600.0).contains(&t);
    let refused: Vec<_> = refs.iter().filter(|x| x["result"] == 61).collect();
    let accepted: Vec<_> = refs.iter().filter(|x| x["result"] == 0).collect();
    assert_eq!(refused.len(), 1, "{text}");
    assert!(chip(refused[0]["asked_at_s"].as_f64().unwrap()), "{text}");
    assert!(
        refused[0]["innovation_um"].as_f64().unwrap() > 40.0,
        "{text}"
    );
    assert!(accepted.len() >= 2, "{text}");
    assert_eq!(accepted.len() + refused.len(), refs.len(), "{text}");
    let first = accepted[0]["innovation_um"].as_f64().unwrap();
    assert!(
        (first - ERROR_UM).abs() <= 0.1,
        "first innovation {first}: {text}"
    );
    for x in &accepted {
        let i = x["innovation_um"].as_f64().unwrap();
        assert!((-0.2..=ERROR_UM + 0.1).contains(&i), "{x}: {text}");
    }
    let last = refs.last().unwrap();
    assert_eq!(
        (last["accepted"].as_u64(), last["refused"].as_u64()),
        (Some(accepted.len() as u64), Some(1)),
        "{text}"
    );

    // The figures over the snapshots mbpoll read: the model alone is off by
    // exactly its error; with references the served error is far below it.
    let whole = &r["figures"]["whole trace"];
    let held = &r["figures"]["held-out"];
    assert!(whole["snapshots"].as_u64().unwrap() >= 50, "{text}");
    assert!(held["snapshots"].as_u64().unwrap() >= 10, "{text}");
    for f in [whole, held] {
        let without = f["mae_without_um"].as_f64().unwrap();
        assert!((without - ERROR_UM).abs() < 1e-6, "{f}");
        let with = f["mae_with_um"].as_f64().unwrap();
        assert!(with < 0.75 * without, "{f}: {text}");
    }
    assert!(held["mae_with_um"].as_f64().unwrap() < 1.5, "{text}");
}

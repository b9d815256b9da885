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
    demo_references_script as script, demo_temps as temps, export_demo, one_board, BenchBoard, BOOT,
};
use serde_json::Value;
use std::path::Path;
use tcomp_link::board_link::BoardLink;
use tcomp_model::reference_replay::{parse_params, score, ReferenceArgs};
use thermocomp_core::ask::AskParams;
use thermocomp_core::reference::ReferenceParams;
use thermocomp_protocol::holding::{
    result, CMD_TAKE_PROBE_REFERENCE, HR_ASK_INTERVAL, HR_ASK_SETTLE, HR_ASK_SPEED_STEP,
    HR_COMMAND, HR_PROBE_DIRECTION, HR_RESULT, HR_UNLOCK,
};
use thermocomp_protocol::registers::{IR_CORRECTIONS, IR_REF_TIME, IR_REF_WANTED, IR_SAMPLE_TIME};

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

// ---------------------------------------------------------------------------
// The board against the desktop replay (issue 51, done-when): on a trace of
// the same kind, the bench board in lockstep (the PLC probes at the sample
// after a request, as `tcomp replay --reference-when-asked` models it)
// raises input register 23 at the very samples the replay's rule raises
// it, with the same reasons; each reference is taken at the sample the
// replay takes it, and every served correction read equals the replay's
// (`--reference-dump`) bit for bit. Then a reset while a request is raised
// and a speed change is settling keeps the schedule: the request is raised
// again at the first sample after the reboot, and the speed-change request
// comes the settling time after the change, as without the reset.

/// The second test's spindle: back to the first speed at the second change,
/// so that a reboot (the trace starts again at row 0) sees the speed held.
fn rpm_back(t: f64) -> u32 {
    if (CHANGES_S[0]..CHANGES_S[1]).contains(&t) {
        6000
    } else {
        3000
    }
}

/// The model's error at the gauge (µm) at trace time `t`: an offset that
/// grows, so that the terms the references learn keep moving.
fn error_um(t: f64) -> f64 {
    ERROR_UM + 2.0 * t / f64::from(ROWS * ROW_S)
}

/// What the PLC saw on the board: the requests raised (sample time s,
/// reason), the references (the sample that raised, result, input
/// registers 300–301: time of the last accepted one), and the served
/// correction of direction 0 per sample time (0.1 µm).
#[derive(Default, Debug)]
struct Seen {
    raised: Vec<(u64, u16)>,
    references: Vec<(u64, u16, u32)>,
    served: std::collections::BTreeMap<u64, i32>,
}

fn u32_of(w: &[u16]) -> u32 {
    u32::from(w[0]) << 16 | u32::from(w[1])
}

/// Holding register 2 once it is neither "pending" (60) nor "storing" (23).
fn settled_result(link: &mut BoardLink, board: &BenchBoard) -> u16 {
    let start = std::time::Instant::now();
    loop {
        let r = link.read_holdings(HR_RESULT, 1).unwrap()[0];
        if r != result::PROBE_REFERENCE_PENDING && r != result::COMMIT_IN_PROGRESS {
            return r;
        }
        assert!(start.elapsed() < BOOT, "result {r}:\n{}", board.log());
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// Unlock, write one holding register, its settled result.
fn write(link: &mut BoardLink, board: &BenchBoard, addr: u16, v: u16) -> u16 {
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(addr, v).unwrap();
    settled_result(link, board)
}

/// The PLC of the replay: read every snapshot it can; at a sample that asks
/// (input register 23), command 12 once (the board, in lockstep, waits for
/// it and takes the reference at the next sample). Stops at the first
/// sample at or after `stop_s` (a request there is noted, not answered).
fn plc(link: &mut BoardLink, board: &BenchBoard, stop_s: u64) -> Seen {
    let mut seen = Seen::default();
    let (mut answered, mut open) = (None, false);
    let start = std::time::Instant::now();
    loop {
        assert!(start.elapsed() < BOOT * 5, "{seen:?}\n{}", board.log());
        let w = link.read_inputs(0, IR_CORRECTIONS + 2).unwrap();
        let t = u64::from(u32_of(&w[usize::from(IR_SAMPLE_TIME)..]));
        let wanted = w[usize::from(IR_REF_WANTED)];
        seen.served
            .insert(t, u32_of(&w[usize::from(IR_CORRECTIONS)..]) as i32);
        if wanted != 0 && !open {
            seen.raised.push((t, wanted));
            open = true;
        }
        if t >= stop_s {
            return seen;
        }
        if wanted == 0 || answered == Some(t) {
            continue;
        }
        answered = Some(t);
        let code = write(link, board, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
        let r = link.read_inputs(IR_REF_TIME, 2).unwrap();
        seen.references.push((t, code, u32_of(&r)));
        open = code != result::OK;
    }
}

/// The replay's schedule: `tcomp replay --reference-when-asked` (the
/// library it runs) with the PLC script's settings, its `--reference-dump`
/// read back. Requests (time s, input-register reason), references (the
/// request's time, the reference's time, accepted) and the served
/// correction per row (0.1 µm).
type Replayed = (Vec<(u64, u16)>, Vec<(u64, u64, bool)>, Vec<i32>);

fn replay_when_asked(trace: &Path, img: &Path, dump: &Path) -> Replayed {
    let mut run = tcomp_data::runcsv::Run::read_with_temperatures(trace).unwrap();
    assert_eq!(run.errors_as_rises("trace"), None, "a relative run");
    let model = thermocomp_core::Model::parse(&std::fs::read(img).unwrap()).unwrap();
    let rows = tcomp_model::replay::replay_files(trace, img).unwrap();
    // The board's rule parameters (holding registers 90–99 untouched); the
    // probe reads without noise, as the trace's own column.
    let sigma = f64::from(ReferenceParams::DEFAULT.sigma_ref_nm) / 1000.0;
    let args = ReferenceArgs {
        noise_um: 0.0,
        seed: 1,
        params: vec![format!("sigma_ref_um={sigma}")],
        dump: Some(dump.to_path_buf()),
        when_asked: Some(AskParams {
            settle_s: SETTLE_S as u16,
            max_interval_s: INTERVAL_S as u16,
            speed_step_rpm: 500,
        }),
        ..ReferenceArgs::default()
    };
    assert_eq!(
        parse_params(&args).unwrap(),
        ReferenceParams::DEFAULT,
        "the board's rule"
    );
    let report = score(&run, &rows, &model, &args, 0, rows.len()).unwrap();
    let ch = &report.channels[0];
    assert_eq!(ch.column, "dZ_um", "direction 0 of the demo model");
    let reason = |r: Option<&str>| match r {
        Some("speed_change") => 1,
        Some("interval") => 2,
        other => panic!("reason {other:?}"),
    };
    let mut raised: Vec<(u64, u16)> = ch
        .taken
        .iter()
        .map(|x| (x.asked_s.unwrap() as u64, reason(x.reason)))
        .collect();
    raised.dedup();
    assert_eq!(raised.len(), ch.asked_speed_change + ch.asked_interval);
    let taken = ch
        .taken
        .iter()
        .map(|x| (x.asked_s.unwrap() as u64, x.time_s as u64, x.accepted))
        .collect();
    let text = std::fs::read_to_string(dump).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = head.iter().position(|c| *c == "dZ_um_served").unwrap();
    let served = lines
        .map(|l| {
            let v: f64 = l.split(',').nth(col).unwrap().parse().unwrap();
            (v * 10.0).round() as i32
        })
        .collect();
    (raised, taken, served)
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn the_board_asks_when_the_replay_predicts_and_a_reset_keeps_the_schedule() {
    let started = std::time::Instant::now();
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-asked-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (plain, trace, img, dump) = (
        dir.join("plain.csv"),
        dir.join("trace.csv"),
        dir.join("v1.img"),
        dir.join("dump.csv"),
    );
    let header = "time_s,spindle_rpm,T01,T02,T03,T04,T05,T06";
    let row = |i: u32| {
        let t = i * ROW_S;
        format!("{t},{}{}", rpm_back(f64::from(t)), temps(i))
    };
    let csv: String = (0..ROWS).map(|i| row(i) + "\n").collect();
    std::fs::write(&plain, format!("{header}\n{csv}")).unwrap();
    export_demo(1, 1, &img);
    // The measured displacement at the gauge (the model's output + its
    // error) is what the probe reads: the same value in both columns.
    let rows = tcomp_model::replay::replay_files(&plain, &img).unwrap();
    let mut csv = format!("# a synthetic run\n{header},dZ_um,dprobe_um\n");
    for (i, r) in rows.iter().enumerate() {
        let t = f64::from(i as u32 * ROW_S);
        let m = f64::from(r.out.corrections[0]) / 10.0 + error_um(t);
        csv += &format!("{},{m:.1},{m:.1}\n", row(i as u32));
    }
    std::fs::write(&trace, csv).unwrap();
    let (raised, taken, served) = replay_when_asked(&trace, &img, &dump);
    // The reset comes at an interval request raised while a speed change
    // settles (the stored state holds both).
    let change = |t: u64| {
        CHANGES_S
            .iter()
            .map(|&c| c as u64)
            .find(|&c| c < t && t < c + SETTLE_S as u64)
    };
    let &(reset_s, _) = raised
        .iter()
        .find(|&&(t, why)| why == 2 && change(t).is_some())
        .expect("an interval request while a speed change settles");
    let change_s = change(reset_s).unwrap();

    let (board, port) = BenchBoard::serve_tcp(&trace, &img, &["20", "lockstep"]);
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    host_tests::commission_link(&mut link);
    // Holding registers 46–48 first, the probe direction last: the rule
    // runs from the direction on; a reset right after it starts the trace
    // and the rule together at row 0, as the replay starts them.
    for (reg, v) in [
        (HR_ASK_SETTLE, SETTLE_S as u16),
        (HR_ASK_INTERVAL, INTERVAL_S as u16),
        (HR_ASK_SPEED_STEP, 500),
        (HR_PROBE_DIRECTION, 0),
    ] {
        assert_eq!(write(&mut link, &board, reg, v), result::OK, "HR {reg}");
    }
    assert_eq!(
        link.read_inputs(IR_REF_WANTED, 1).unwrap(),
        vec![0],
        "nothing asked before the reset:\n{}",
        board.log()
    );
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(HR_COMMAND, 8).unwrap();
    board.wait_for_boots(2, BOOT);

    let seen = plc(&mut link, &board, reset_s);
    let before: Vec<_> = raised.iter().copied().filter(|r| r.0 <= reset_s).collect();
    assert_eq!(seen.raised, before, "requests (s, reason): board vs replay");
    let refs: Vec<_> = taken.iter().filter(|r| r.0 < reset_s).collect();
    assert_eq!(seen.references.len(), refs.len(), "{:?}", seen.references);
    for (&(asked, code, at), &&(r_asked, r_at, accepted)) in seen.references.iter().zip(&refs) {
        assert_eq!(asked, r_asked);
        assert!(accepted, "the replay refused the reference at {r_at} s");
        assert_eq!(
            (code, u64::from(at)),
            (result::OK, r_at),
            "asked at {asked} s"
        );
    }
    let mut compared = 0;
    for (&t, &c) in &seen.served {
        let i = (t / u64::from(ROW_S)) as usize;
        assert_eq!(c, served[i], "served at {t} s (row {i})");
        compared += 1;
    }
    let after_refs = seen
        .served
        .keys()
        .filter(|&&t| refs.first().is_some_and(|r| t >= r.1))
        .count();
    println!(
        "{} requests and {} references as the replay; {compared} served values equal ({after_refs} after the first reference)",
        seen.raised.len(),
        seen.references.len()
    );
    assert!(
        refs.len() >= 4 && after_refs >= 100,
        "{compared} {after_refs}"
    );

    // Reset with the request raised (the board holds the trace there): the
    // stored state is that of the request. The trace restarts at row 0 at
    // the held speed; the request is raised at once, and once answered the
    // speed change still settling asks `settle` after the change.
    std::thread::sleep(std::time::Duration::from_secs(2));
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(HR_COMMAND, 8).unwrap();
    board.wait_for_boots(3, BOOT);
    let settled = SETTLE_S as u64 - (reset_s - change_s);
    let row_s = u64::from(ROW_S);
    let change_due = settled.div_ceil(row_s) * row_s;
    let interval_due = change_due + row_s + INTERVAL_S as u64;
    let seen = plc(&mut link, &board, interval_due);
    assert_eq!(
        seen.raised,
        vec![(0, 2), (change_due, 1), (interval_due, 2)],
        "after the reset at {reset_s} s (change at {change_s} s): {:?}\n{}",
        seen.references,
        board.log()
    );
    assert_eq!(seen.references[0], (0, result::OK, 15));
    println!(
        "after the reset: requests {:?}; the test took {:.1} s",
        seen.raised,
        started.elapsed().as_secs_f64()
    );
}

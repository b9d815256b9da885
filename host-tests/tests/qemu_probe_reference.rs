//! Probe references on the QEMU bench board (issue 28): the PLC's command 12
//! over Modbus makes the board average its (emulated) probe at the gauge
//! and update the direction's terms by `thermocomp_core::reference`; the
//! served corrections then equal what the desktop predicts from the same
//! inputs (the host's compensator replay + the same core rule), bit for bit.
//! The state survives a reset; a reading far from the model is refused and
//! changes nothing but the refused count.
use std::time::{Duration, Instant};

use host_tests::qemu::{export_demo, one_board, BenchBoard, BOOT};
use tcomp_link::board_link::BoardLink;
use tcomp_model::replay::ReplayRow;
use thermocomp_core::reference::{ReferenceOutcome, ReferenceParams, ReferenceState};
use thermocomp_protocol::holding::{
    result, CMD_TAKE_PROBE_REFERENCE, HR_COMMAND, HR_PROBE_DIRECTION, HR_RESULT, HR_UNLOCK,
};
use thermocomp_protocol::registers::*;

const ROWS: u32 = 6000;
const ROW_S: u32 = 15;
/// Rows from here on read 80 µm off the model at the gauge (a chip on it).
const CHIP_FROM_ROW: usize = 700;

fn u32_of(w: &[u16]) -> u32 {
    u32::from(w[0]) << 16 | u32::from(w[1])
}

/// Temperatures of the trace (6 channels), one row.
fn temps(i: u32) -> String {
    (0..6)
        .map(|c| format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) * 0.002))
        .collect()
}

/// One snapshot: sample time (s) and the served corrections (0.1 µm).
fn snapshot(link: &mut BoardLink) -> (u64, [i32; 6]) {
    let w = link.read_inputs(0, 42).unwrap();
    let t = u64::from(u32_of(&w[usize::from(IR_SAMPLE_TIME)..]));
    let c = std::array::from_fn(|d| u32_of(&w[usize::from(IR_CORRECTIONS) + 2 * d..]) as i32);
    (t, c)
}

fn command(link: &mut BoardLink, code: u16) {
    host_tests::commission_link(link);
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(HR_COMMAND, code).unwrap();
}

/// HR_RESULT once it is neither "pending" (60) nor "storing" (23).
fn final_result(link: &mut BoardLink, board: &BenchBoard) -> u16 {
    let start = Instant::now();
    loop {
        let r = link.read_holdings(HR_RESULT, 1).unwrap()[0];
        if r != result::PROBE_REFERENCE_PENDING && r != result::COMMIT_IN_PROGRESS {
            return r;
        }
        assert!(start.elapsed() < BOOT, "result {r}:\n{}", board.log());
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The board's sample time reaches `t_s`.
fn wait_sample(link: &mut BoardLink, board: &BenchBoard, t_s: u64) {
    let start = Instant::now();
    while snapshot(link).0 < t_s {
        assert!(start.elapsed() < BOOT * 3, "{}", board.log());
        std::thread::sleep(Duration::from_millis(100));
    }
}

struct Expect<'a> {
    rows: &'a [ReplayRow],
    max: [i32; 6],
    params: ReferenceParams,
}

impl Expect<'_> {
    fn row(&self, t_s: u64) -> &ReplayRow {
        self.rows
            .iter()
            .find(|r| r.time_ms / 1000 == t_s)
            .unwrap_or_else(|| panic!("no row at {t_s} s"))
    }

    /// Served corrections with direction 0's state `st` (the others fresh).
    fn served(&self, st: &ReferenceState, t_s: u64) -> [i32; 6] {
        let r = self.row(t_s);
        let fresh = ReferenceState::new(&self.params);
        std::array::from_fn(|d| {
            let s = if d == 0 { st } else { &fresh };
            s.serve(&self.params, r.time_ms, r.out.corrections[d], self.max[d])
        })
    }

    /// Compare `n` snapshots from `from_s` on with the prediction.
    fn check(&self, link: &mut BoardLink, st: &ReferenceState, from_s: u64, n: usize) -> usize {
        let mut seen = std::collections::BTreeSet::new();
        let start = Instant::now();
        while seen.len() < n {
            let (t, c) = snapshot(link);
            if t >= from_s {
                assert_eq!(c, self.served(st, t), "t = {t} s");
                seen.insert(t);
            }
            assert!(start.elapsed() < BOOT, "compared only {seen:?}");
            std::thread::sleep(Duration::from_millis(30));
        }
        seen.len()
    }
}

/// Take a reference over Modbus; the board's outcome must be the core's
/// outcome on the host for the row it was taken at.
fn reference(
    link: &mut BoardLink,
    board: &BenchBoard,
    e: &Expect,
    probe: &[i32],
    st: &mut ReferenceState,
) -> (u16, u64) {
    command(link, CMD_TAKE_PROBE_REFERENCE);
    let code = final_result(link, board);
    let w = link.read_inputs(IR_REF_TIME, 6).unwrap();
    // The refused count says which reference this was; the time is the
    // last accepted one's, so a refusal is placed by the innovation.
    let accepted_t = u64::from(u32_of(&w[0..2]));
    let innovation = u32_of(&w[2..4]) as i32;
    let row_t = if code == result::OK {
        accepted_t
    } else {
        // Refused: find the row whose innovation the board reports.
        e.rows
            .iter()
            .map(|r| r.time_ms / 1000)
            .find(|&t| {
                let r = e.row(t);
                let i = (t / u64::from(ROW_S)) as usize;
                let mut s = *st;
                matches!(s.reference(&e.params, r.time_ms, r.out.corrections[0], probe[i]),
                    ReferenceOutcome::Refused { innovation: v } if v == innovation)
                    && i >= CHIP_FROM_ROW
            })
            .expect("a row with the refused innovation")
    };
    let r = e.row(row_t);
    let i = (row_t / u64::from(ROW_S)) as usize;
    let outcome = st.reference(&e.params, r.time_ms, r.out.corrections[0], probe[i]);
    let want = match outcome {
        ReferenceOutcome::Accepted { innovation, .. } => (result::OK, innovation),
        ReferenceOutcome::Refused { innovation } => (result::REFERENCE_REFUSED, innovation),
    };
    assert_eq!((code, innovation), want, "row {i}: {outcome:?}");
    assert_eq!((w[4], w[5]), (st.accepted, st.refused), "accepted, refused");
    (code, row_t)
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn probe_references_over_modbus_serve_what_the_desktop_predicts_and_survive_a_reset() {
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-qemu-probe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (plain, trace, img) = (
        dir.join("plain.csv"),
        dir.join("trace.csv"),
        dir.join("v1.img"),
    );
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..ROWS {
        csv += &format!("{},3000{}\n", i * ROW_S, temps(i));
    }
    std::fs::write(&plain, csv).unwrap();
    let bytes = export_demo(1, 1, &img);
    let model = thermocomp_core::Model::parse(&bytes).unwrap();
    let rows = tcomp_model::replay::replay_files(&plain, &img).unwrap();
    // The probe at the gauge reads direction 0's model output + 3 µm (the
    // model's error the references learn), + 80 µm more from CHIP_FROM_ROW.
    let probe: Vec<i32> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| r.out.corrections[0] + 30 + if i >= CHIP_FROM_ROW { 800 } else { 0 })
        .collect();
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06,dprobe_um\n");
    for (i, p) in probe.iter().enumerate() {
        let i32_ = i as u32;
        csv += &format!(
            "{},3000{},{:.1}\n",
            i32_ * ROW_S,
            temps(i32_),
            f64::from(*p) / 10.0
        );
    }
    std::fs::write(&trace, csv).unwrap();
    let e = Expect {
        rows: &rows,
        max: std::array::from_fn(|d| model.directions.get(d).map_or(0, |x| x.max_correction)),
        params: ReferenceParams::DEFAULT,
    };
    assert!(!model.directions.is_empty());

    let (board, port) = BenchBoard::serve_tcp(&trace, &img, &["50"]);
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    assert_eq!(
        link.read_inputs(IR_MAP_VERSION, 1).unwrap(),
        vec![thermocomp_protocol::registers::MAP_VERSION]
    );
    // No probe direction yet: command 12 is answered 63, nothing learned.
    command(&mut link, CMD_TAKE_PROBE_REFERENCE);
    assert_eq!(final_result(&mut link, &board), result::NO_PROBE_DIRECTION);
    // The probe measures direction 0 (stored with the settings).
    link.write_one(HR_UNLOCK, host_tests::TEST_UNLOCK_KEY)
        .unwrap();
    link.write_one(HR_PROBE_DIRECTION, 0).unwrap();
    assert_eq!(final_result(&mut link, &board), result::OK);

    let params = ReferenceParams::DEFAULT;
    let mut st = ReferenceState::new(&params);
    // Before any reference the board serves the model alone.
    e.check(&mut link, &st, 0, 5);
    wait_sample(&mut link, &board, 60 * u64::from(ROW_S));
    let (code, t1) = reference(&mut link, &board, &e, &probe, &mut st);
    assert_eq!(code, result::OK, "{}", board.log());
    assert!(st.bias_nm > 2_000, "{st:?}");
    e.check(&mut link, &st, t1, 10);
    // A second one later: the terms move again, as predicted.
    wait_sample(&mut link, &board, t1 + 120 * u64::from(ROW_S));
    let (code, t2) = reference(&mut link, &board, &e, &probe, &mut st);
    assert_eq!(code, result::OK);
    assert!(t2 > t1);
    e.check(&mut link, &st, t2, 10);
    // A chip on the gauge: refused, counted, the served values unchanged.
    let before = st;
    wait_sample(
        &mut link,
        &board,
        (CHIP_FROM_ROW as u64 + 5) * u64::from(ROW_S),
    );
    let (code, _) = reference(&mut link, &board, &e, &probe, &mut st);
    assert_eq!(code, result::REFERENCE_REFUSED);
    assert_eq!(
        ReferenceState {
            refused: 0,
            last_innovation_nm: 0,
            last_refused: false,
            ..st
        },
        ReferenceState {
            last_innovation_nm: 0,
            ..before
        }
    );
    let n = e.check(&mut link, &st, 0, 10);
    assert_eq!(n, 10);

    // A reset (test command 8): the trace and the board's time restart;
    // the stored state resumes with its last reference at the first cycle.
    command(&mut link, 8);
    board.wait_for_boots(2, BOOT);
    let w = link.read_inputs(IR_REF_TIME, 6).unwrap();
    assert_eq!((w[4], w[5]), (2, 1), "counts kept:\n{}", board.log());
    let mut rebased = st;
    rebased.last_ms = Some(rows[0].time_ms);
    assert_eq!(u32_of(&w[0..2]), 0, "re-based to the first cycle");
    e.check(&mut link, &rebased, 0, 10);
    assert_eq!(
        link.read_holdings(HR_PROBE_DIRECTION, 1).unwrap(),
        vec![0],
        "the probe direction is stored"
    );
}

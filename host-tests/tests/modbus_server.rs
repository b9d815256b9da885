//! The Modbus RTU server on real frames: reads, writes, the unlock rule,
//! model upload and commit, exceptions and silent discards per the spec,
//! and random frames never panic it.
use heapless::Vec as HVec;
use host_tests::modbus::{be_words, encode, frame, read, write1, write_n};
use host_tests::TEST_UNLOCK_KEY;
use proptest::prelude::*;
use thermocomp::modbus::registers::*;
use thermocomp::modbus::{Action, Server, Snapshot};
use thermocomp::state::AppState;
use thermocomp_core::float::demo_model;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;
use thermocomp_protocol::rtu::{crc16, MAX_FRAME};

struct Bench {
    server: Server,
    state: AppState,
    snap: Snapshot,
    reply: HVec<u8, MAX_FRAME>,
    now: u64,
}

impl Bench {
    fn new() -> Self {
        let mut snap = Snapshot {
            sequence: 77,
            ..Snapshot::default()
        };
        snap.corrections[0] = -123_456;
        snap.axes[0].offset = 42;
        snap.axes[0].slope = -7;
        snap.temperatures[0] = Some(centidegrees(20 * 16 + 1));
        // A commissioned board: it has its own unlock key.
        let mut state = AppState::new(17, 115_200);
        state.keys.unlock = Some(TEST_UNLOCK_KEY);
        Bench {
            server: Server::new(),
            state,
            snap,
            reply: HVec::new(),
            now: 1000,
        }
    }
    fn ask(&mut self, f: &[u8]) -> (Action, Vec<u8>) {
        let a = self
            .server
            .handle(f, self.now, &self.snap, &mut self.state, &mut self.reply);
        if !self.reply.is_empty() {
            let n = self.reply.len();
            assert_eq!(
                crc16(&self.reply[..n - 2]).to_le_bytes(),
                [self.reply[n - 2], self.reply[n - 1]],
                "reply CRC"
            );
        }
        (a, self.reply.to_vec())
    }
    fn words(&mut self, fc: u8, addr: u16, count: u16) -> Vec<u16> {
        let (_, r) = self.ask(&read(17, fc, addr, count));
        assert_eq!(r[1], fc, "reply {r:02x?}");
        r[3..r.len() - 2]
            .chunks(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    }
    fn exception_of(&mut self, f: &[u8]) -> u8 {
        let (_, r) = self.ask(f);
        assert_eq!(r.len(), 5, "a 5-byte exception reply: {r:02x?}");
        assert_eq!(r[1], f[1] | 0x80);
        r[2]
    }
}

#[test]
fn input_registers_give_the_snapshot_with_high_word_first() {
    let mut b = Bench::new();
    let w = b.words(4, 0, 4);
    assert_eq!(w, vec![0x1234, 0x5678, MAP_VERSION, b.snap.status]);
    let c = b.words(4, IR_CORRECTIONS, 2);
    assert_eq!(((u32::from(c[0]) << 16) | u32::from(c[1])) as i32, -123_456);
    let axis = b.words(4, IR_AXES, AXIS_BLOCK);
    assert_eq!(
        axis,
        vec![0, 42, 0xFFFF, 0xFFF9, 0, 0, 0, 77],
        "offset, slope, ref, sequence"
    );
    let t = b.words(4, IR_TEMPERATURES, 2);
    assert_eq!(
        t,
        vec![2006, NOT_AVAILABLE],
        "20.0625 °C -> 2006 (0.01 °C), then n/a"
    );
    // The whole map reads in one request of up to 125 registers.
    assert_eq!(b.words(4, IR_LAST + 1 - 125, 125).len(), 125);
}

#[test]
fn bad_frames_are_silent_and_the_next_good_one_is_answered() {
    let mut b = Bench::new();
    let mut f = read(17, 4, 0, 2);
    f[3] ^= 1; // CRC now wrong
    assert_eq!(b.ask(&f).1, Vec::<u8>::new());
    assert_eq!(b.ask(&f[..5]).1, Vec::<u8>::new(), "truncated");
    assert_eq!(b.ask(&[0u8; 300]).1, Vec::<u8>::new(), "oversize");
    assert_eq!(
        b.ask(&read(18, 4, 0, 2)).1,
        Vec::<u8>::new(),
        "another unit"
    );
    assert_eq!(
        b.ask(&read(0, 4, 0, 2)).1,
        Vec::<u8>::new(),
        "broadcast read"
    );
    assert_eq!(b.words(4, 0, 2), vec![0x1234, 0x5678]);
    assert_eq!(
        b.server.counters().crc_errors,
        2,
        "the corrupted and the truncated frame"
    );
}

#[test]
fn exceptions_follow_the_specification() {
    let mut b = Bench::new();
    assert_eq!(
        b.exception_of(&frame(&[17, 0x2B, 0, 0])),
        0x01,
        "unknown function"
    );
    assert_eq!(
        b.exception_of(&frame(&[17, 0x84, 0, 0])),
        0x01,
        "function code with the high bit"
    );
    assert_eq!(
        b.exception_of(&read(17, 1, 0, 8)),
        0x01,
        "coils are not served"
    );
    assert_eq!(b.exception_of(&read(17, 4, 0, 0)), 0x03, "count 0");
    assert_eq!(
        b.exception_of(&read(17, 4, 0, 126)),
        0x03,
        "count above 125"
    );
    assert_eq!(
        b.exception_of(&read(17, 4, IR_LAST, 2)),
        0x02,
        "past the map"
    );
    assert_eq!(
        b.exception_of(&read(17, 3, 9000, 1)),
        0x02,
        "holding past the map"
    );
    assert_eq!(
        b.exception_of(&write1(17, HR_RESULT, 0)),
        0x02,
        "read-only register"
    );
    assert_eq!(b.exception_of(&write1(17, HR_UNIT, 5)), 0x01, "locked");
    let mut bad_count = write_n(17, HR_POSITIONS, &[1, 2]);
    bad_count[6] = 3; // byte count disagrees
    let n = bad_count.len();
    let crc = crc16(&bad_count[..n - 2]).to_le_bytes();
    bad_count[n - 2..].copy_from_slice(&crc);
    assert_eq!(b.exception_of(&bad_count), 0x03);
}

/// An FC16 header with any register count and a byte count that matches the
/// frame (the data bytes that follow), so only the count can be wrong.
fn write_n_raw(unit: u8, addr: u16, count: u16, data: &[u8]) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let [c, d] = count.to_be_bytes();
    let mut body = vec![unit, 0x10, a, b, c, d, data.len() as u8];
    body.extend_from_slice(data);
    frame(&body)
}

#[test]
fn fc16_with_count_zero_is_exception_03_and_writes_nothing() {
    let mut b = Bench::new();
    for addr in [HR_POSITIONS, HR_SPINDLE, 9000] {
        assert_eq!(
            b.exception_of(&write_n_raw(17, addr, 0, &[])),
            0x03,
            "count 0 at {addr}"
        );
    }
    assert_eq!(
        b.state.plc.written_ms, None,
        "nothing was written, so the PLC inputs stay stale"
    );
    // Broadcast: no reply, and still nothing written.
    assert!(b.ask(&write_n_raw(0, HR_POSITIONS, 0, &[])).1.is_empty());
    assert_eq!(b.state.plc.written_ms, None);
}

#[test]
fn fc16_count_of_0x8000_or_more_is_refused_without_overflow() {
    let mut b = Bench::new();
    // 0x8000 * 2 and 0x8001 * 2 wrap to the byte counts 0 and 2 in a u16.
    assert_eq!(
        b.exception_of(&write_n_raw(17, HR_SPINDLE, 0x8000, &[])),
        0x03
    );
    assert_eq!(
        b.exception_of(&write_n_raw(17, HR_SPINDLE, 0x8001, &[0x12, 0x34])),
        0x03
    );
    assert_eq!(b.state.plc.spindle_rpm, 0);
    assert_eq!(b.state.plc.written_ms, None);
}

#[test]
fn plc_writes_positions_and_speed_without_unlock() {
    let mut b = Bench::new();
    let (a, r) = b.ask(&write_n(17, HR_SPINDLE, &[6000, 0xFFFF, 0xFC18]));
    assert_eq!(a, Action::None);
    assert_eq!(r.len(), 8, "FC16 echo reply");
    assert_eq!(b.state.plc.spindle_rpm, 6000);
    assert_eq!(b.state.plc.positions[0], -1000);
    assert_eq!(b.state.plc.written_ms, Some(1000));
    // Broadcast write: done, no reply.
    let (_, r) = b.ask(&write1(0, HR_SPINDLE, 1200));
    assert!(r.is_empty());
    assert_eq!(b.state.plc.spindle_rpm, 1200);
}

#[test]
fn unlock_then_configure_and_the_lock_expires() {
    let mut b = Bench::new();
    assert_eq!(b.exception_of(&write1(17, HR_UNLOCK, 0x1111)), 0x03);
    assert_eq!(
        b.exception_of(&write1(17, HR_CLAMP, 100)),
        0x01,
        "wrong code keeps it locked"
    );
    b.now += UNLOCK_HOLDOFF_MS;
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    assert_eq!(b.words(3, HR_UNLOCK, 1), vec![1]);
    assert_eq!(b.ask(&write1(17, HR_CLAMP, 100)).0, Action::LimitsChanged);
    assert_eq!(
        b.exception_of(&write1(17, HR_BAUD, 1234)),
        0x03,
        "no such baud rate"
    );
    assert_eq!(b.words(3, HR_UNLOCK, 1), vec![0], "a refusal locks");
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    assert_eq!(b.ask(&write1(17, HR_BAUD, 96)).0, Action::LinkChanged);
    assert_eq!(b.state.settings.baud, 9600);
    b.now += UNLOCK_MS;
    assert_eq!(b.exception_of(&write1(17, HR_CLAMP, 50)), 0x01, "expired");
    assert_eq!(b.state.settings.clamp[0], 100);
}

#[test]
fn a_broadcast_never_unlocks_changes_the_link_or_runs_a_command() {
    let mut b = Bench::new();
    // Unlock by broadcast: refused (every board on the bus would open at once).
    assert!(b.ask(&write1(0, HR_UNLOCK, TEST_UNLOCK_KEY)).1.is_empty());
    assert!(!b.server.unlocked(b.now), "broadcast unlocked");
    assert!(b
        .ask(&write_n(0, HR_UNLOCK, &[TEST_UNLOCK_KEY]))
        .1
        .is_empty());
    assert!(!b.server.unlocked(b.now), "FC16 broadcast unlocked");
    // Even while this board is unlocked by its own address, a broadcast does
    // not change its unit, baud, limits or staging area, nor run a command.
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    assert!(b.server.unlocked(b.now));
    for (addr, value) in [
        (HR_UNIT, 5),
        (HR_BAUD, 96),
        (HR_CLAMP, 10),
        (HR_RATE, 10),
        (HR_STAGED_LEN, 4),
        (HR_STAGING, 0xBEEF),
        (HR_COMMAND, CMD_LOCK),
        (HR_COMMAND, CMD_REREFERENCE),
    ] {
        let (action, reply) = b.ask(&write1(0, addr, value));
        assert!(reply.is_empty());
        assert_eq!(action, Action::None, "broadcast write of {addr}");
    }
    let (action, _) = b.ask(&write_n(0, HR_UNIT, &[5, 96]));
    assert_eq!(action, Action::None);
    let h = &b.state.settings;
    assert_eq!((h.unit, h.baud), (17, 115_200));
    assert_eq!((h.clamp[0], h.rate[0]), (u16::MAX, u16::MAX));
    assert!(
        b.server.unlocked(b.now),
        "a broadcast lock command was carried out"
    );
    assert_eq!(b.words(3, HR_STAGED_LEN, 1), vec![0]);
    assert_eq!(b.words(3, HR_STAGING, 1), vec![0]);
    // The PLC's registers still take broadcasts (one speed for every board).
    b.ask(&write_n(0, HR_SPINDLE, &[3000, 0, 7]));
    assert_eq!(b.state.plc.spindle_rpm, 3000);
    assert_eq!(b.state.plc.positions[0], 7);
}

#[test]
fn a_broadcast_commit_does_not_commit_a_valid_staged_model() {
    let (mut m, _) = demo_model(3).quantize().unwrap();
    let mut img = vec![0u8; m.encoded_len()];
    m.encode(&mut img).unwrap();
    let mut b = Bench::new();
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    upload(&mut b, &img);
    let (action, reply) = b.ask(&write1(0, HR_COMMAND, CMD_COMMIT_MODEL));
    assert!(reply.is_empty());
    assert_eq!(action, Action::None);
    assert_eq!(b.words(3, HR_RESULT, 1), vec![result::NONE]);
    // The same image committed by address goes through.
    let (action, _) = b.ask(&write1(17, HR_COMMAND, CMD_COMMIT_MODEL));
    assert_eq!(action, Action::CommitModel { len: img.len() });
}

#[test]
fn a_wrong_unlock_key_answers_exception_03_and_changes_nothing() {
    let mut b = Bench::new();
    for key in [0x0000, 0x1111, TEST_UNLOCK_KEY ^ 1, 0xFFFF] {
        assert_eq!(
            b.exception_of(&write1(17, HR_UNLOCK, key)),
            0x03,
            "FC06 {key:#x}"
        );
        assert_eq!(
            b.exception_of(&write_n(17, HR_UNLOCK, &[key])),
            0x03,
            "FC16 {key:#x}"
        );
        assert!(!b.server.unlocked(b.now));
    }
    // Even the right key waits out the hold-off after a wrong one.
    assert_eq!(
        b.exception_of(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY)),
        0x03,
        "hold-off"
    );
    b.now += UNLOCK_HOLDOFF_MS;
    // The right key is echoed; a wrong one afterwards is refused and locks
    // the board (every refusal does: a guessing master gains nothing).
    assert_eq!(
        b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY)).1,
        write1(17, HR_UNLOCK, TEST_UNLOCK_KEY)
    );
    assert_eq!(b.exception_of(&write1(17, HR_UNLOCK, 0x1111)), 0x03);
    assert!(!b.server.unlocked(b.now));
}

/// Every refused write to this unit locks the board, whatever refused it
/// and whichever master sent it (the lock is the board's: no sessions).
#[test]
fn every_refused_write_locks_the_board() {
    let img = encoded(demo_model(3).quantize().unwrap().0);
    let mut corrupt = img.clone();
    corrupt[40] ^= 0xFF;
    let mut bad_count = write_n(17, HR_CLAMP, &[1, 2]);
    bad_count[6] = 3;
    let n = bad_count.len();
    let crc = crc16(&bad_count[..n - 2]).to_le_bytes();
    bad_count[n - 2..].copy_from_slice(&crc);
    // (what to send once unlocked, the exception it gets)
    let refusals: Vec<(&str, Refusal<'_>, u8)> = vec![
        (
            "bad CRC image",
            Box::new(|b: &mut Bench| {
                upload(b, &corrupt);
                write1(17, HR_COMMAND, CMD_COMMIT_MODEL)
            }),
            0x04,
        ),
        (
            "staged length 0",
            Box::new(|b: &mut Bench| {
                upload(b, &img);
                b.ask(&write1(17, HR_STAGED_LEN, 0));
                write1(17, HR_COMMAND, CMD_COMMIT_MODEL)
            }),
            0x04,
        ),
        (
            "staged length too long for the image",
            Box::new(|b: &mut Bench| {
                upload(b, &img);
                b.ask(&write1(17, HR_STAGED_LEN, (img.len() + 2) as u16));
                write1(17, HR_COMMAND, CMD_COMMIT_MODEL)
            }),
            0x04,
        ),
        (
            "staged length above the staging area",
            Box::new(|_: &mut Bench| write1(17, HR_STAGED_LEN, 9000)),
            0x03,
        ),
        (
            "wrong key",
            Box::new(|_: &mut Bench| write1(17, HR_UNLOCK, 0x1234)),
            0x03,
        ),
        (
            "unit out of range",
            Box::new(|_: &mut Bench| write1(17, HR_UNIT, 300)),
            0x03,
        ),
        (
            "read-only register",
            Box::new(|_: &mut Bench| write1(17, HR_RESULT, 0)),
            0x02,
        ),
        (
            "unknown command",
            Box::new(|_: &mut Bench| write1(17, HR_COMMAND, 999)),
            0x03,
        ),
        (
            "byte count disagrees",
            Box::new(move |_: &mut Bench| bad_count.clone()),
            0x03,
        ),
        (
            "coil write",
            Box::new(|_: &mut Bench| frame(&[17, 5, 0, 0, 0xFF, 0])),
            0x01,
        ),
    ];
    for (what, request, code) in &refusals {
        let mut b = Bench::new();
        b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
        let req = request(&mut b);
        assert!(b.server.unlocked(b.now), "{what}: unlocked before");
        assert_eq!(b.exception_of(&req), *code, "{what}");
        assert!(!b.server.unlocked(b.now), "{what}: still unlocked");
        assert_eq!(b.words(3, HR_UNLOCK, 1), vec![0], "{what}");
        assert_eq!(
            b.exception_of(&write1(17, HR_CLAMP, 100)),
            0x01,
            "{what}: a protected write after it"
        );
    }
    // A refused read does not lock; a broadcast refusal does not either (a
    // broadcast never runs a command, the lock included).
    let mut b = Bench::new();
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    assert_eq!(b.exception_of(&read(17, 3, 9000, 1)), 0x02);
    assert!(b.ask(&write1(0, HR_UNIT, 5)).1.is_empty());
    assert!(b.server.unlocked(b.now));
    // Busy (06) asks the master to send the same request again later: it
    // does not lock, so the retransmission goes through.
    b.state.busy = true;
    assert_eq!(b.exception_of(&write1(17, HR_UNIT, 5)), 0x06);
    assert!(b.server.unlocked(b.now));
    b.state.busy = false;
    assert_eq!(b.ask(&write1(17, HR_UNIT, 5)).0, Action::LinkChanged);
    // A new board (a reset) starts locked; the unlock times out.
    assert!(!Bench::new().server.unlocked(0));
    b.now += UNLOCK_MS;
    assert!(!b.server.unlocked(b.now));
}

fn upload(b: &mut Bench, image: &[u8]) {
    for (i, chunk) in be_words(image).chunks(100).enumerate() {
        let (_, r) = b.ask(&write_n(17, HR_STAGING + (i * 100) as u16, chunk));
        assert_eq!(r[1], 0x10, "{r:02x?}");
    }
    b.ask(&write1(17, HR_STAGED_LEN, image.len() as u16));
}

#[test]
fn model_upload_commits_only_a_valid_image() {
    let (mut m, _) = demo_model(3).quantize().unwrap();
    let mut img = vec![0u8; m.encoded_len()];
    m.encode(&mut img).unwrap();
    let mut b = Bench::new();
    // Locked: staging writes refused.
    assert_eq!(b.exception_of(&write_n(17, HR_STAGING, &[1, 2])), 0x01);
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    let mut corrupt = img.clone();
    corrupt[40] ^= 0xFF;
    upload(&mut b, &corrupt);
    assert_eq!(
        b.exception_of(&write1(17, HR_COMMAND, CMD_COMMIT_MODEL)),
        0x04
    );
    assert_eq!(b.words(3, HR_RESULT, 1), vec![result::BAD_CRC]);
    assert_eq!(b.words(3, HR_UNLOCK, 1), vec![0], "a refused commit locks");
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    upload(&mut b, &img);
    assert_eq!(
        b.words(3, HR_STAGING, 2),
        vec![
            u16::from_be_bytes([img[0], img[1]]),
            u16::from_be_bytes([img[2], img[3]])
        ]
    );
    let (a, r) = b.ask(&write1(17, HR_COMMAND, CMD_COMMIT_MODEL));
    assert_eq!(r.len(), 8);
    assert_eq!(a, Action::CommitModel { len: img.len() });
    assert_eq!(b.state.staging.staged(), &img[..]);
    assert_eq!(b.words(3, HR_UNLOCK, 1), vec![0], "a commit locks again");
}

/// Stage `image` (padded to whole registers) with `staged_len`, then send `command`.
fn stage_and_send(b: &mut Bench, image: &[u8], staged_len: usize, command: u16) -> Vec<u8> {
    b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
    b.ask(&write1(17, HR_COMMAND, CMD_CLEAR_STAGING));
    upload(b, image);
    b.ask(&write1(17, HR_STAGED_LEN, staged_len as u16));
    b.ask(&write1(17, HR_COMMAND, command)).1
}

fn encoded(mut m: thermocomp_core::Model) -> Vec<u8> {
    encode(&mut m)
}

#[test]
fn each_image_refusal_has_its_own_result_code() {
    let (good, _) = demo_model(3).quantize().unwrap();
    let with = |edit: &dyn Fn(&mut thermocomp_core::Model)| {
        let mut m = good.clone();
        edit(&mut m);
        encoded(m)
    };
    let mut corrupt = encoded(good.clone());
    corrupt[40] ^= 0xFF;
    let mut heavy = good.clone();
    for t in heavy.tables.iter_mut().filter(|t| t.axis == 0) {
        for term in t.terms.iter_mut() {
            term.coef = i32::MAX;
            term.position_power = 3;
        }
        while t.terms.len() < thermocomp_core::MAX_TERMS {
            let last = *t.terms.last().unwrap();
            t.terms.push(last).unwrap();
        }
    }
    while heavy.tables.len() < thermocomp_core::MAX_TABLES {
        let axis_table = heavy.tables.iter().find(|t| t.axis == 0).unwrap().clone();
        heavy.tables.push(axis_table).unwrap();
    }
    let cases: Vec<(&str, Vec<u8>, usize, u16)> = vec![
        ("bad CRC", corrupt.clone(), corrupt.len(), result::BAD_CRC),
        (
            "sensor channel 99",
            with(&|m| m.sensors[1].channel = 99),
            0,
            result::SENSOR_CHANNEL,
        ),
        (
            "model version 0",
            with(&|m| m.model_version = 0),
            0,
            result::ZERO_MODEL_VERSION,
        ),
        (
            "max_rate 0",
            with(&|m| m.directions[0].max_rate = 0),
            0,
            result::MAX_RATE,
        ),
        (
            "max_correction 0x7fffffff",
            with(&|m| m.directions[0].max_correction = i32::MAX),
            0,
            result::MAX_CORRECTION,
        ),
        (
            "overflowing tables",
            encoded(heavy),
            0,
            result::TABLE_SUM_TOO_LARGE,
        ),
    ];
    let mut seen = vec![];
    for (what, img, staged, code) in cases {
        let mut b = Bench::new();
        let staged = if staged == 0 { img.len() } else { staged };
        let r = stage_and_send(&mut b, &img, staged, CMD_COMMIT_MODEL);
        assert_eq!(&r[1..3], &[0x86, 0x04], "{what}: {r:02x?}");
        assert_eq!(b.words(3, HR_RESULT, 1), vec![code], "{what}");
        seen.push(code);
    }
    // Trailing garbage after a valid sealed image.
    let img = encoded(good.clone());
    let mut tail = img.clone();
    tail.extend_from_slice(&[0xAB, 0xCD]);
    let mut b = Bench::new();
    let r = stage_and_send(&mut b, &tail, tail.len(), CMD_COMMIT_MODEL);
    assert_eq!(&r[1..3], &[0x86, 0x04], "{r:02x?}");
    assert_eq!(b.words(3, HR_RESULT, 1), vec![result::TRAILING_BYTES]);
    seen.push(result::TRAILING_BYTES);
    seen.extend([
        result::OK,
        result::NONE,
        result::BAD_LENGTH,
        result::STORE_FAILED,
    ]);
    seen.push(result::NOT_NEWER);
    let mut distinct = seen.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), seen.len(), "codes not distinct: {seen:?}");
    // Every ImageError maps to a named code other than OK/NONE.
    for e in [
        thermocomp_core::ImageError::BadMagic,
        thermocomp_core::ImageError::LengthMismatch,
        thermocomp_core::ImageError::UnsupportedVersion(2),
    ] {
        let code = result::of_image_error(&e);
        assert!(!matches!(code, result::OK | result::NONE), "{e}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5000))]
    #[test]
    fn random_frames_never_panic(body in proptest::collection::vec(any::<u8>(), 0..260), fix_crc in any::<bool>(), unit in prop_oneof![Just(17u8), Just(0u8), any::<u8>()]) {
        let mut b = Bench::new();
        b.ask(&write1(17, HR_UNLOCK, TEST_UNLOCK_KEY));
        let mut f = body.clone();
        if !f.is_empty() { f[0] = unit; }
        if fix_crc && f.len() >= 2 { f = frame(&f[..f.len() - 2]); }
        let (_, r) = b.ask(&f);
        prop_assert!(r.len() <= MAX_FRAME);
        if !r.is_empty() { prop_assert_eq!(r[0], 17); }
    }

    /// FC16 headers of every count with a frame-consistent byte count: the
    /// count is checked without overflow, and a wrong count writes nothing.
    #[test]
    fn fc16_of_any_count_never_panics_and_a_wrong_count_writes_nothing(count in any::<u16>(), data in proptest::collection::vec(any::<u8>(), 0..=247)) {
        let mut b = Bench::new();
        let (_, r) = b.ask(&write_n_raw(17, HR_SPINDLE, count, &data));
        prop_assert!(!r.is_empty());
        let valid = (1..=123).contains(&count) && usize::from(count) * 2 == data.len();
        if !valid {
            prop_assert_eq!(&r[1..3], &[0x90u8, 0x03][..]);
            prop_assert_eq!(b.state.plc.written_ms, None);
        }
    }
}

/// A request that a locked-after board must refuse: builds and sends it, returns the reply.
type Refusal<'a> = Box<dyn Fn(&mut Bench) -> Vec<u8> + 'a>;

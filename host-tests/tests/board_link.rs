//! tcomp's Modbus master (record, upload) against the board's real server
//! code: in-process over a socket, and the firmware under QEMU.
use std::io::{Read, Write};
use std::net::TcpListener;
use std::time::Duration;

use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{answer, blank_app, frame, rtu_socket, Reply};
use host_tests::qemu::{export_demo, warming_trace, BenchBoard};
use std::sync::{Arc, Mutex};
use tcomp_link::board_link::{record, upload, BoardLink, Commit};
use thermocomp::app::App;
use thermocomp::modbus::{Server, Snapshot};
use thermocomp::state::AppState;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::rtu::crc16;

/// The board's frame handler behind a TCP socket (one client), in a thread.
fn fake_board(answer: bool) -> String {
    let mut server = Server::new();
    let mut state = AppState::new(1, 115_200);
    let snap = Snapshot {
        sequence: 9,
        ..Snapshot::default()
    };
    let mut reply = Reply::new();
    rtu_socket(move |req| {
        server.handle(req, 0, &snap, &mut state, &mut reply);
        if answer {
            reply.to_vec()
        } else {
            vec![]
        }
    })
}

#[test]
fn reads_writes_and_exceptions_round_trip_through_the_real_server() {
    let mut link = BoardLink::tcp(&fake_board(true), 1).unwrap();
    assert_eq!(link.read_inputs(0, 2).unwrap(), vec![0x1234, 0x5678]);
    assert_eq!(link.read_inputs(4, 2).unwrap(), vec![0, 9]);
    link.write_one(5, 1500).unwrap();
    assert_eq!(link.read_holdings(5, 1).unwrap(), vec![1500]);
    let e = link.write_one(3, 7).unwrap_err().to_string();
    assert!(e.contains("exception 01"), "{e}");
    let e = link.read_inputs(400, 1).unwrap_err().to_string();
    assert!(e.contains("exception 02"), "{e}");
    let e = upload(
        &mut link,
        b"not an image",
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("not valid, not sent"), "{e}");
}

/// The board's application (server, model store on a mock flash) behind a
/// socket, its state shared with the test: every request is logged, and
/// request number `fault_at` (0-based) gets exception 04 instead of being
/// carried out (a board failing mid-upload).
struct SharedBoard {
    app: App<MockFlash>,
    requests: Vec<Vec<u8>>,
    fault_at: Option<usize>,
}

fn inspectable_board(
    running: Option<&[u8]>,
    fault_at: Option<usize>,
) -> (String, Arc<Mutex<SharedBoard>>) {
    let mut app = blank_app();
    host_tests::commission(&mut app);
    if let Some(image) = running {
        app.program(image).unwrap();
    }
    let board = Arc::new(Mutex::new(SharedBoard {
        app,
        requests: vec![],
        fault_at,
    }));
    let shared = board.clone();
    let addr = rtu_socket(move |req| {
        let mut b = shared.lock().unwrap();
        let k = b.requests.len();
        b.requests.push(req.to_vec());
        if b.fault_at == Some(k) {
            frame(&[req[0], req[1] | 0x80, 4])
        } else {
            answer(&mut b.app, req)
        }
    });
    (addr, board)
}

fn unlocked(board: &Arc<Mutex<SharedBoard>>) -> bool {
    board.lock().unwrap().app.unlocked(0)
}

fn demo_image_bytes(version: u32) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(u64::from(version));
    fm.model_version = version;
    let (mut m, _) = fm.quantize().unwrap();
    let mut b = vec![0u8; m.encoded_len()];
    m.encode(&mut b).unwrap();
    b
}

#[test]
fn an_image_larger_than_the_staging_area_is_refused_before_anything_is_sent() {
    let (addr, board) = inspectable_board(None, None);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    // A valid image followed by padding up to beyond the staging area.
    let mut big = demo_image_bytes(2);
    big.resize(STAGING_REGS as usize * 2 + 2, 0);
    let e = upload(
        &mut link,
        &big,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("staging area"), "{e}");
    assert!(board.lock().unwrap().requests.is_empty(), "nothing sent");
}

#[test]
fn a_failed_upload_relocks_the_board() {
    let image = demo_image_bytes(2);
    // The map check is request 0, the key state 1, the channel states 2
    // (the sensor check), unlock 3, staging 4.., then the length and the
    // commit: fail each write after the unlock in turn; the board must end
    // locked and keep its staging from being committed by anyone else.
    let n_staging = (image.len().div_ceil(2)).div_ceil(100);
    for fault_at in 4..=n_staging + 5 {
        let (addr, board) = inspectable_board(None, Some(fault_at));
        let mut link = BoardLink::tcp(&addr, 1).unwrap();
        let e = format!(
            "{:#}",
            upload(
                &mut link,
                &image,
                &host_tests::upload_opts(Commit::NewerOnly, true)
            )
            .unwrap_err()
        );
        assert!(e.contains("exception 04"), "{e}");
        assert!(
            !unlocked(&board),
            "unlocked after a failure at request {fault_at}: {e}"
        );
        let b = board.lock().unwrap();
        let last = b.requests.last().unwrap();
        assert_eq!(
            &last[1..6],
            &[6, 0, HR_COMMAND as u8, 0, CMD_LOCK as u8],
            "relock sent last"
        );
        assert_eq!(b.app.model_version(), 0, "nothing committed");
    }
}

#[test]
fn a_refused_commit_names_the_reason_and_relocks_and_rollback_commits() {
    // The board runs version 5: version 2 is not newer.
    let (addr, board) = inspectable_board(Some(&demo_image_bytes(5)), None);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let image = demo_image_bytes(2);
    let e = format!(
        "{:#}",
        upload(
            &mut link,
            &image,
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap_err()
    );
    assert!(e.contains("NOT_NEWER") && e.contains("--rollback"), "{e}");
    assert!(!unlocked(&board));
    assert_eq!(board.lock().unwrap().app.model_version(), 5);
    // The rollback commits it on purpose.
    let s = upload(
        &mut link,
        &image,
        &host_tests::upload_opts(Commit::Rollback, true),
    )
    .unwrap();
    assert_eq!(s.model_version, 2);
    assert_eq!(s.result, result::OK);
    assert!(!unlocked(&board));
    assert_eq!(board.lock().unwrap().app.model_version(), 2);
}

#[test]
fn a_silent_board_is_a_clear_error_after_the_retries() {
    let mut link = BoardLink::tcp(&fake_board(false), 1)
        .unwrap()
        .with_timeout(Duration::from_millis(300));
    let t = std::time::Instant::now();
    let e = format!("{:#}", link.read_inputs(0, 2).unwrap_err());
    assert!(
        e.contains("no valid reply after 3 tries") && e.contains("timeout"),
        "{e}"
    );
    assert!(
        t.elapsed() >= Duration::from_millis(900),
        "three 300 ms timeouts"
    );
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn upload_and_record_against_the_bench_board() {
    let dir = std::env::temp_dir().join(format!("thermocomp-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (trace, v1, v2) = (
        dir.join("trace.csv"),
        dir.join("v1.img"),
        dir.join("v2.img"),
    );
    warming_trace(&trace, 3000, 0.01);
    for (v, p) in [(1u32, &v1), (2, &v2)] {
        export_demo(u64::from(v), v, p);
    }
    let (board, port) = BenchBoard::serve_tcp(&trace, &v1, &["50"]);
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    host_tests::commission_link(&mut link);
    let opts = host_tests::upload_opts(Commit::NewerOnly, false);
    let s = upload(&mut link, &std::fs::read(&v2).unwrap(), &opts).unwrap();
    assert_eq!(s.model_version, 2);
    // Record five samples, then two more appended to the same file.
    let out = dir.join("recorded.csv");
    record(&mut link, &out, Duration::from_millis(300), 5, false).unwrap();
    record(&mut link, &out, Duration::from_millis(300), 2, true).unwrap();
    let run = tcomp_data::runcsv::Run::read(&out).unwrap();
    assert_eq!(run.rows(), 7, "5 + 2 appended");
    assert_eq!(run.meta("board_model_version"), Some("2"));
    assert!(run.col("T06").unwrap().iter().all(|v| v.is_some()));
    let times = run.col("time_s").unwrap();
    assert!(
        times.windows(2).all(|w| w[1].unwrap() > w[0].unwrap()),
        "time increases across the append"
    );
    assert!(
        run.col("comp_d0_um")
            .unwrap()
            .iter()
            .any(|v| v.unwrap() != 0.0),
        "{}",
        board.log()
    );
}

/// A device that answers every FC04 read with `regs` from address 0 (and
/// logs how many requests it saw): an older board, or not a board at all.
fn fixed_input_device(regs: Vec<u16>) -> (String, Arc<Mutex<usize>>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    let seen = Arc::new(Mutex::new(0usize));
    let log = seen.clone();
    std::thread::spawn(move || {
        let (mut s, _) = l.accept().unwrap();
        let mut req = [0u8; 8];
        while s.read_exact(&mut req).is_ok() {
            *log.lock().unwrap() += 1;
            let (start, count) = (
                usize::from(u16::from_be_bytes([req[2], req[3]])),
                usize::from(u16::from_be_bytes([req[4], req[5]])),
            );
            let mut reply = vec![req[0], 4, (2 * count) as u8];
            for a in start..start + count {
                reply.extend(regs.get(a).copied().unwrap_or(0).to_be_bytes());
            }
            let crc = crc16(&reply);
            reply.extend(crc.to_le_bytes());
            s.write_all(&reply).unwrap();
        }
    });
    (addr, seen)
}

#[test]
fn upload_refuses_a_board_with_an_older_register_map_or_no_test_pattern() {
    use thermocomp_protocol::registers::MAP_VERSION;
    let image = demo_image_bytes(2);
    let (addr, seen) = fixed_input_device(vec![0x1234, 0x5678, MAP_VERSION - 1]);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let e = format!(
        "{:#}",
        upload(
            &mut link,
            &image,
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap_err()
    );
    assert!(
        e.contains(&format!("register map version {}", MAP_VERSION - 1)) && e.contains("not sent"),
        "{e}"
    );
    assert_eq!(*seen.lock().unwrap(), 1, "only the identification was read");
    let (addr, _) = fixed_input_device(vec![0x5678, 0x1234, MAP_VERSION]);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let e = format!(
        "{:#}",
        upload(
            &mut link,
            &image,
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap_err()
    );
    assert!(e.contains("0x56781234") && e.contains("word order"), "{e}");
    // the board's own server serves the current version: accepted
    let (addr, board) = inspectable_board(None, None);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    upload(
        &mut link,
        &image,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap();
    assert_eq!(board.lock().unwrap().app.model_version(), 2);
}

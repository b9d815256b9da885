//! tcomp's Modbus master (record, upload) against the board's real server
//! code: in-process over a socket, and the firmware under QEMU.
use std::io::{Read, Write};
use std::net::TcpListener;
use std::time::Duration;

use host_tests::qemu::{free_tcp_port, BenchBoard};
use tcomp::board_link::{record, upload, BoardLink};
use thermocomp::modbus::server::{expected_request_len, MAX_FRAME};
use thermocomp::modbus::{Server, Snapshot};

/// The board's frame handler behind a TCP socket (one client), in a thread.
fn fake_board(answer: bool) -> String {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        let (mut s, _) = l.accept().unwrap();
        let mut server = Server::new(1, 115_200);
        let snap = Snapshot {
            sequence: 9,
            ..Snapshot::default()
        };
        let mut reply = heapless::Vec::<u8, MAX_FRAME>::new();
        let mut buf = Vec::new();
        let mut byte = [0u8; 1];
        while s.read_exact(&mut byte).is_ok() {
            buf.push(byte[0]);
            if expected_request_len(&buf).is_some_and(|n| buf.len() >= n) {
                server.handle(&buf, 0, &snap, &mut reply);
                if answer && !reply.is_empty() {
                    s.write_all(&reply).unwrap();
                }
                buf.clear();
            }
        }
    });
    addr
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
    let e = upload(&mut link, b"not an image").unwrap_err().to_string();
    assert!(e.contains("not valid, not sent"), "{e}");
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
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..3000 {
        csv += &format!("{},3000", i * 15);
        for c in 0..6 {
            csv += &format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) * 0.01);
        }
        csv += "\n";
    }
    std::fs::write(&trace, csv).unwrap();
    for (v, p) in [(1u32, &v1), (2, &v2)] {
        let mut fm = thermocomp_core::float::demo_model(u64::from(v));
        fm.model_version = v;
        tcomp::export::export(&fm, p).unwrap();
    }
    let port = free_tcp_port();
    let serial = format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on");
    let board = BenchBoard::start(
        &serial,
        &["serve", trace.to_str().unwrap(), v1.to_str().unwrap(), "50"],
    );
    assert!(
        board.wait_for("serving Modbus RTU", Duration::from_secs(60)),
        "{}",
        board.log()
    );
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    let s = upload(&mut link, &std::fs::read(&v2).unwrap()).unwrap();
    assert_eq!(s.model_version, 2);
    // Record five samples, then two more appended to the same file.
    let out = dir.join("recorded.csv");
    record(&mut link, &out, Duration::from_millis(300), 5, false).unwrap();
    record(&mut link, &out, Duration::from_millis(300), 2, true).unwrap();
    let run = tcomp::runcsv::Run::read(&out).unwrap();
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

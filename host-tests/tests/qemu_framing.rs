//! The bench board's RTU framing under QEMU (issue 30): the application's
//! framer on bytes timed in the receive interrupt. A request hidden inside
//! another unit's frame is not executed, a frame with a long silence inside
//! gets no answer, and two requests separated by a silence get two answers.
use host_tests::modbus::frame;
use host_tests::qemu::{export_demo, modbus_master as python, BenchBoard};
use thermocomp_protocol::holding::*;

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn boot() -> (BenchBoard, String) {
    let d = std::env::temp_dir().join(format!("thermocomp-framing-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let (t, m) = (d.join("trace.csv"), d.join("model.img"));
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..400 {
        csv += &format!("{},0,20,20.1,20.2,20.3,20.4,20.5\n", i * 15);
    }
    std::fs::write(&t, csv).unwrap();
    export_demo(1, 1, &m);
    let (board, port) = BenchBoard::serve_tcp(&t, &m, &["50"]);
    (board, port.to_string())
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn framing_on_the_bench_follows_the_line_timing() {
    let (board, p) = boot();
    let read_pattern = frame(&[1, 4, 0, 0, 0, 2]);
    let pattern_reply = "010404123456780a"; // + CRC low byte (checked by prefix)

    // 1. Frame-in-frame, sent as one write: an FC16 to unit 2 whose data
    // carries a unit-1 unlock, a unit-1 "unit address = 9" and a broadcast
    // of spindle speed 0x1234. None of them may be executed.
    let mut data = frame(&[1, 6, 0, HR_UNLOCK as u8, 0xA5, 0xC3]);
    data.extend(frame(&[1, 6, 0, HR_UNIT as u8, 0, 9]));
    data.extend(frame(&[0, 6, 0, HR_SPINDLE as u8, 0x12, 0x34]));
    let mut body = vec![2, 0x10, 0, 20, 0, (data.len() / 2) as u8, data.len() as u8];
    body.extend(&data);
    let outer = frame(&body);
    let r = python(&["raw", "--port", &p, "--hex", &hex(&outer)]);
    assert_eq!(
        r["reply"],
        "",
        "frame-in-frame answered: {r}\n{}",
        board.log()
    );
    let hold = python(&["hold", "--port", &p]);
    let regs = hold["registers"]
        .as_array()
        .unwrap_or_else(|| panic!("{hold}"));
    assert_eq!(
        regs[HR_UNLOCK as usize], 0,
        "unlocked by a hidden request: {hold}"
    );
    assert_eq!(regs[HR_UNIT as usize], 1, "unit changed: {hold}");
    assert_ne!(
        regs[HR_SPINDLE as usize], 0x1234,
        "hidden broadcast: {hold}"
    );

    // 2. A request split by an 8 ms silence (a break: above the bench's
    // 3 ms floor on t1.5, under its 10 ms t3.5; QEMU's late delivery of the
    // first bytes may shorten it by a millisecond or so, a loaded host may
    // stretch it into two fragments, also unanswered) and by 40 ms (two
    // fragments): neither answered. Then the whole request is answered.
    for gap in ["8", "40"] {
        let r = python(&[
            "raw",
            "--port",
            &p,
            "--hex",
            &hex(&read_pattern[..3]),
            "--hex",
            &hex(&read_pattern[3..]),
            "--gap-ms",
            gap,
        ]);
        assert_eq!(r["reply"], "", "split by {gap} ms: {r}");
    }
    let r = python(&["raw", "--port", &p, "--hex", &hex(&read_pattern)]);
    assert!(
        r["reply"]
            .as_str()
            .unwrap()
            .starts_with(&pattern_reply[..14]),
        "{r}"
    );

    // 3. Two requests in one write, no silence between: one 16-byte frame
    // with a wrong CRC, no answer. With 50 ms between them: two answers.
    let mut two = read_pattern.clone();
    two.extend(&read_pattern);
    let r = python(&["raw", "--port", &p, "--hex", &hex(&two)]);
    assert_eq!(r["reply"], "", "back to back with no silence: {r}");
    let r = python(&[
        "raw",
        "--port",
        &p,
        "--hex",
        &hex(&read_pattern),
        "--hex",
        &hex(&read_pattern),
        "--gap-ms",
        "50",
    ]);
    let reply = r["reply"].as_str().unwrap();
    assert_eq!(reply.len(), 2 * 2 * 9, "two replies of 9 bytes: {r}");
    assert!(reply.starts_with(&pattern_reply[..14]), "{r}");
    assert!(reply[18..].starts_with(&pattern_reply[..14]), "{r}");

    // 4. A library master still works (pymodbus, no retries).
    let ok = python(&["read", "--port", &p, "--samples", "20"]);
    assert_eq!(ok.as_array().unwrap().len(), 20, "{ok}");
}

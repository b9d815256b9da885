//! The bench firmware under QEMU: it boots, runs embassy tasks on its own time
//! driver, logs over semihosting and reports its verdict as QEMU's exit status.
//! These need the firmware built for thumbv7em-none-eabihf and Debian's
//! qemu-system-arm, so plain `cargo test` skips them; scripts/test.sh (the
//! README's test command) runs them with --include-ignored.

use std::time::Duration;

use host_tests::qemu::run_firmware;

const LIMIT: Duration = Duration::from_secs(60);

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn selftest_passes_and_exits_zero() {
    let run = run_firmware(&["selftest"], LIMIT);
    assert_eq!(
        run.status,
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        run.stdout,
        run.stderr
    );
    assert!(
        run.stdout.contains("bench board (mps2-an386) up"),
        "{}",
        run.stdout
    );
    assert!(
        run.stdout.contains("selftest timers:") && run.stdout.contains(": pass"),
        "{}",
        run.stdout
    );
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn selftest_timing_is_virtual_and_deterministic() {
    // The timer check runs on QEMU's instruction-driven clock: exact, and
    // the same however loaded the host is. One run is paused (SIGSTOP) for
    // a second of host time mid-way; its guest sees none of it.
    let lines: Vec<String> = (0..3)
        .map(|i| {
            let run = if i == 2 {
                host_tests::qemu::run_firmware_paused(&["selftest"], LIMIT, Duration::from_secs(1))
            } else {
                run_firmware(&["selftest"], LIMIT)
            };
            assert_eq!(run.status, Some(0), "stdout:\n{}", run.stdout);
            // 1 ns per instruction under icount; the loop's own entry and
            // exit add a few (how many depends on the build's code layout,
            // 0..=8 seen): within the calibration's 0.3 %, never host time.
            let took = run
                .stdout
                .lines()
                .find_map(|l| {
                    l.strip_prefix("selftest clock: 3000-instruction loop took ")?
                        .strip_suffix(" ns: virtual (icount)")?
                        .parse::<u64>()
                        .ok()
                })
                .unwrap_or(0);
            assert!((3000..=3009).contains(&took), "{}", run.stdout);
            run.stdout
                .lines()
                .filter(|l| l.starts_with("selftest"))
                .map(String::from)
                .collect::<Vec<_>>()
                .join("\n")
        })
        .collect();
    assert!(
        lines[0].contains("selftest timers: 200 ms elapsed, 19 ticker periods: pass"),
        "{}",
        lines[0]
    );
    assert_eq!(lines[0], lines[1]);
    assert_eq!(lines[0], lines[2]);
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn failing_selfcheck_fails_the_exit_status() {
    // A golden-vector file that does not exist cannot be checked: the
    // self-test must count that as a failure and exit 1.
    let run = run_firmware(&["selftest", "no/such/golden.bin"], LIMIT);
    assert_eq!(run.status, Some(1), "stdout:\n{}", run.stdout);
    assert!(run.stdout.contains("1 failure(s)"), "{}", run.stdout);
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn unknown_mode_is_refused_with_its_own_status() {
    let run = run_firmware(&["frobnicate"], LIMIT);
    assert_eq!(run.status, Some(2), "stdout:\n{}", run.stdout);
    assert!(run.stdout.contains("unknown mode"), "{}", run.stdout);
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn replay_reads_every_sample_of_a_trace() {
    let dir = tempdir();
    let path = dir.join("trace.csv");
    let mut csv = String::from("# run: boot-test\ntime_s,spindle_rpm,T01,T02,dx_um\n");
    for i in 0..50 {
        // Sensor T01 drops off the bus for rows 20..=21.
        let t01 = if (20..22).contains(&i) {
            String::new()
        } else {
            format!("{:.4}", 20.0 + i as f64 * 0.1)
        };
        csv.push_str(&format!(
            "{},{},{},{:.4},0\n",
            i * 10,
            1000 + i,
            t01,
            -5.0 + i as f64 * 0.05
        ));
    }
    std::fs::write(&path, csv).unwrap();
    let run = run_firmware(&["replay", path.to_str().unwrap()], LIMIT);
    assert_eq!(run.status, Some(0), "stdout:\n{}", run.stdout);
    assert!(
        run.stdout.contains("replay done: 50 samples"),
        "{}",
        run.stdout
    );
    // The board's real acquisition (ROM search, Match ROM, CRC) on the
    // emulated bus. Row 10: 20.9 °C = 334.4 sixteenths -> 334, both sensors ok.
    assert!(
        run.stdout
            .contains("t=90000 ms ok=2 faulty=0 T0=Some(334) Ok rpm=1009 |"),
        "{}",
        run.stdout
    );
    // T01 gone: the read floats high -> Disconnected, last good value held
    // (row 19: 21.9 °C = 350.4 -> 350); back on the bus, its first reading
    // could predate a Convert T it missed -> Intermittent, held; one whole
    // cycle on the bus later -> Ok (row 23: 22.3 °C = 356.8 -> 357).
    assert!(
        run.stdout
            .contains("t=200000 ms ok=1 faulty=1 T0=Some(350) Disconnected"),
        "{}",
        run.stdout
    );
    assert!(
        run.stdout
            .contains("t=220000 ms ok=1 faulty=1 T0=Some(350) Intermittent"),
        "{}",
        run.stdout
    );
    assert!(
        run.stdout
            .contains("t=230000 ms ok=2 faulty=0 T0=Some(357) Ok"),
        "{}",
        run.stdout
    );

    std::fs::write(&path, "time_s,T01\n0,20\n10,abc\n").unwrap();
    let bad = run_firmware(&["replay", path.to_str().unwrap()], LIMIT);
    assert_eq!(bad.status, Some(3), "a bad trace must fail: {}", bad.stdout);
    assert!(bad.stdout.contains("BadNumber"), "{}", bad.stdout);
}

fn tempdir() -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("thermocomp-qemu-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn instruction_counting_method_measures_a_known_loop() {
    // The bench mode's first figure is a loop of exactly 3000 instructions;
    // the method (icount + SysTick, see boards/qemu-mps2/src/cycles.rs) must
    // read it within 0.5 %.
    let run = host_tests::qemu::run_firmware_with(&["-icount", "shift=0"], &["bench"], LIMIT);
    assert_eq!(run.status, Some(0), "stdout:\n{}", run.stdout);
    let line = run
        .stdout
        .lines()
        .find(|l| l.starts_with('{'))
        .expect("a JSON line");
    let key = "\"known_loop_3000_insn_x100\":";
    let at = line.find(key).expect("known loop figure") + key.len();
    let digits: String = line[at..]
        .chars()
        .take_while(|c| c.is_ascii_digit())
        .collect();
    let x100: f64 = digits.parse().unwrap();
    let insns = x100 / 100.0;
    assert!(
        (insns - 3000.0).abs() < 15.0,
        "known loop measured {insns} instructions"
    );
}

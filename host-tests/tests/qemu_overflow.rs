//! A stack overflow on the bench board (issue 47): built with flip-link, the
//! stack sits at the bottom of RAM, so a recursion that runs off it faults
//! instead of writing over `.bss`; the HardFault entry moves the stack
//! pointer back before any Rust runs, writes the fault record (kind 5,
//! stack overflow, detail the stack pointer) and resets the board, which
//! boots again and finds the record.

use std::time::Duration;

use host_tests::qemu::run_firmware;

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn a_stack_overflow_lands_in_the_fault_record_and_resets_the_board() {
    let run = run_firmware(&["overflow"], Duration::from_secs(60));
    let out = format!("stdout:\n{}\nstderr:\n{}", run.stdout, run.stderr);
    assert_eq!(run.status, Some(0), "{out}");
    assert!(run.stdout.contains("stack overflow: sp="), "{out}");
    let boots = run.stdout.matches("bench board (mps2-an386) up").count();
    assert_eq!(boots, 2, "the fault resets the board once: {out}");
    let record = run
        .stdout
        .lines()
        .find(|l| l.contains("fault record:"))
        .unwrap_or_else(|| panic!("no fault record after the reset: {out}"));
    assert!(record.contains("kind=5 (stack overflow)"), "{record}");
    assert!(record.contains("pc=0x00000000"), "{record}");
    assert!(record.contains("count=1"), "{record}");
    // The stack pointer at the fault lies below the start of RAM (the
    // stack ran off its bottom, not into the statics above it).
    let sp = record
        .split("detail=0x")
        .nth(1)
        .and_then(|d| u32::from_str_radix(d.get(..8)?, 16).ok())
        .unwrap_or_else(|| panic!("no detail in {record}"));
    assert!(sp < 0x2000_0000, "sp {sp:#x}: {record}");
}

//! Bad arguments to the benchmark binaries: one `error:` line on stderr,
//! a non-zero exit and no stack trace, as for `tcomp` (issue 13).

use std::path::Path;
use std::process::{Command, Output};

/// Run one of the package's programs with RUST_BACKTRACE=1 set.
fn program(exe: &str, dir: &Path, args: &[&str]) -> Output {
    Command::new(exe)
        .current_dir(dir)
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .env_remove("TCOMP_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .unwrap()
}

#[test]
fn benchmarks_refuse_bad_arguments_with_one_line_too() {
    let dir = tempfile::tempdir().unwrap();
    for exe in [
        env!("CARGO_BIN_EXE_bench-diagnose"),
        env!("CARGO_BIN_EXE_bench-fit"),
        env!("CARGO_BIN_EXE_bench-geometry"),
        env!("CARGO_BIN_EXE_bench-rotary"),
        env!("CARGO_BIN_EXE_bench-sim"),
    ] {
        // a value that cannot be parsed: every benchmark reads its options first
        let out = program(
            exe,
            dir.path(),
            &["--seed", "x", "--cases", "x", "--repeat", "x"],
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        let line = stderr.trim_end();
        assert!(!out.status.success(), "{exe} exited 0: {line}");
        assert!(
            line.starts_with("error: ")
                && !line.contains('\n')
                && !line.contains("Stack backtrace"),
            "{exe}: not one error line:\n{stderr}"
        );
    }
}

/// `--help` prints a line for every flag the scripts and BENCHMARKS.md
/// give each benchmark (clap), and exits 0.
#[test]
fn every_benchmark_lists_its_flags_under_help() {
    let dir = tempfile::tempdir().unwrap();
    let benches: [(&str, &[&str]); 4] = [
        (
            env!("CARGO_BIN_EXE_bench-fit"),
            &[
                "--json",
                "--no-sklearn",
                "--data",
                "--ensemble",
                "--seeds",
                "--big-rows",
                "--write-big",
            ],
        ),
        (
            env!("CARGO_BIN_EXE_bench-geometry"),
            &[
                "--json",
                "--seeds",
                "--board-only",
                "--firmware",
                "--rich",
                "--method",
                "--first-seed",
                "--no-wave",
            ],
        ),
        (
            env!("CARGO_BIN_EXE_bench-rotary"),
            &[
                "--json",
                "--seeds",
                "--first-seed",
                "--noise-um",
                "--thermal-cycles",
                "--bias-states",
                "--linear",
            ],
        ),
        (env!("CARGO_BIN_EXE_bench-sim"), &["--json", "--repeat"]),
    ];
    for (exe, flags) in benches {
        let out = program(exe, dir.path(), &["--help"]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{exe} --help failed: {stdout}");
        for flag in flags {
            let line = stdout
                .lines()
                .find(|l| l.trim_start().starts_with(&format!("{flag} ")));
            assert!(
                line.is_some_and(|l| l.len() > flag.len() + 10),
                "{exe} --help: no line of text for {flag}:\n{stdout}"
            );
        }
    }
}

#[test]
fn the_issue_27_columns_refuse_bad_choices_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_bench-diagnose");
    for (args, says) in [
        (&["--columns", "exact,bogus"][..], "unknown column `bogus`"),
        (
            &["--columns", "all", "--worlds", "moon"][..],
            "unknown world `moon`",
        ),
        (
            &["--columns", "fit", "--sigma", "5", "--cases", "1"][..],
            "--sigma 5",
        ),
    ] {
        let out = program(exe, dir.path(), args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let line = stderr.trim_end();
        assert!(!out.status.success(), "{args:?} exited 0: {line}");
        assert!(
            line.starts_with("error: ") && !line.contains('\n') && line.contains(says),
            "{args:?}: not the one error line about {says}:\n{stderr}"
        );
    }
}

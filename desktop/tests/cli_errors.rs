//! Bad input to the real `tcomp` binary: every refusal is one line on stderr,
//! `error: …` naming what was wrong, with a non-zero exit and no stack trace
//! unless asked for (issue 13).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Run `tcomp` the way a developer's shell might (RUST_BACKTRACE=1 set).
fn tcomp(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .current_dir(dir)
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .env_remove("TCOMP_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .unwrap()
}

/// `tcomp args` must fail with one `error:` line that contains every `needle`.
fn refuses(dir: &Path, args: &[&str], needles: &[&str]) -> String {
    let out = tcomp(dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success(),
        "tcomp {args:?} exited 0\nstdout: {stdout}\nstderr: {stderr}"
    );
    let line = stderr.trim_end();
    assert!(
        line.starts_with("error: ") && !line.contains('\n'),
        "tcomp {args:?}: not one error line:\n{stderr}"
    );
    for n in needles {
        assert!(line.contains(n), "tcomp {args:?}: {line:?} lacks {n:?}");
    }
    line.to_string()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn errors_are_one_line_without_a_backtrace_unless_asked() {
    let dir = tempfile::tempdir().unwrap();
    let line = refuses(dir.path(), &["info", "missing.csv"], &["missing.csv"]);
    assert!(!line.contains("backtrace"), "{line}");

    // Asked for: the cause chain and the stack trace, by flag or by variable.
    let out = tcomp(dir.path(), &["info", "missing.csv", "--debug"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("Stack backtrace"), "{stderr}");
    let out = Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .current_dir(dir.path())
        .args(["info", "missing.csv"])
        .env_remove("RUST_BACKTRACE")
        .env("TCOMP_BACKTRACE", "1")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("Stack backtrace"), "{stderr}");
}

//! What the geometry tests share: the independent Python line writers in
//! `data/` (never `tcomp`'s own simulator) and running the CLI on their files.
#![allow(dead_code)] // each test binary uses its own part of this module

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const EXE: &str = env!("CARGO_BIN_EXE_tcomp");

/// Runs `tests/data/<script>` (a line writer) for one machine and returns
/// its 28 line files (14 lines, forward and backward), sorted by name.
pub fn generate(script: &str, dir: &Path, seed: u32, noise_um: f64) -> Vec<PathBuf> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(script);
    let out = Command::new("python3")
        .arg(&script)
        .args(["--seed", &seed.to_string()])
        .args(["--noise-um", &noise_um.to_string()])
        .arg("--out")
        .arg(dir)
        .output()
        .expect("python3 runs (scripts/test.sh installs it)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 28, "the writer makes 14 lines × 2 runs");
    files
}

/// `tcomp <args> <files>`.
pub fn run(args: &[&str], files: &[PathBuf]) -> Output {
    Command::new(EXE).args(args).args(files).output().unwrap()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// `tcomp <args>` run in `dir`.
pub fn tcomp(dir: &Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

/// [`tcomp`] that must succeed; its standard output.
pub fn ok(dir: &Path, args: &[&str]) -> String {
    let out = tcomp(dir, args);
    assert!(
        out.status.success(),
        "tcomp {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// [`tcomp`] that must fail with one line `error: …` naming `needle`.
pub fn refused(dir: &Path, args: &[&str], needle: &str) {
    let out = tcomp(dir, args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "tcomp {args:?} accepted");
    let line = err.trim_end();
    assert!(
        line.starts_with("error: ") && !line.contains('\n') && line.contains(needle),
        "{line:?} lacks {needle:?}"
    );
}

//! Runs the bench firmware under qemu-system-arm (mps2-an386) and captures
//! what it prints over semihosting and its exit status.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The bench firmware ELF: `$THERMOCOMP_QEMU_ELF`, else the release build in
/// the workspace's target directory (`scripts/test.sh` builds it first).
pub fn firmware_elf() -> PathBuf {
    if let Some(p) = std::env::var_os("THERMOCOMP_QEMU_ELF") {
        return PathBuf::from(p);
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    target.join("thumbv7em-none-eabihf/release/board-qemu-mps2")
}

pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[derive(Debug)]
pub struct QemuRun {
    pub status: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

/// Boot the firmware with `args` as its command line; kill it after `limit`.
pub fn run_firmware(args: &[&str], limit: Duration) -> QemuRun {
    run_firmware_with(&[], args, limit)
}

/// As [`run_firmware`], with extra QEMU options (e.g. `-icount shift=0`).
pub fn run_firmware_with(qemu_options: &[&str], args: &[&str], limit: Duration) -> QemuRun {
    let elf = firmware_elf();
    assert!(
        elf.exists(),
        "bench firmware {} not built: run scripts/test.sh (or cargo build -p board-qemu-mps2 --release --target thumbv7em-none-eabihf)",
        elf.display()
    );
    let mut child = Command::new("qemu-system-arm")
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-serial", "null", "-monitor", "none"])
        .args(qemu_options)
        .arg("-kernel")
        .arg(&elf)
        .arg("-append")
        .arg(args.join(" "))
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("qemu-system-arm not found: apt-get install qemu-system-arm");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait for qemu") {
            break s.code();
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stdout = String::new();
    let mut stderr = String::new();
    use std::io::Read;
    if let Some(mut o) = child.stdout.take() {
        let _ = o.read_to_string(&mut stdout);
    }
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut stderr);
    }
    QemuRun {
        status,
        stdout,
        stderr,
    }
}

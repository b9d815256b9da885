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

/// Start qemu-system-arm (mps2-an386, semihosting) on the bench firmware with
/// UART0 on `serial`, extra QEMU options and `args` as the firmware's command line.
fn spawn_qemu(serial: &str, qemu_options: &[&str], args: &[&str]) -> std::process::Child {
    let elf = firmware_elf();
    assert!(
        elf.exists(),
        "bench firmware {} not built: run scripts/test.sh (or cargo build -p board-qemu-mps2 --release --target thumbv7em-none-eabihf)",
        elf.display()
    );
    Command::new("qemu-system-arm")
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-serial", serial, "-monitor", "none"])
        .args(qemu_options)
        .arg("-kernel")
        .arg(&elf)
        .arg("-append")
        .arg(args.join(" "))
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("qemu-system-arm not found: apt-get install qemu-system-arm")
}

/// QEMU options for virtual time: the clock advances 1 ns per instruction
/// and jumps to the next timer when the CPU sleeps, so a one-shot run's
/// timing is the same on an idle and on a loaded host.
pub const VIRTUAL_TIME: [&str; 2] = ["-icount", "shift=0,sleep=off"];

/// Boot the firmware with `args` as its command line on virtual time
/// ([`VIRTUAL_TIME`]); kill it after `limit` (host time).
pub fn run_firmware(args: &[&str], limit: Duration) -> QemuRun {
    run_firmware_with(&VIRTUAL_TIME, args, limit)
}

/// As [`run_firmware`], with these QEMU options instead (e.g. `-icount
/// shift=0` for the bench mode).
pub fn run_firmware_with(qemu_options: &[&str], args: &[&str], limit: Duration) -> QemuRun {
    collect(spawn_qemu("null", qemu_options, args), limit)
}

/// As [`run_firmware`], with QEMU stopped (SIGSTOP) for `pause` of host time
/// shortly after it starts: what a loaded host does to it, in the extreme.
pub fn run_firmware_paused(args: &[&str], limit: Duration, pause: Duration) -> QemuRun {
    let child = spawn_qemu("null", &VIRTUAL_TIME, args);
    let pid = child.id().to_string();
    std::thread::sleep(Duration::from_millis(30));
    let signal = |sig: &str| {
        let ok = Command::new("kill")
            .args([sig, &pid])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "kill {sig} {pid} failed");
    };
    signal("-STOP");
    std::thread::sleep(pause);
    signal("-CONT");
    collect(child, limit)
}

/// Waits for QEMU to exit (killed after `limit`) and takes its output.
fn collect(mut child: std::process::Child, limit: Duration) -> QemuRun {
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

/// The bench firmware running in the background with its UART0 on a host
/// character device (`tcp:…` or `pty`), for Modbus masters to talk to.
/// Killed when dropped.
pub struct BenchBoard {
    child: std::process::Child,
    log: std::sync::Arc<std::sync::Mutex<String>>,
}

impl BenchBoard {
    pub fn start(serial: &str, args: &[&str]) -> BenchBoard {
        let mut child = spawn_qemu(serial, &[], args);
        let log = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        for stream in [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let log = log.clone();
            std::thread::spawn(move || {
                use std::io::BufRead;
                for line in std::io::BufReader::new(stream)
                    .lines()
                    .map_while(Result::ok)
                {
                    if let Ok(mut l) = log.lock() {
                        l.push_str(&line);
                        l.push('\n');
                    }
                }
            });
        }
        BenchBoard { child, log }
    }

    pub fn log(&self) -> String {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Wait until the log contains `needle`; false after `limit`.
    pub fn wait_for(&self, needle: &str, limit: Duration) -> bool {
        let start = Instant::now();
        while start.elapsed() < limit {
            if self.log().contains(needle) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }
}

impl Drop for BenchBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A TCP port free at the time of the call (bind to 0, read, release).
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free local TCP port")
}

/// One request through `host-tests/py/modbus_master.py` (pymodbus, the real
/// master the QEMU tests use); its JSON answer.
pub fn modbus_master(args: &[&str]) -> serde_json::Value {
    let script = workspace_root().join("host-tests/py/modbus_master.py");
    let out = std::process::Command::new("python3")
        .arg(script)
        .args(args)
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "modbus_master.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

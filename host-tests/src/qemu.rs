//! Runs the bench firmware under qemu-system-arm (mps2-an386) and captures
//! what it prints over semihosting and its exit status.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The bench firmware ELF: `$THERMOCOMP_QEMU_ELF`, else the `firmware`-profile
/// build in the workspace's target directory (`scripts/test.sh` builds it first).
pub fn firmware_elf() -> PathBuf {
    if let Some(p) = std::env::var_os("THERMOCOMP_QEMU_ELF") {
        return PathBuf::from(p);
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    target.join("thumbv7em-none-eabihf/firmware/board-qemu-mps2")
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
        "bench firmware {} not built: run scripts/test.sh (or cargo build -p board-qemu-mps2 --profile firmware --target thumbv7em-none-eabihf)",
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

/// Runs `host-tests/py/modbus_master.py` (pymodbus, the real master the
/// QEMU tests use) with `args`. It never retries and exits 1 on any
/// dropped frame, so every caller fails on a lossy link.
pub fn modbus_master_output(args: &[&str]) -> std::process::Output {
    let script = workspace_root().join("host-tests/py/modbus_master.py");
    Command::new("python3")
        .arg(script)
        .args(args)
        .output()
        .expect("python3")
}

/// The desktop CLI the QEMU tests compare the board with: `$THERMOCOMP_TCOMP`,
/// else `tcomp` of this test's own profile in the target directory
/// (`target/debug/tcomp`: `cargo test`'s build of the tcomp crate, which
/// `scripts/test.sh` makes first, or `cargo build -p tcomp`).
pub fn tcomp_exe() -> PathBuf {
    if let Some(p) = std::env::var_os("THERMOCOMP_TCOMP") {
        return PathBuf::from(p);
    }
    // this test binary is target/<profile>/deps/<name>-<hash>
    let exe = std::env::current_exe().expect("the test binary's path");
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>");
    let tcomp = profile_dir.join(format!("tcomp{}", std::env::consts::EXE_SUFFIX));
    assert!(
        tcomp.exists(),
        "{} not built: run `cargo build -p tcomp` (scripts/test.sh builds it), or set THERMOCOMP_TCOMP",
        tcomp.display()
    );
    tcomp
}

/// One request through [`modbus_master_output`]; its JSON answer.
pub fn modbus_master(args: &[&str]) -> serde_json::Value {
    let out = modbus_master_output(args);
    assert!(
        out.status.success(),
        "modbus_master.py {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// What the firmware logs each time it starts serving Modbus (once a boot).
pub const SERVING: &str = "serving Modbus RTU";

/// How long a test waits for the bench board to boot (a loaded host).
pub const BOOT: Duration = Duration::from_secs(60);

/// QEMU's `-serial` value for UART0 as a TCP server on local `port`.
pub fn tcp_serial(port: u16) -> String {
    format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on")
}

impl BenchBoard {
    /// The firmware's `serve trace model extra…` with UART0 on `serial`,
    /// once it serves Modbus (fails with its log after [`BOOT`]).
    pub fn serve(serial: &str, trace: &Path, model: &Path, extra: &[&str]) -> BenchBoard {
        let mut args = vec!["serve", trace.to_str().unwrap(), model.to_str().unwrap()];
        args.extend_from_slice(extra);
        let board = BenchBoard::start(serial, &args);
        assert!(board.wait_for(SERVING, BOOT), "{}", board.log());
        board
    }

    /// Wait until the board has booted `n` times (its log says [`SERVING`]
    /// `n` times); the host time it took. Fails with the log after `limit`.
    pub fn wait_for_boots(&self, n: usize, limit: Duration) -> Duration {
        let start = Instant::now();
        while start.elapsed() < limit {
            if self.log().matches(SERVING).count() >= n {
                return start.elapsed();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        panic!("no boot #{n} within {limit:?}:\n{}", self.log());
    }

    /// The host pty QEMU put UART0 on (a board started on serial `pty`).
    pub fn pty(&self) -> String {
        self.log()
            .split_whitespace()
            .find(|w| w.starts_with("/dev/pts/"))
            .expect("QEMU names the pty")
            .to_string()
    }

    /// As [`BenchBoard::serve`] on a free local TCP port; the board and the port.
    pub fn serve_tcp(trace: &Path, model: &Path, extra: &[&str]) -> (BenchBoard, u16) {
        let port = free_tcp_port();
        let board = BenchBoard::serve(&tcp_serial(port), trace, model, extra);
        (board, port)
    }
}

/// One bench board at a time in a test binary: QEMU hands the guest one
/// UART byte per main-loop turn, so parallel boards on a 2-core host
/// stretch frames. Hold the guard for the test's length.
pub fn one_board() -> std::sync::MutexGuard<'static, ()> {
    static ONE_BOARD: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE_BOARD.lock().unwrap_or_else(|e| e.into_inner())
}

/// A replay trace of six sensors, `rows` samples 15 s apart at 3000 rpm,
/// sensor `c` (from 0) warming by `(c + 1) * step_c` °C a row.
pub fn warming_trace(path: &Path, rows: u32, step_c: f64) {
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..rows {
        csv += &format!("{},3000", i * 15);
        for c in 0..6 {
            csv += &format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) * step_c);
        }
        csv += "\n";
    }
    std::fs::write(path, csv).unwrap();
}

/// The demo model of `seed` as version `version`, exported to `path` as
/// `tcomp export` writes it; the image's bytes.
pub fn export_demo(seed: u64, version: u32, path: &Path) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(seed);
    fm.model_version = version;
    tcomp_model::export::export(&fm, path).unwrap();
    std::fs::read(path).unwrap()
}

/// Six demo-model sensor readings (°C) for trace row `i`, comma-led: a slow
/// warm-up of 0.002 K per row times the channel number (the probe-reference
/// QEMU tests' synthetic runs).
pub fn demo_temps(i: u32) -> String {
    (0..6)
        .map(|c| format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) * 0.002))
        .collect()
}

/// `scripts/demo_references.py` (the README demo's PLC side) with `args`.
pub fn demo_references_script(args: &[&str]) -> std::process::Output {
    Command::new("python3")
        .arg(workspace_root().join("scripts/demo_references.py"))
        .args(args)
        .output()
        .expect("python3")
}

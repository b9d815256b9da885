//! The math core on the emulated Cortex-M4: golden vectors generated here on
//! the host are reproduced bit for bit by the firmware; a changed expectation
//! fails its self-test; a replay with a model logs corrections equal to the
//! host core's for the same acquired values.

use std::time::Duration;

use host_tests::qemu::run_firmware;
use thermocomp_core::golden;

const LIMIT: Duration = Duration::from_secs(120);

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("thermocomp-core-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn firmware_reproduces_the_host_golden_vectors_bit_for_bit() {
    let dir = scratch("golden");
    let path = dir.join("golden.bin");
    let bytes = golden::generate(1500, 4242).unwrap();
    assert_eq!(
        golden::check(&bytes),
        Ok(1500),
        "the host agrees with itself"
    );
    std::fs::write(&path, &bytes).unwrap();
    let run = run_firmware(&["selftest", path.to_str().unwrap()], LIMIT);
    assert_eq!(
        run.status,
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        run.stdout,
        run.stderr
    );
    assert!(
        run.stdout
            .contains("1500 steps reproduced bit for bit: pass"),
        "{}",
        run.stdout
    );
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn a_single_changed_expected_bit_fails_the_firmware_selftest() {
    let dir = scratch("golden-bad");
    let path = dir.join("golden.bin");
    let mut bytes = golden::generate(300, 7).unwrap();
    let n = bytes.len();
    bytes[n - 9] ^= 0x04; // inside the last step's expected outputs
    std::fs::write(&path, &bytes).unwrap();
    let run = run_firmware(&["selftest", path.to_str().unwrap()], LIMIT);
    assert_eq!(run.status, Some(1), "stdout:\n{}", run.stdout);
    assert!(
        run.stdout.contains("Mismatch { step: 299 }"),
        "{}",
        run.stdout
    );
}

#[test]
#[ignore = "needs the QEMU firmware: scripts/test.sh builds it and runs this"]
fn replay_with_a_model_logs_the_host_cores_corrections() {
    use thermocomp_core::{Compensator, StepInput};
    let dir = scratch("replay");
    // The demo model, exported as the board loads it.
    let (mut model, _) = thermocomp_core::float::demo_model(1).quantize().unwrap();
    let mut image = vec![0u8; model.encoded_len()];
    model.encode(&mut image).unwrap();
    std::fs::write(dir.join("model.img"), &image).unwrap();
    // A warm-up trace on six sensors, 1/16 °C exact values, spindle stepping.
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    let mut host = Compensator::new(Some(model));
    let mut expected = Vec::new();
    for i in 0..120u32 {
        let rpm = if i < 20 {
            0
        } else if i < 70 {
            6000
        } else {
            9000
        };
        let temps: Vec<i32> = (0..6).map(|c| 20 * 16 + (i as i32 * (c + 1)) / 3).collect();
        let t_s = i * 15;
        csv += &format!("{t_s},{rpm}");
        for t in &temps {
            csv += &format!(",{}", f64::from(*t) / 16.0);
        }
        csv += "\n";
        let t_opt: Vec<Option<i32>> = temps.iter().map(|&t| Some(t)).collect();
        let out = host.step(&StepInput {
            now_ms: u64::from(t_s) * 1000,
            temps: &t_opt,
            spindle_rpm: rpm,
            positions: &[0; 6],
            stale: false,
        });
        expected.push(out);
    }
    std::fs::write(dir.join("trace.csv"), csv).unwrap();
    let trace = dir.join("trace.csv");
    let img = dir.join("model.img");
    let run = run_firmware(
        &["replay", trace.to_str().unwrap(), img.to_str().unwrap()],
        LIMIT,
    );
    assert_eq!(run.status, Some(0), "stdout:\n{}", run.stdout);
    assert!(
        run.stdout.contains("model") && run.stdout.contains("loaded"),
        "{}",
        run.stdout
    );
    let lines: Vec<&str> = run.stdout.lines().filter(|l| l.starts_with("t=")).collect();
    assert_eq!(lines.len(), 120, "{}", run.stdout);
    for (line, out) in lines.iter().zip(&expected) {
        let z = fmt_um(out.corrections[0]);
        assert!(line.contains(&format!(" Z={z}")), "{line} vs Z={z}");
        assert!(
            line.contains(&format!("status={:#06x}", out.status)),
            "{line} vs {:#06x}",
            out.status
        );
    }
    // The corrections really move during the run.
    assert_ne!(expected[0].corrections, expected[119].corrections);
}

fn fmt_um(v: i32) -> String {
    let sign = if v < 0 { "-" } else { "+" };
    format!("{sign}{}.{}", v.unsigned_abs() / 10, v.unsigned_abs() % 10)
}

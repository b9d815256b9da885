//! `tcomp replay --reference-when-asked` (issue 51 item 3): the references
//! the board asks for, by the math core's rule (`thermocomp_core::ask`),
//! on a small synthetic run written here: one sample a minute for 12 h,
//! the spindle at 0 rpm, 3000 rpm from minute 100, a 200 rpm wobble (no
//! change) at minute 200, 1000 rpm from minute 380. With the suggested
//! rule (15 min after a change of ≥ 500 rpm, at most 70 min between
//! accepted references) and the PLC probing at the next sample, the
//! references fall at minutes 71 (interval), 116 (change at 100), 187,
//! 258, 329 (interval), 396 (change at 380), 467, 538, 609, 680 (interval).
//! A reference accepted within a change's settling time does not answer
//! for the settled state: with 30 min / 2 h, the interval's reference at
//! 121 is followed by the change's at 131.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const ROWS: usize = 720;

/// Deterministic standard-normal-ish noise (sum of 12 uniforms − 6).
struct Noise(u64);
impl Noise {
    fn next(&mut self) -> f64 {
        let mut s = 0.0;
        for _ in 0..12 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            s += (self.0 >> 11) as f64 / (1u64 << 53) as f64;
        }
        s - 6.0
    }
}

fn rpm_at(minute: usize) -> f64 {
    match minute {
        0..100 => 0.0,
        100..200 => 3000.0,
        200..380 => 3200.0,
        _ => 1000.0,
    }
}

/// `dx_um` follows two temperatures that follow the spindle; with `rpm`
/// the run has the `spindle_rpm` column.
fn write_run(dir: &Path, name: &str, rpm: bool) -> PathBuf {
    let mut g = Noise(11);
    let mut s = String::from(if rpm {
        "time_s,spindle_rpm,T_a,T_b,dx_um\n"
    } else {
        "time_s,T_a,T_b,dx_um\n"
    });
    let (mut ta, mut tb) = (20.0f64, 20.0f64);
    for k in 0..ROWS {
        let r = rpm_at(k);
        let dx = 2.0 * (ta - 20.0) - 0.5 * (tb - 20.0) + 0.2 * g.next();
        if rpm {
            s.push_str(&format!("{},{r},{ta:.4},{tb:.4},{dx:.4}\n", k * 60));
        } else {
            s.push_str(&format!("{},{ta:.4},{tb:.4},{dx:.4}\n", k * 60));
        }
        let target = 20.0 + r / 600.0;
        ta = target + (-60.0f64 / 900.0).exp() * (ta - target);
        tb = 20.0
            + (target - 20.0) / 2.0
            + (-60.0f64 / 2400.0).exp() * (tb - 20.0 - (target - 20.0) / 2.0);
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

fn tcomp(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The run, and an image fitted on it (MLR, the first 60 %).
fn setup(dir: &Path) -> (PathBuf, PathBuf) {
    let run = write_run(dir, "run.csv", true);
    let fit = dir.join("fit.json");
    let img = dir.join("model.img");
    ok(&tcomp(&[
        "fit".as_ref(),
        run.as_os_str(),
        "--split-chrono".as_ref(),
        "0.6,0.8".as_ref(),
        "--mlr-only".as_ref(),
        "--json".as_ref(),
        "--out".as_ref(),
        fit.as_os_str(),
    ]));
    ok(&tcomp(&[
        "export".as_ref(),
        "--model".as_ref(),
        fit.as_os_str(),
        "--run".as_ref(),
        run.as_os_str(),
        "-o".as_ref(),
        img.as_os_str(),
    ]));
    (run, img)
}

fn replay(run: &Path, img: &Path, more: &[&str]) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec!["replay".as_ref(), run.as_os_str(), img.as_os_str()];
    args.extend(more.iter().map(|a| std::ffi::OsStr::new(*a)));
    tcomp(&args)
}

fn dx(v: &serde_json::Value) -> &serde_json::Value {
    v["references"]["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["column"] == "dx_um")
        .unwrap()
}

/// (minute, reason, accepted) of every reference taken.
fn taken(c: &serde_json::Value) -> Vec<(u64, String, bool)> {
    c["taken"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["time_s"].as_f64().unwrap() as u64 / 60,
                t["reason"].as_str().unwrap().to_string(),
                t["accepted"].as_bool().unwrap(),
            )
        })
        .collect()
}

/// "dx_um: N references (…" in the text output.
fn printed_count(text: &str) -> usize {
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("dx_um:") && l.contains(" references ("))
        .unwrap_or_else(|| panic!("no reference count in {text}"));
    line.trim_start()
        .trim_start_matches("dx_um:")
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn the_board_asks_after_a_speed_change_and_at_the_longest_interval() {
    let dir = tempfile::tempdir().unwrap();
    let (run, img) = setup(dir.path());
    let v: serde_json::Value = serde_json::from_str(&ok(&replay(
        &run,
        &img,
        &["--reference-when-asked", "--json"],
    )))
    .unwrap();
    let w = &v["references"]["when_asked"];
    assert_eq!(w["settle_s"], 900);
    assert_eq!(w["max_interval_s"], 4200);
    assert_eq!(w["speed_step_rpm"], 500);
    assert_eq!(w["latency_rows"], 1);
    let c = dx(&v);
    let t = taken(c);
    let expect: Vec<(u64, &str)> = vec![
        (71, "interval"),
        (116, "speed_change"), // 15 min after the change at 100, + 1 sample
        (187, "interval"),
        (258, "interval"),
        (329, "interval"),
        (396, "speed_change"), // the 200 rpm wobble at 200 is no change
        (467, "interval"),
        (538, "interval"),
        (609, "interval"),
        (680, "interval"),
    ];
    let got: Vec<(u64, &str)> = t.iter().map(|(m, r, _)| (*m, r.as_str())).collect();
    assert_eq!(got, expect);
    assert!(t.iter().all(|(_, _, a)| *a), "clean readings are accepted");
    // Each request raised once, probed at the next sample.
    assert_eq!(c["asked_speed_change"], 2);
    assert_eq!(c["asked_interval"], 8);
    for x in c["taken"].as_array().unwrap() {
        let (at, asked) = (
            x["time_s"].as_f64().unwrap(),
            x["asked_s"].as_f64().unwrap(),
        );
        assert_eq!(at - asked, 60.0, "{x}");
    }
    // The count: the schedule's, in the JSON and in the text.
    assert_eq!(c["references"], expect.len());
    assert_eq!(c["accepted"], expect.len());
    let text = ok(&replay(&run, &img, &["--reference-when-asked"]));
    assert_eq!(printed_count(&text), expect.len(), "{text}");
    assert!(text.contains("references when the board asks"), "{text}");
    // Settable: 30 min after a change, at most 2 h apart.
    let v: serde_json::Value = serde_json::from_str(&ok(&replay(
        &run,
        &img,
        &[
            "--reference-when-asked",
            "--ask-settle",
            "30min",
            "--ask-interval",
            "2h",
            "--json",
        ],
    )))
    .unwrap();
    let got: Vec<u64> = taken(dx(&v)).iter().map(|t| t.0).collect();
    assert_eq!(got, vec![121, 131, 252, 373, 411, 532, 653]);
}

#[test]
fn a_refused_reading_leaves_the_request_raised_and_the_next_row_probes_again() {
    let dir = tempfile::tempdir().unwrap();
    let (run, img) = setup(dir.path());
    let out = ok(&replay(
        &run,
        &img,
        &[
            "--reference-when-asked",
            "--reference-outliers",
            "30%:50",
            "--reference-seed",
            "2",
            "--json",
        ],
    ));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let c = dx(&v);
    let t = c["taken"].as_array().unwrap();
    let refused: Vec<usize> = (0..t.len())
        .filter(|&k| !t[k]["accepted"].as_bool().unwrap())
        .collect();
    assert!(!refused.is_empty(), "seed 2 corrupts some readings: {c}");
    for &k in &refused {
        assert!(t[k]["corrupted"].as_bool().unwrap(), "{}", t[k]);
        let next = t.get(k + 1).expect("the request stays raised");
        assert_eq!(
            next["row"].as_u64().unwrap(),
            t[k]["row"].as_u64().unwrap() + 1,
            "the next row probes again"
        );
        assert_eq!(next["asked_s"], t[k]["asked_s"], "the same request");
        assert_eq!(next["reason"], t[k]["reason"]);
    }
    assert_eq!(c["references"], t.len());
    assert_eq!(c["refused"], refused.len());
    assert_eq!(
        c["accepted"].as_u64().unwrap() + refused.len() as u64,
        t.len() as u64
    );
}

#[test]
fn without_spindle_speed_the_board_asks_by_the_interval_only() {
    let dir = tempfile::tempdir().unwrap();
    let (_, img) = setup(dir.path());
    let run = write_run(dir.path(), "no_rpm.csv", false);
    let text = ok(&replay(&run, &img, &["--reference-when-asked"]));
    assert!(
        text.contains("no spindle_rpm column: the board asks by the interval rule only"),
        "{text}"
    );
    let v: serde_json::Value = serde_json::from_str(&ok(&replay(
        &run,
        &img,
        &["--reference-when-asked", "--json"],
    )))
    .unwrap();
    assert_eq!(v["references"]["when_asked"]["spindle_rpm"], false);
    let got: Vec<u64> = taken(dx(&v)).iter().map(|t| t.0).collect();
    assert_eq!(got, vec![71, 142, 213, 284, 355, 426, 497, 568, 639, 710]);
    assert_eq!(printed_count(&text), got.len());
}

#[test]
fn when_asked_is_refused_with_a_clock_schedule() {
    let dir = tempfile::tempdir().unwrap();
    let run = write_run(dir.path(), "run.csv", true);
    let img = dir.path().join("none.img"); // never read: clap refuses first
                                           // One line names both flags (clap adds its usage lines below it).
    let o = replay(
        &run,
        &img,
        &["--reference-when-asked", "--reference-every", "1h"],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let first = err.lines().next().unwrap_or_default();
    assert!(
        first.starts_with("error: ")
            && first.contains("--reference-when-asked")
            && first.contains("--reference-every"),
        "{err}"
    );
    // The rule's parameters only with the rule.
    let o = replay(&run, &img, &["--ask-settle", "10min"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.starts_with("error: ") && err.contains("--reference-when-asked"),
        "{err}"
    );
}

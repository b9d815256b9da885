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

/// A valid demo image (6 sensors on channels 0-5) written by `tcomp export --demo`.
fn demo_image(dir: &Path) -> PathBuf {
    let out = tcomp(dir, &["export", "--demo", "-o", "demo.img"]);
    assert!(out.status.success(), "{out:?}");
    dir.join("demo.img")
}

fn small_run(dir: &Path, name: &str) -> PathBuf {
    let mut s = String::from("time_s,spindle_rpm,T_a,T_b,T_c,T_d,T_e,T_f,dx_um\n");
    for k in 0..20 {
        let t = 20.0 + 0.1 * k as f64;
        s.push_str(&format!("{},3000,{t},{t},{t},{t},{t},{t},{}\n", k * 10, k));
    }
    write(dir, name, &s)
}

/// A stored error (not Debug output such as `BadCrc { stored: … }` or `BadNumber(2)`).
fn assert_no_debug_form(line: &str) {
    for debug in ["BadCrc", "BadNumber", "BadMagic", "TooShort", "{ ", "(2)"] {
        assert!(!line.contains(debug), "Debug form in {line:?}");
    }
}

#[test]
fn image_errors_are_messages_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let image = demo_image(dir.path());
    let run = small_run(dir.path(), "run.csv");
    let mut bytes = std::fs::read(&image).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(dir.path().join("corrupt.img"), &bytes).unwrap();
    std::fs::write(
        dir.path().join("text.img"),
        b"time_s,T_a\n0,20.00\n10,21.00\n20,22.00\n30,23.00\n",
    )
    .unwrap();
    assert!(run.exists());

    for sub in [
        vec!["replay", "run.csv", "corrupt.img"],
        vec!["report", "run.csv", "--image", "corrupt.img", "-o", "plots"],
    ] {
        let line = refuses(dir.path(), &sub, &["corrupt.img", "CRC-32 mismatch"]);
        assert_no_debug_form(&line);
    }
    assert!(
        !dir.path().join("plots").exists(),
        "report wrote plots for a refused image"
    );
    let line = refuses(
        dir.path(),
        &["replay", "run.csv", "text.img"],
        &["text.img", "not a model image"],
    );
    assert_no_debug_form(&line);
}

#[test]
fn trace_parser_errors_are_messages_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    demo_image(dir.path());
    // An exponent is a number for the CSV reader but not for the board's
    // plain-decimal trace parser, which `replay` uses to be bit-exact.
    let mut text = std::fs::read_to_string(small_run(dir.path(), "run.csv")).unwrap();
    text = text.replacen("\n10,3000,20.1,", "\n10,3000,2.01e1,", 1);
    write(dir.path(), "exp.csv", &text);
    let line = refuses(
        dir.path(),
        &["replay", "exp.csv", "demo.img"],
        &["exp.csv", "line 3", "column 3", "plain decimal"],
    );
    assert_no_debug_form(&line);
}

/// A file under `desktop/`.
fn repo_file(rel: &str) -> String {
    format!("{}/../../{rel}", env!("CARGO_MANIFEST_DIR"))
}

/// Every subcommand that reads runs refuses a header-only file and a run
/// without temperature columns, naming the file.
#[test]
fn runs_without_data_or_temperatures_are_refused_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    demo_image(dir.path());
    write(
        dir.path(),
        "head.csv",
        "# run: empty\ntime_s,spindle_rpm,T_a,T_b,dx_um\n",
    );
    let mut no_temps = String::from("time_s,spindle_rpm,dx_um\n");
    for k in 0..60 {
        no_temps.push_str(&format!("{},3000,{}\n", k * 10, 0.1 * k as f64));
    }
    write(dir.path(), "notemp.csv", &no_temps);
    let fit_json = repo_file("demo/fl-thermal-fit.json");
    let machine = repo_file("examples/machines/turning-center-16.toml");
    let commands = |run: &'static str| -> Vec<Vec<String>> {
        [
            vec!["select", run],
            vec!["replay", run, "demo.img"],
            vec!["fit", run, "--split-chrono", "0.6,0.8"],
            vec!["export", "--model", &fit_json, "--run", run, "-o", "x.img"],
            vec!["report", run, "-o", "plots"],
            vec!["diagnose", &machine, run],
        ]
        .into_iter()
        .map(|v| v.into_iter().map(String::from).collect())
        .collect()
    };
    for args in commands("head.csv") {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refuses(dir.path(), &args, &["head.csv", "no data rows"]);
    }
    for args in commands("notemp.csv") {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        if args[0] == "fit" {
            // fit is being rewritten; it refuses, the message is its own.
            refuses(dir.path(), &args, &["temperature columns"]);
        } else {
            refuses(dir.path(), &args, &["notemp.csv", "no temperature columns"]);
        }
    }
    assert!(!dir.path().join("x.img").exists());
    assert!(!dir.path().join("plots").exists());
}

/// `replay` refuses a model whose sensor channels the run does not have
/// (the replay would show only "sensor fault").
#[test]
fn replay_refuses_a_model_reading_channels_the_run_lacks() {
    let dir = tempfile::tempdir().unwrap();
    demo_image(dir.path()); // channels 0-5
    let mut s = String::from("time_s,spindle_rpm,T_a,T_b,dx_um\n");
    for k in 0..20 {
        s.push_str(&format!("{},3000,20.5,21.25,{k}\n", k * 10));
    }
    write(dir.path(), "two.csv", &s);
    refuses(
        dir.path(),
        &["replay", "two.csv", "demo.img"],
        &["demo.img", "two.csv", "channel 2", "2 temperature columns"],
    );
}

/// A physically impossible or non-numeric cell is refused by every
/// subcommand that reads runs, naming the file, the line and the column.
#[test]
fn impossible_cells_are_refused_by_every_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    demo_image(dir.path());
    let good = std::fs::read_to_string(small_run(dir.path(), "good.csv")).unwrap();
    // Line 5 is the fourth data row; T_c is the fifth column.
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    let cell = |line: &str, value: &str| {
        let mut f: Vec<&str> = line.split(',').collect();
        f[4] = value;
        f.join(",")
    };
    let fit_json = repo_file("demo/fl-thermal-fit.json");
    let machine = repo_file("examples/machines/turning-center-16.toml");
    let original = lines[4].clone();
    for (value, why) in [
        ("1e300", "outside"),
        ("250", "outside"),
        ("-80.5", "outside"),
        ("NaN", "not a finite number"),
        ("inf", "not a finite number"),
        ("twenty", "cannot parse"),
    ] {
        lines[4] = cell(&original, value);
        write(dir.path(), "bad.csv", &(lines.join("\n") + "\n"));
        for args in [
            vec!["info", "bad.csv"],
            vec!["select", "bad.csv"],
            vec!["replay", "bad.csv", "demo.img"],
            vec!["fit", "bad.csv", "--split-chrono", "0.6,0.8"],
            vec![
                "export", "--model", &fit_json, "--run", "bad.csv", "-o", "x.img",
            ],
            vec!["report", "bad.csv", "-o", "plots"],
            vec!["diagnose", &machine, "bad.csv"],
        ] {
            refuses(
                dir.path(),
                &args,
                &["bad.csv", "line 5", "column `T_c`", value, why],
            );
        }
    }
    // The same file with a possible value in that cell is read.
    lines[4] = cell(&original, "35.5");
    write(dir.path(), "fine.csv", &(lines.join("\n") + "\n"));
    let out = tcomp(dir.path(), &["replay", "fine.csv", "demo.img"]);
    assert!(out.status.success(), "{out:?}");
}

/// The shipped machine with the first occurrence of `from` replaced by `to`.
fn machine_with(dir: &Path, name: &str, from: &str, to: &str) -> String {
    let text =
        std::fs::read_to_string(repo_file("examples/machines/turning-center-16.toml")).unwrap();
    assert!(text.contains(from), "{from}");
    write(dir, name, &text.replacen(from, to, 1));
    name.to_string()
}

fn duty_with(dir: &Path, name: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(repo_file("examples/duty/warmup-steps.toml")).unwrap();
    assert!(text.contains(from), "{from}");
    write(dir, name, &text.replacen(from, to, 1));
    name.to_string()
}

/// Machine files, duty files and options of `sim` and `diagnose`: every
/// impossible value and every unbounded size is refused in one line naming
/// the file, the key and the allowed range.
#[test]
fn sim_and_diagnose_refuse_impossible_machines_duties_and_options() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let machine = repo_file("examples/machines/turning-center-16.toml");
    let duty = repo_file("examples/duty/warmup-steps.toml");
    let short = repo_file("examples/duty/short-steps.csv");
    let out = tcomp(d, &["sim", &machine, "--duty", &short, "-o", "run.csv"]);
    assert!(out.status.success(), "{out:?}");

    let bad_machines = [
        // 100000 slices once asked for an 80 GB matrix and aborted.
        (
            "segments = 10",
            "segments = 100000",
            "rod.segments",
            "2..=100",
        ),
        ("c_j_per_k = 2300.0", "c_j_per_k = nan", "c_j_per_k", "NaN"),
        (
            "g_amb_w_per_k = 0.2",
            "g_amb_w_per_k = -inf",
            "g_amb_w_per_k",
            "-inf",
        ),
        ("g_w_per_k = 15.0", "g_w_per_k = -15.0", "g_w_per_k", "-15"),
        (
            "n_max_rpm = 10000.0",
            "n_max_rpm = 0",
            "n_max_rpm",
            "above 0",
        ),
        (
            "motor_node = \"motor\"",
            "motor_node = \"motor\"\nalpha_per_k = -11.5e-6",
            "alpha_per_k",
            "0..=",
        ),
        ("quant_c = 0.0625", "quant_c = inf", "noise.quant_c", "inf"),
        (
            "diameter_mm = ",
            "diameter_mm = -1 #",
            "rod.diameter_mm",
            "above 0",
        ),
        (
            "c_j_per_k = 2300.0",
            "c_j_per_k = 2300.0\nmass_kg = 5",
            "line 33, column 1",
            "unknown field `mass_kg`",
        ),
    ];
    for (i, (from, to, key, range)) in bad_machines.into_iter().enumerate() {
        let file = machine_with(d, &format!("m{i}.toml"), from, to);
        let needles = [file.as_str(), key, range];
        refuses(d, &["sim", &file, "--duty", &duty, "-o", "x.csv"], &needles);
        refuses(d, &["diagnose", &file, "run.csv"], &needles);
    }
    assert!(!d.join("x.csv").exists());

    let bad_duties = [
        ("rpm = 6000", "rpm = -6000", "segment 3: rpm", "0..=100000"),
        ("rpm = 6000", "rpm = 6e9", "segment 3: rpm", "0..=100000"),
        ("rpm = 6000", "rpm = nan", "segment 3: rpm", "NaN"),
        ("feed = 0.2", "feed = 2", "segment 2: feed", "0..=1"),
        (
            "duration_min = 90",
            "duration_min = inf",
            "duration_min",
            "inf",
        ),
        (
            "sample_period_s = 1",
            "sample_period_s = 0",
            "sample_period_s",
            "1..=3600",
        ),
        (
            "sample_period_s = 1",
            "sample_period_s = 1\nrepeat = 10000000000",
            "repeat",
            "1..=",
        ),
    ];
    for (i, (from, to, key, range)) in bad_duties.into_iter().enumerate() {
        let file = duty_with(d, &format!("d{i}.toml"), from, to);
        refuses(
            d,
            &["sim", &machine, "--duty", &file, "-o", "x.csv"],
            &[file.as_str(), key, range],
        );
    }
    let mut csv_duty = std::fs::read_to_string(&short).unwrap();
    csv_duty = csv_duty.replacen("600,4000,", "600,-4000,", 1);
    write(d, "neg.csv", &csv_duty);
    refuses(
        d,
        &["sim", &machine, "--duty", "neg.csv", "-o", "x.csv"],
        &["neg.csv", "spindle_rpm", "-4000"],
    );

    for (option, needles) in [
        (
            vec!["--sample-period", "0"],
            ["--sample-period", "1..=3600"],
        ),
        (
            vec!["--sample-period", "NaN"],
            ["--sample-period", "1..=3600"],
        ),
        (vec!["--hours=-1"], ["--hours", "720"]),
        (vec!["--hours", "1e9"], ["--hours", "720"]),
        (vec!["--hours", "100"], ["rows", "200000"]),
        (
            vec!["--effect", "convection=h:nan"],
            ["h = NaN", "0..=1000"],
        ),
        (vec!["--effect", "ballscrew=k_w:-5"], ["k_w = -5", "0..="]),
    ] {
        let mut args = vec![
            "sim",
            machine.as_str(),
            "--duty",
            duty.as_str(),
            "-o",
            "x.csv",
        ];
        args.extend(option);
        refuses(d, &args, &needles);
    }
    for (option, needles) in [
        (vec!["--threads", "0"], ["--threads", "1..=1024"]),
        (vec!["--fit-fraction", "NaN"], ["--fit-fraction", "0.05"]),
    ] {
        let mut args = vec!["diagnose", machine.as_str(), "run.csv"];
        args.extend(option);
        refuses(d, &args, &needles);
    }
    assert!(!d.join("x.csv").exists());
}

#[test]
fn fit_names_an_input_that_never_reads() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = String::from("time_s,spindle_rpm,T_a,T_dead,dx_um\n");
    for k in 0..60 {
        let t = 20.0 + 0.1 * k as f64;
        s.push_str(&format!("{},3000,{t},,{}\n", k * 10, k));
    }
    let run = write(dir.path(), "dead.csv", &s);
    let run = run.to_str().unwrap();
    let out = dir.path().join("m.json");
    refuses(
        dir.path(),
        &[
            "fit",
            run,
            "--split-chrono",
            "0.6,0.8",
            "--features",
            "T_a,T_dead",
            "--out",
            out.to_str().unwrap(),
        ],
        &["input T_dead has no values in the training rows"],
    );
}

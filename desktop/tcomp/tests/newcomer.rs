//! The newcomer's path (issue 48 item 6): unit and reference mistakes are
//! refused before an image is written, `fit` says what it ships and what
//! it left out, `select`/`export`/`replay` say what their figures mean,
//! the run reader names a foreign separator, and the help guides.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const EXE: &str = env!("CARGO_BIN_EXE_tcomp");

/// How a synthetic run is written (a warm-up/cool-down cycle).
#[derive(Clone, Copy, Default)]
struct Spec {
    fahrenheit: bool,
    mm: bool,
    offset_um: f64,
    absolute: bool,
    no_spindle: bool,
    /// Temperature columns after T_a, T_b, T_c (T_x01 …).
    extra: usize,
    /// dx_um is 0 on the first row and 30 µm after (not what the
    /// temperatures say: a board serving them does worse about the mean).
    step: bool,
}

fn write_run(dir: &Path, name: &str, spec: Spec) -> PathBuf {
    let mut s = String::from("# run: synthetic\n# machine: test-mill\n");
    if spec.absolute {
        s.push_str("# error_reference: absolute\n");
    }
    let mut cols = vec!["time_s".to_string()];
    if !spec.no_spindle {
        cols.push("spindle_rpm".into());
    }
    cols.extend(["T_a", "T_b", "T_c"].map(String::from));
    cols.extend((1..=spec.extra).map(|j| format!("T_x{j:02}")));
    cols.push("dx_um".into());
    s.push_str(&(cols.join(",") + "\n"));
    let mut temp = 20.0;
    for k in 0..600 {
        let rpm = if (k / 150) % 2 == 0 { 4000.0 } else { 0.0 };
        let tb = 20.0 + (temp - 20.0) * 0.5 + (k as f64 * 0.01).sin() * 0.2;
        let tc = 21.0 + (k as f64 * 0.003).cos();
        let mut dx = 3.0 * (temp - 20.0) - 1.5 * (tb - 20.0) + spec.offset_um;
        if spec.step {
            dx = if k == 0 { 0.0 } else { 30.0 };
        }
        if spec.mm {
            dx /= 1000.0;
        }
        let mut temps = vec![temp, tb, tc];
        temps.extend(
            (1..=spec.extra).map(|j| 20.0 + 0.3 * (k as f64 * 0.01 * j as f64 + j as f64).sin()),
        );
        if spec.fahrenheit {
            temps.iter_mut().for_each(|t| *t = *t * 1.8 + 32.0);
        }
        let mut row = vec![(k * 30).to_string()];
        if !spec.no_spindle {
            row.push(rpm.to_string());
        }
        row.extend(temps.iter().map(|t| format!("{t:.4}")));
        row.push(format!("{dx:.5}"));
        s.push_str(&(row.join(",") + "\n"));
        let target = 20.0 + rpm / 500.0;
        temp = target + (-30.0f64 / 1800.0).exp() * (temp - target);
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

fn tcomp(dir: &Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

/// Must succeed; its standard output.
fn ok(dir: &Path, args: &[&str]) -> String {
    let o = tcomp(dir, args);
    assert!(
        o.status.success(),
        "tcomp {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Must fail with one line `error: …` holding every needle.
fn refused(dir: &Path, args: &[&str], needles: &[&str]) {
    let o = tcomp(dir, args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "tcomp {args:?} accepted: {err}");
    let line = err.trim_end();
    assert!(
        line.starts_with("error: ") && !line.contains('\n'),
        "not one line: {line:?}"
    );
    for n in needles {
        assert!(line.contains(n), "{line:?} lacks {n:?}");
    }
}

/// `fit` of one run, quick (MLR only).
fn fit(run: &str, extra: &[&str]) -> Vec<String> {
    let mut a: Vec<String> = ["fit", run, "--split-chrono", "0.6,0.8", "--mlr-only"]
        .map(String::from)
        .to_vec();
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn unit_and_reference_mistakes_are_refused_before_an_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_run(d, "good.csv", Spec::default());
    let fahrenheit = Spec {
        fahrenheit: true,
        ..Spec::default()
    };
    write_run(d, "f.csv", fahrenheit);
    write_run(
        d,
        "mm.csv",
        Spec {
            mm: true,
            ..Spec::default()
        },
    );
    let offset = Spec {
        offset_um: 44.0,
        ..Spec::default()
    };
    write_run(d, "abs.csv", offset);
    write_run(
        d,
        "absok.csv",
        Spec {
            absolute: true,
            ..offset
        },
    );

    // °F: the message says what it looks like, the threshold, the fix and the flag.
    refused(
        d,
        &strs(&fit("f.csv", &[])),
        &[
            "f.csv",
            "°F",
            "above 45 °C",
            "(°F − 32) / 1.8",
            "--accept-units",
        ],
    );
    let o = tcomp(d, &strs(&fit("f.csv", &["--accept-units"])));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr)
        .contains("warning: f.csv: the temperatures look like °F"));
    // mm in a µm column.
    refused(
        d,
        &strs(&fit("mm.csv", &[])),
        &[
            "mm.csv",
            "dx_um",
            "looks like mm",
            "under 0.5",
            "multiply by 1000",
            "--accept-units",
        ],
    );
    // An absolute error column without the metadata saying so.
    refused(
        d,
        &strs(&fit("abs.csv", &[])),
        &[
            "abs.csv",
            "dx_um starts at 44.0 µm",
            "±5 µm",
            "# error_reference: absolute",
            "--accept-reference",
        ],
    );
    ok(d, &strs(&fit("absok.csv", &[])));
    ok(d, &strs(&fit("abs.csv", &["--accept-reference"])));

    // `export` checks its run the same way: no image for °F channels.
    ok(d, &strs(&fit("good.csv", &["--out", "fit.json"])));
    refused(
        d,
        &[
            "export", "--model", "fit.json", "--run", "f.csv", "-o", "x.img",
        ],
        &["f.csv", "°F", "--accept-units"],
    );
    assert!(!d.join("x.img").exists());
    ok(
        d,
        &[
            "export",
            "--model",
            "fit.json",
            "--run",
            "f.csv",
            "-o",
            "x.img",
            "--accept-units",
        ],
    );
    assert!(d.join("x.img").exists());
}

#[test]
fn fit_says_what_export_ships_and_every_sensor_it_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 22 temperature columns: T_x18 and T_x19 are beyond the board's 20.
    write_run(
        d,
        "wide.csv",
        Spec {
            extra: 19,
            ..Spec::default()
        },
    );
    let text = ok(d, &strs(&fit("wide.csv", &["--no-fallbacks"])));
    assert!(
        text.contains("beyond the board's 20 channels are not candidates: T_x18, T_x19"),
        "{text}"
    );
    assert!(text.contains("what `export` ships"), "{text}");
    let ships = text
        .lines()
        .find(|l| l.trim_start().starts_with("dx_um: ") && l.contains(", reads "))
        .unwrap_or_else(|| panic!("no shipped line: {text}"));
    assert!(ships.contains("dx_um: mlr"), "{ships}");
    for s in ["T_x18", "T_x19"] {
        assert!(
            text.contains(&format!("left out {s}: beyond the board's 20 channels")),
            "{text}"
        );
    }
    // Every temperature column is either read or left out with a reason.
    let v: serde_json::Value = serde_json::from_str(&ok(
        d,
        &strs(&fit("wide.csv", &["--no-fallbacks", "--json"])),
    ))
    .unwrap();
    let c = &v["shipped"][0];
    assert_eq!(c["model"], v["chosen"]["dx_um"]);
    let read = c["sensors"].as_array().unwrap().len();
    let left = c["left_out"].as_array().unwrap();
    assert_eq!(read + left.len(), 22, "{c}");
    assert!(left.iter().all(|l| !l["why"].as_str().unwrap().is_empty()));

    // select's picks: --sensors-from its JSON, and --sensors.
    let sel = ok(d, &["select", "wide.csv", "--groups", "3", "--json"]);
    std::fs::write(d.join("sel.json"), &sel).unwrap();
    let picks: Vec<String> = serde_json::from_str::<serde_json::Value>(&sel).unwrap()["chosen"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .filter(|s| s != "T_x18" && s != "T_x19")
        .collect();
    let list = picks.join(",");
    for flag in [["--sensors-from", "sel.json"], ["--sensors", list.as_str()]] {
        if flag[0] == "--sensors-from" && picks.len() < 3 {
            continue; // select picked a sensor beyond the board: refused below
        }
        let v: serde_json::Value = serde_json::from_str(&ok(
            d,
            &strs(&fit("wide.csv", &[flag[0], flag[1], "--json"])),
        ))
        .unwrap();
        let c = &v["shipped"][0];
        for s in c["sensors"].as_array().unwrap() {
            assert!(picks.contains(&s.as_str().unwrap().to_string()), "{c}");
        }
        let not_picked = c["left_out"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["sensor"] == "T_x05" && !picks.contains(&"T_x05".to_string()));
        if let Some(l) = not_picked {
            assert!(l["why"].as_str().unwrap().contains("picked sensors"), "{l}");
        }
    }
    refused(
        d,
        &strs(&fit("wide.csv", &["--sensors", "T_a,T_nope"])),
        &["--sensors", "T_nope", "not a temperature column"],
    );
    refused(
        d,
        &strs(&fit("wide.csv", &["--sensors", "T_x19"])),
        &["--sensors", "T_x19", "beyond the board's 20 channels"],
    );
}

#[test]
fn select_scores_say_what_they_are_and_export_prints_the_wiring() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_run(d, "good.csv", Spec::default());
    let text = ok(d, &["select", "good.csv", "--groups", "2"]);
    assert!(text.contains("score: summed |r|"), "{text}");
    assert!(text.contains("(score 0."), "{text}");

    ok(d, &strs(&fit("good.csv", &["--out", "fit.json"])));
    let text = ok(
        d,
        &[
            "export", "--model", "fit.json", "--run", "good.csv", "-o", "m.img",
        ],
    );
    assert!(
        text.contains("wiring (model sensor → board channel)"),
        "{text}"
    );
    assert!(text.contains("T_a → T01"), "{text}");
    let v: serde_json::Value = serde_json::from_str(&ok(
        d,
        &[
            "export", "--model", "fit.json", "--run", "good.csv", "-o", "m.img", "--json",
        ],
    ))
    .unwrap();
    let wiring = v["wiring"].as_array().unwrap();
    assert!(
        wiring
            .iter()
            .any(|w| w["sensor"] == "T_b" && w["board_channel"] == "T02"),
        "{v}"
    );
}

#[test]
fn replay_explains_stale_rows_and_never_worse_is_true_of_what_is_shown() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let no_rpm = Spec {
        no_spindle: true,
        ..Spec::default()
    };
    write_run(d, "norpm.csv", no_rpm);
    ok(d, &strs(&fit("norpm.csv", &["--out", "fit.json"])));
    ok(
        d,
        &[
            "export",
            "--model",
            "fit.json",
            "--run",
            "norpm.csv",
            "-o",
            "m.img",
        ],
    );
    let text = ok(d, &["replay", "norpm.csv", "m.img"]);
    assert_eq!(text.matches("marked stale because").count(), 1, "{text}");
    assert!(text.contains("no spindle_rpm column"), "{text}");

    // A block the board improves about the reference but worsens about its mean.
    write_run(
        d,
        "step.csv",
        Spec {
            step: true,
            ..no_rpm
        },
    );
    let text = ok(d, &["replay", "step.csv", "m.img"]);
    let v: serde_json::Value =
        serde_json::from_str(&ok(d, &["replay", "step.csv", "m.img", "--json"])).unwrap();
    let ch = &v["channels"][0];
    assert_eq!(ch["never_worse"], true, "{ch}");
    assert!(
        ch["reduction_about_mean_pct"].as_f64().unwrap() < 0.0,
        "{ch}"
    );
    assert_eq!(ch["never_worse_about_mean"], false, "{ch}");
    let line = text
        .lines()
        .find(|l| l.contains("never worse than no compensation"))
        .unwrap();
    assert!(
        line.contains("about the block's own mean NO") && !line.ends_with(": yes"),
        "{line}"
    );
}

#[test]
fn the_run_reader_names_separators_decimal_commas_and_too_few_rows() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let w = |name: &str, text: &str| std::fs::write(d.join(name), text).unwrap();
    w("semi.csv", "time_s;T_a;dx_um\n0;20,5;0\n10;20,7;1,5\n");
    refused(
        d,
        &["select", "semi.csv"],
        &[
            "semi.csv",
            "this file uses ';' as separator; export it as comma-separated",
        ],
    );
    w(
        "quoted.csv",
        "time_s,T_a,dx_um\n0,\"20,5\",0\n10,\"20,7\",1\n",
    );
    refused(
        d,
        &["info", "quoted.csv"],
        &["line 2", "`20,5`", "decimal comma"],
    );
    w("split.csv", "time_s,T_a,dx_um\n0,20,5,0\n10,20,7,1\n");
    refused(d, &["info", "split.csv"], &["line 2", "decimal commas?"]);
    w("kelvin.csv", "time_s,T_a,dx_um\n0,293.15,0\n10,293.4,1\n");
    refused(d, &["info", "kelvin.csv"], &["kelvin?", "subtract 273.15"]);

    write_run(d, "good.csv", Spec::default());
    let good = std::fs::read_to_string(d.join("good.csv")).unwrap();
    let three: Vec<&str> = good.lines().take(6).collect(); // 2 metadata, header, 3 rows
    w("three.csv", &(three.join("\n") + "\n"));
    refused(
        d,
        &["select", "three.csv"],
        &[
            "three.csv",
            "3 row(s)",
            "`select` needs at least 10 rows",
            "correlation",
        ],
    );
    refused(
        d,
        &strs(&fit("good.csv", &["--validate", "three.csv"])),
        &[
            "three.csv",
            "3 row(s)",
            "`fit --validate` needs at least 10 rows",
            "RMS",
        ],
    );
}

/// `tcomp <cmd> --help` entries (flags, arguments) without a description.
fn undocumented(cmd: &[&str]) -> Vec<String> {
    let o = Command::new(EXE).args(cmd).arg("--help").output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let lines: Vec<&str> = text.lines().collect();
    let indent = |l: &str| l.len() - l.trim_start().len();
    let mut bad = Vec::new();
    let mut on = false;
    for (i, l) in lines.iter().enumerate() {
        if *l == "Options:" || *l == "Arguments:" {
            on = true;
            continue;
        }
        if !l.is_empty() && !l.starts_with(' ') {
            on = false;
        }
        if !on || l.trim().is_empty() || indent(l) >= 10 {
            continue;
        }
        // `-o, --out <OUT>  text` (short form) or the text on the next,
        // deeper lines (long form); the entry itself has no double blank
        let t = l.trim();
        let next = lines.get(i + 1).copied().unwrap_or("");
        let text_below = indent(next) >= 10 && !next.trim().is_empty();
        if !t.contains("  ") && !text_below {
            bad.push(format!("{}: {t}", cmd.join(" ")));
        }
    }
    bad
}

#[test]
fn diagnose_info_and_help_guide_a_newcomer() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_run(d, "good.csv", Spec::default());
    let text = ok(d, &["info", "good.csv"]);
    assert!(
        text.contains("metadata:") && text.contains("  machine: test-mill"),
        "{text}"
    );

    // A machine file's diagnosis needs spindle_rpm: one line pointing to `diagnose fit`.
    write_run(
        d,
        "norpm.csv",
        Spec {
            no_spindle: true,
            ..Spec::default()
        },
    );
    let machine = format!(
        "{}/../../examples/machines/turning-center-16.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    refused(
        d,
        &["diagnose", &machine, "norpm.csv"],
        &[
            "norpm.csv",
            "no `spindle_rpm`",
            "tcomp diagnose fit norpm.csv",
        ],
    );
    // --report makes its folder, as `report -o` does.
    ok(
        d,
        &["diagnose", "fit", "norpm.csv", "--report", "out/diag/r.md"],
    );
    assert!(d.join("out/diag/r.md").is_file());

    for cmd in [
        "export",
        "replay",
        "upload",
        "keygen",
        "commission",
        "record",
        "report",
        "golden",
        "select",
        "fit",
        "sim",
        "diagnose",
        "info",
    ] {
        let bad = undocumented(&[cmd]);
        assert!(bad.is_empty(), "flags without help text: {bad:?}");
    }
    for cmd in ["fit", "export", "replay", "diagnose"] {
        let o = Command::new(EXE).args([cmd, "--help"]).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains("Example:") && text.contains(&format!("tcomp {cmd} ")),
            "{cmd} --help has no example: {text}"
        );
    }
}

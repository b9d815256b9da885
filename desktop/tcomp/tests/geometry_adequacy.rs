//! Adequacy that can fail (issue 29 item 3, issue 49 item 2) and the
//! per-node identifier (`identify --method dense`). The default polynomial
//! model is tested against the stated noise (fit residual, each line
//! predicted from the others): it refuses a machine it cannot hold
//! (`data/geometry_rich_gen.py`: degree-5 polynomials plus waves) unless
//! `--accept-inadequate`, and not one it can (`data/geometry_lines_gen.py`,
//! its own class); the verdict travels to `table`, `tooltip`, `export`.
mod common;
use common::*;
use std::path::PathBuf;

/// `identify --json [extra]`: the output (when it exits 0), its stderr and
/// whether it succeeded.
fn identify(files: &[PathBuf], extra: &[&str]) -> (Option<serde_json::Value>, String, bool) {
    let out = run(
        &[&["geometry", "identify", "--json"], extra].concat(),
        files,
    );
    let v = out
        .status
        .success()
        .then(|| serde_json::from_slice(&out.stdout).unwrap());
    (v, stderr(&out), out.status.success())
}

/// Issue 49 item 2: on its own class at the stated noise the default model
/// is adequate (exit 0, nothing on stderr); on a machine beyond its class
/// (degree-5 polynomials plus waves) `identify` exits non-zero with one line
/// naming what failed, by how much and what to do, and with
/// `--accept-inadequate` writes the model marked `"adequate": false` with a
/// one-line warning. The older leave-one-line-out block stays in the JSON.
#[test]
fn the_default_model_refuses_a_machine_beyond_its_class_and_not_one_inside_it() {
    for noise in [0.0, 0.5] {
        let own = tempfile::tempdir().unwrap();
        let files = generate("geometry_lines_gen.py", own.path(), 1, noise);
        let (v, err, ok) = identify(&files, &[]);
        assert!(ok && err.is_empty(), "own class, σ {noise}: {err}");
        let v = v.unwrap();
        assert_eq!(v["adequate"], true, "{}", v["adequacy"]);
        let a = &v["adequacy"];
        assert!(a["noise_source"].as_str().unwrap().contains("default"));
        assert!(a["sigma_inflation"].as_f64().unwrap() < 1.3, "{a}");
        let (l, n) = (
            v["leave_one_line_out"]["rms_um"].as_f64().unwrap(),
            v["leave_one_line_out"]["noise_um"].as_f64().unwrap(),
        );
        assert!(l < 1.4 * n + 0.01, "own class, σ {noise}: LOLO {l} vs {n}");

        let rich = tempfile::tempdir().unwrap();
        let files = generate("geometry_rich_gen.py", rich.path(), 2, noise);
        let (v, err, ok) = identify(&files, &[]);
        assert!(!ok && v.is_none(), "rich, σ {noise} accepted");
        let line = err.trim_end();
        assert!(line.starts_with("error: ") && !line.contains('\n'), "{err}");
        for needle in [
            "inadequate",
            "×",
            "tcomp geometry plan",
            "--accept-inadequate",
        ] {
            assert!(line.contains(needle), "{line} lacks {needle}");
        }
        let (v, err, ok) = identify(&files, &["--accept-inadequate"]);
        assert!(ok, "{err}");
        let v = v.unwrap();
        assert_eq!(v["adequate"], false);
        // The misfit is measured (the σ's themselves now come from the
        // shape-free class, whose own inflation `sigma_inflation` is).
        let a = &v["adequacy"];
        let misfit = a["birge_ratio"].as_f64().unwrap();
        assert!(
            misfit.max(a["holdout_ratio"].as_f64().unwrap()) > 2.0,
            "{a}"
        );
        assert!(!v["adequacy"]["weak"].as_array().unwrap().is_empty());
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.starts_with("warning: ") && err.contains("inadequate"),
            "{err}"
        );
        let text = run(&["geometry", "identify", "--accept-inadequate"], &files);
        let t = String::from_utf8_lossy(&text.stdout);
        assert!(
            t.contains("INADEQUATE") && t.contains("weakly determined"),
            "{t}"
        );
    }
}

/// The verdict travels: `table`, `tooltip` and `export --geometry` refuse
/// the inadequate model (and the table built from it) unless
/// `--accept-inadequate`, and then mark their output.
#[test]
fn table_tooltip_and_export_refuse_an_inadequate_model_unless_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let files = generate("geometry_rich_gen.py", d, 4, 0.5);
    let (v, _, _) = identify(&files, &["--accept-inadequate"]);
    std::fs::write(d.join("m.json"), v.unwrap().to_string()).unwrap();
    refused(
        d,
        &["geometry", "table", "--model", "m.json"],
        "--accept-inadequate",
    );
    refused(
        d,
        &["geometry", "tooltip", "--errors", "m.json", "--at", "1,2,3"],
        "inadequate",
    );
    let t = ok(
        d,
        &[
            "geometry",
            "tooltip",
            "--errors",
            "m.json",
            "--at",
            "1,2,3",
            "--json",
            "--accept-inadequate",
        ],
    );
    let t: serde_json::Value = serde_json::from_str(&t).unwrap();
    assert_eq!(t["adequate"], false);
    let vol = ok(
        d,
        &[
            "geometry",
            "table",
            "--model",
            "m.json",
            "--json",
            "--accept-inadequate",
        ],
    );
    let p: serde_json::Value = serde_json::from_str(&vol).unwrap();
    assert_eq!(p["adequate"], false);
    std::fs::write(d.join("vol.json"), vol).unwrap();
    let export = ["export", "--demo", "--geometry", "vol.json", "-o", "x.img"];
    refused(d, &export, "inadequate");
    let out = tcomp(d, &[&export[..], &["--accept-inadequate"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).starts_with("warning: "), "{}", stderr(&out));
    // a file without a verdict (simulate's truth): unknown, warned, used
    let own = generate("geometry_lines_gen.py", &d.join("own"), 1, 0.5);
    let (v, _, _) = identify(&own, &[]);
    let mut v = v.unwrap();
    v.as_object_mut().unwrap().remove("adequate");
    std::fs::write(d.join("old.json"), v.to_string()).unwrap();
    let out = tcomp(d, &["geometry", "table", "--model", "old.json"]);
    assert!(out.status.success());
    assert!(
        stderr(&out).contains("adequacy unknown"),
        "{}",
        stderr(&out)
    );
}

/// On machines beyond the class the polynomial posterior's 3σ covered the
/// true error at 32.5 % (74.9 % inflated by the misfit); the σ's printed
/// now come from the class not told the shape (`shape_free`, issue 49
/// item 2) and cover it at ≥ 95 % of every term × tabulated position and
/// the squareness.
#[test]
fn printed_sigmas_cover_the_true_error_on_an_inadequate_model() {
    let (mut n, mut raw, mut infl) = (0usize, 0usize, 0usize);
    for seed in [2, 4] {
        let dir = tempfile::tempdir().unwrap();
        let files = generate("geometry_rich_gen.py", dir.path(), seed, 0.5);
        let (v, _, _) = identify(&files, &["--accept-inadequate"]);
        let v = v.unwrap();
        let f = v["adequacy"]["sigma_inflation"].as_f64().unwrap();
        let truth =
            tcomp_geometry::score::TabulatedTruth::read(&dir.path().join("truth.json")).unwrap();
        let mut count = |d: f64, s: f64| {
            n += 1;
            raw += usize::from(d.abs() <= 3.0 * s / f);
            infl += usize::from(d.abs() <= 3.0 * s);
        };
        for t in tcomp_geometry::Term::all() {
            let e = &v["errors"][t.name()];
            let num = |k: &str| -> Vec<f64> {
                e[k].as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            let (q, val, sig) = (num("positions_mm"), num("values"), num("sigma"));
            // the zero of the axis is exact (every error is zero there)
            for i in 1..q.len() {
                count(val[i] - truth.value_ref(t, q[i]), sig[i]);
            }
        }
        let sq = truth.squareness_ref();
        for (i, name) in ["EC0Y", "EB0Z", "EA0Z"].iter().enumerate() {
            let d = v["squareness_urad"][name].as_f64().unwrap() - sq[i];
            count(d, v["squareness_sigma_urad"][name].as_f64().unwrap());
        }
    }
    let (r, i) = (raw as f64 / n as f64, infl as f64 / n as f64);
    println!(
        "3σ coverage over {n} term × positions: {:.1} % without the inflation, {:.1} % printed",
        100.0 * r,
        100.0 * i
    );
    assert!(i >= 0.95, "printed 3σ covers {i}");
}

fn s(v: &[String]) -> Vec<&str> {
    v.iter().map(|x| x.as_str()).collect()
}

/// Five-axis: the project's own machine at the stated noise is adequate;
/// a component order below the machine's is refused in one line, and with
/// `--accept-inadequate` the model file carries `"adequate": false`, which
/// `export --rotary` refuses. `tooltip --turntable` refuses the model file
/// (it is not a turntable description) naming what it is.
#[test]
fn identify_rotary_refuses_a_model_below_the_machine_and_tooltip_names_a_rotary_model() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "geometry",
            "sim-rotary",
            "--out",
            "r",
            "--lines",
            "--seed",
            "4",
        ],
    );
    let mut rfiles: Vec<String> = std::fs::read_dir(d.join("r"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .map(|p| p.display().to_string())
        .collect();
    rfiles.sort();
    let mut lines: Vec<String> = std::fs::read_dir(d.join("r/lines"))
        .unwrap()
        .map(|e| e.unwrap().path().display().to_string())
        .collect();
    lines.sort();
    let args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = vec!["geometry".into(), "identify-rotary".into()];
        a.extend(rfiles.iter().cloned());
        a.push("--lines".into());
        a.extend(lines.iter().cloned());
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let good = tcomp(d, &s(&args(&["--json", "--model-out", "good.json"])));
    assert!(good.status.success(), "{}", stderr(&good));
    let v: serde_json::Value = serde_json::from_slice(&good.stdout).unwrap();
    assert_eq!(v["adequate"], true, "{}", v["adequacy"]);
    refused(d, &s(&args(&["--order-c", "1"])), "--accept-inadequate");
    ok(
        d,
        &s(&args(&[
            "--order-c",
            "1",
            "--accept-inadequate",
            "--model-out",
            "bad.json",
        ])),
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("bad.json")).unwrap()).unwrap();
    assert_eq!(m["adequate"], false);
    ok(
        d,
        &["geometry", "table", "--model", "r/errors.json", "--json"],
    );
    let vol = ok(
        d,
        &["geometry", "table", "--model", "r/errors.json", "--json"],
    );
    std::fs::write(d.join("vol.json"), vol).unwrap();
    let export = |m: &str| -> Vec<String> {
        [
            "export",
            "--demo",
            "--geometry",
            "vol.json",
            "--rotary",
            m,
            "-o",
            "x.img",
        ]
        .map(String::from)
        .to_vec()
    };
    refused(d, &s(&export("bad.json")), "inadequate");
    let out = tcomp(d, &s(&export("good.json")));
    assert!(out.status.success(), "{}", stderr(&out));
    refused(
        d,
        &[
            "geometry",
            "tooltip",
            "--turntable",
            "good.json",
            "--at",
            "100,100,100,30,45",
        ],
        "identify-rotary model",
    );
}

#[test]
fn dense_identification_is_refused_or_honest_on_a_rich_machine() {
    let dir = tempfile::tempdir().unwrap();
    let files = generate("geometry_rich_gen.py", dir.path(), 3, 0.0);
    // 11 nodes keep the debug-build test short; the method is the same.
    let args = ["geometry", "identify", "--method", "dense", "--nodes", "11"];
    let plain = run(&args, &files);
    let out = run(&[&args[..], &["--partial", "--json"]].concat(), &files);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["method"], "dense");
    let marked: Vec<String> = v["unobservable_terms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect();
    assert_eq!(plain.status.success(), marked.is_empty());
    let id = &v["identification"];
    let eff = id["effective_parameters"].as_f64().unwrap();
    let unknowns = id["unknowns"].as_f64().unwrap();
    assert!(eff > 20.0 && eff < unknowns, "{eff} of {unknowns}");
    assert!(id["hyper"]["length_scale_strokes"].as_f64().unwrap() > 0.0);
    let model = dir.path().join("id.json");
    std::fs::write(&model, &out.stdout).unwrap();
    let s = run(
        &[
            "geometry",
            "score",
            "--json",
            "--model",
            model.to_str().unwrap(),
            "--truth",
            dir.path().join("truth.json").to_str().unwrap(),
        ],
        &[],
    );
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    let s: serde_json::Value = serde_json::from_slice(&s.stdout).unwrap();
    for (name, r) in s["terms"].as_object().unwrap() {
        let limit = if "ABC".contains(&name[1..2]) {
            4.0
        } else {
            1.0
        };
        let rms = r[1].as_f64().unwrap();
        assert!(
            marked.contains(name) || rms <= limit,
            "{name} off by {rms} RMS, not marked"
        );
    }
}

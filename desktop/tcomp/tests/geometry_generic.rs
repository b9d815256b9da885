//! The generic identifier as `identify`'s default (issue 49 items 1–2): a
//! machine richer than any model (`data/geometry_rich_gen.py`: degree-5
//! polynomials plus waves, per-line laser scale 0.5 ppm, reflector 1 mm
//! and beam 200 µrad off, lost motion, σ 0.5 µm), measured along the rich
//! plan → exit 0 and the true errors within the printed 3σ at ≥ 95 % of
//! terms × positions; the same machine's 14 lines → refused, the
//! combinations no line sees named.
mod common;
use common::*;
use std::path::{Path, PathBuf};
use tcomp_geometry::errors::{Term, SQUARENESS_NAMES};
use tcomp_geometry::score::TabulatedTruth;

/// The machine of `seed` measured along `plan` (`14` or `rich`, as
/// `geometry plan` prints it) by the independent writer; its line files.
fn lines_of(dir: &Path, plan: &str, seed: u32) -> Vec<PathBuf> {
    let p = run(&["geometry", "plan", "--plan", plan, "--json"], &[]);
    assert!(p.status.success(), "{}", String::from_utf8_lossy(&p.stderr));
    let v: serde_json::Value = serde_json::from_slice(&p.stdout).unwrap();
    let plan_file = dir.join("plan.json");
    std::fs::write(&plan_file, v["lines"].to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/geometry_rich_gen.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(["--seed", &seed.to_string(), "--noise-um", "0.5", "--plan"])
        .arg(&plan_file)
        .arg("--out")
        .arg(dir)
        .output()
        .expect("python3 runs");
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
    files
}

#[test]
fn the_rich_plan_gives_a_model_whose_sigmas_cover_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let files = lines_of(dir.path(), "rich", 21);
    assert_eq!(files.len(), 56);
    let out = run(
        &["geometry", "identify", "--points", "21", "--json"],
        &files,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["method"], "generic");
    assert_eq!(v["adequate"], true);
    assert!(v["unobservable_terms"].is_null() || v["unobservable_terms"] == serde_json::json!([]));
    let truth = TabulatedTruth::read(&dir.path().join("truth.json")).unwrap();
    let (mut inside, mut n) = (0usize, 0usize);
    for t in Term::all() {
        let e = &v["errors"][t.name()];
        let l = truth.stroke_mm[t.axis.index()];
        let q = e["positions_mm"].as_array().unwrap();
        let val = e["values"].as_array().unwrap();
        let sig = e["sigma"].as_array().unwrap();
        assert_eq!(sig.len(), q.len(), "{}: a σ per position", t.name());
        for i in 0..q.len() {
            let qi = q[i].as_f64().unwrap();
            // Where the convention pins both to zero, nothing is counted.
            if qi < 1e-9 || (t.is_straightness() && (qi - l).abs() < 1e-9) {
                continue;
            }
            let d = (val[i].as_f64().unwrap() - truth.value_ref(t, qi)).abs();
            inside += usize::from(d <= 3.0 * sig[i].as_f64().unwrap());
            n += 1;
        }
    }
    let sr = truth.squareness_ref();
    for (i, name) in SQUARENESS_NAMES.iter().enumerate() {
        let d = (v["squareness_urad"][name].as_f64().unwrap() - sr[i]).abs();
        inside += usize::from(d <= 3.0 * v["squareness_sigma_urad"][name].as_f64().unwrap());
        n += 1;
    }
    let share = inside as f64 / n as f64;
    assert!(share >= 0.95, "3σ covers {:.1} % of {n}", 100.0 * share);
}

#[test]
fn the_same_machines_14_lines_are_refused_naming_what_no_line_sees() {
    let dir = tempfile::tempdir().unwrap();
    let files = lines_of(dir.path(), "14", 21);
    assert_eq!(files.len(), 28);
    let out = run(&["geometry", "identify"], &files);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("no line sees"), "{e}");
    assert!(
        Term::all().any(|t| e.contains(&format!("{} ", t.name()))
            || e.contains(&format!("{})", t.name()))),
        "{e}"
    );
    // Asked for the generic model, the same lines are refused the same way.
    let g = run(&["geometry", "identify", "--method", "generic"], &files);
    assert!(!g.status.success());
    let ge = String::from_utf8_lossy(&g.stderr);
    assert!(
        ge.contains("combinations of the errors that no line sees"),
        "{ge}"
    );
}

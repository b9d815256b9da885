//! `tcomp geometry plan --plan 14|rich` and `simulate --plan rich` (issue
//! 49 item 1): the rich plan's criterion (no null direction for the
//! flexible class, worst-term σ) against today's 14 lines, and its line
//! files read back by `identify`.
mod common;
use common::*;

fn json(dir: &std::path::Path, args: &[&str]) -> serde_json::Value {
    serde_json::from_str(&ok(dir, args)).unwrap()
}

#[test]
fn plan_prints_the_criterion_of_either_plan() {
    let dir = tempfile::tempdir().unwrap();
    let rich = json(
        dir.path(),
        &["geometry", "plan", "--plan", "rich", "--json"],
    );
    let lines = rich["lines"].as_array().unwrap();
    assert!((18..=28).contains(&lines.len()), "{}", lines.len());
    for l in lines {
        assert!(l["purpose"].as_str().is_some_and(|p| !p.is_empty()));
        assert_eq!(l["end_mm"].as_array().unwrap().len(), 3);
    }
    let c = &rich["criterion"];
    assert_eq!(c["null_directions"], 0);
    let fourteen = json(dir.path(), &["geometry", "plan", "--plan", "14", "--json"]);
    let c14 = &fourteen["criterion"];
    assert!(c14["null_directions"].as_u64().unwrap() > 0);
    assert!(c14["min_lines_identifiable"].is_null());
    assert!(c["worst_um"].as_f64().unwrap() < c14["worst_um"].as_f64().unwrap());
    assert!(c["worst_urad"].as_f64().unwrap() < c14["worst_urad"].as_f64().unwrap());
    // More noise, larger σ.
    let noisy = json(
        dir.path(),
        &[
            "geometry",
            "plan",
            "--plan",
            "rich",
            "--noise-um",
            "2",
            "--json",
        ],
    );
    assert!(noisy["criterion"]["worst_um"].as_f64().unwrap() > c["worst_um"].as_f64().unwrap());
    // In words, with units; the default is still today's plan.
    let text = ok(dir.path(), &["geometry", "plan"]);
    assert_eq!(text.lines().filter(|l| l.starts_with('L')).count(), 14);
    assert!(
        text.contains("null directions") && text.contains("µrad"),
        "{text}"
    );
    assert!(text.contains("--plan rich"), "{text}");
    refused(dir.path(), &["geometry", "plan", "--plan", "99"], "--plan");
}

#[test]
fn simulate_plan_rich_writes_lines_identify_reads() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rich");
    ok(
        dir.path(),
        &[
            "geometry",
            "simulate",
            "--plan",
            "rich",
            "--seed",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let mut files: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    assert!(files.len() >= 36, "{} files", files.len());
    let v = run(&["geometry", "identify", "--json"], &files);
    assert!(v.status.success(), "{}", stderr(&v));
    let v = run(
        &["geometry", "identify", "--method", "smooth", "--json"],
        &files,
    );
    assert!(v.status.success(), "{}", stderr(&v));
    let id: serde_json::Value = serde_json::from_slice(&v.stdout).unwrap();
    let n = id["identification"]["lines"].as_u64().unwrap();
    assert!(n >= 18, "{n} lines identified");
    // Today's default is unchanged: 14 lines.
    let out14 = dir.path().join("fourteen");
    ok(
        dir.path(),
        &[
            "geometry",
            "simulate",
            "--seed",
            "5",
            "--out",
            out14.to_str().unwrap(),
        ],
    );
    let n14 = std::fs::read_dir(&out14)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "csv")
        })
        .count();
    assert_eq!(n14, 28);
}

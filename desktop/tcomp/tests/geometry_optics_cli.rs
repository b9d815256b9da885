//! `tcomp geometry plan|simulate --plan rich-optics` (issue 49: one
//! straightness-optics line): the plan names its straightness line, the
//! simulated files carry `measures: straightness`, the default identifier
//! (generic) reads them and recovers the machine within its σ's, and the
//! polynomial model refuses them in one line.
mod common;
use common::*;

#[test]
fn rich_optics_is_simulated_and_identified_by_the_generic_model() {
    let dir = tempfile::tempdir().unwrap();
    let plan: serde_json::Value = serde_json::from_str(&ok(
        dir.path(),
        &["geometry", "plan", "--plan", "rich-optics", "--json"],
    ))
    .unwrap();
    let lines = plan["lines"].as_array().unwrap();
    assert_eq!(lines.len(), 28);
    let straight: Vec<_> = (lines.iter())
        .filter(|l| l["measures"] == "straightness")
        .collect();
    assert_eq!(straight.len(), 1);
    assert_eq!(plan["criterion"]["null_directions"], 0);

    let out = dir.path().join("s");
    let o = out.to_str().unwrap();
    ok(
        dir.path(),
        &[
            "geometry",
            "simulate",
            "--plan",
            "rich-optics",
            "--seed",
            "5",
            "--out",
            o,
        ],
    );
    let id = straight[0]["line"].as_str().unwrap();
    let text = std::fs::read_to_string(out.join(format!("{id}_forward.csv"))).unwrap();
    assert!(text.contains("# measures: straightness") && text.contains("# sense: "));
    let mut files: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    files.sort();
    let truth = out.join("errors.json");
    let mut args = vec!["geometry", "identify", "--json", "--truth"];
    args.push(truth.to_str().unwrap());
    args.extend(files.iter().map(String::as_str));
    let v: serde_json::Value = serde_json::from_str(&ok(dir.path(), &args)).unwrap();
    assert_eq!(v["method"], "generic");
    assert_eq!(v["adequate"], true);
    // Every error recovered to a small part of its true size.
    let rec = v["recovery"].as_object().unwrap();
    assert_eq!(rec.len(), 18);
    for (name, r) in rec {
        let (rms, peak) = (r["rms"].as_f64().unwrap(), r["true_peak"].as_f64().unwrap());
        assert!(rms < 0.15 * peak, "{name}: rms {rms:.2} of peak {peak:.2}");
    }

    let mut poly = vec!["geometry", "identify", "--method", "poly"];
    poly.extend(files.iter().map(String::as_str));
    refused(
        dir.path(),
        &poly,
        &format!("line {id} is straightness-optics"),
    );
}

//! Straightness-optics lines (issue 49: "with one straightness-optics line
//! allowed"): the format's `measures: straightness` / `sense` keys, and the
//! generic identifier on the rich-optics plan, a machine drawn by the
//! independent rich writer (`desktop/tcomp/tests/data/geometry_rich_gen.py`).

use std::path::Path;

use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::errors::Term;
use tcomp_geometry::generic::identify_generic;
use tcomp_geometry::identify::{identify, Degrees, LineKind, LineObs};
use tcomp_geometry::lines::{average_runs, LineFile};
use tcomp_geometry::plan_optics::{rich_optics_lines, RICH_OPTICS_REPLACES};
use tcomp_geometry::score::{read_dir_lines, TabulatedTruth};
use tcomp_geometry::shape_free::coverage_3sigma;

const STROKE: [f64; 3] = [800.0, 500.0, 400.0];

const LINE: &str = "# line: S01
# start_mm: 0,0,0
# direction: 1,0,0
# tool_offset_mm: 0,0,100
# structure: XY/Z
# measures: straightness
# sense: 0,1,0
# source: measured
s_mm,pos_x,pos_y,pos_z,disp_um
0,0,0,0,3.10
50,50,0,0,3.42
100,100,0,0,3.61
";

fn parse(text: &str) -> anyhow::Result<LineFile> {
    LineFile::parse(text, Path::new("s01.csv"))
}

#[test]
fn a_straightness_line_reads_writes_and_averages_with_its_sense() {
    let f = parse(LINE).unwrap();
    assert_eq!(f.spec.kind, LineKind::Straightness);
    assert_eq!(f.spec.sense, [0.0, 1.0, 0.0]);
    let g = parse(&f.to_text()).unwrap();
    assert_eq!(g.spec.kind, LineKind::Straightness);
    assert_eq!(g.spec.sense, f.spec.sense);
    assert_eq!(g.disp_um, f.disp_um);
    let avg = average_runs(&[g]).unwrap();
    assert_eq!(avg[0].obs.kind, LineKind::Straightness);
    assert_eq!(avg[0].obs.sense, [0.0, 1.0, 0.0]);
    // Without the keys: a displacement line, its sense the travel, written as before.
    let plain = LINE.replace("# measures: straightness\n# sense: 0,1,0\n", "");
    let d = parse(&plain).unwrap();
    assert_eq!(d.spec.kind, LineKind::Displacement);
    assert_eq!(d.spec.sense, d.spec.direction);
    assert!(!d.to_text().contains("measures") && !d.to_text().contains("sense"));
    // Runs that disagree on what they measure are not averaged.
    let mut fwd = parse(&LINE.replace("# source", "# run: forward\n# source")).unwrap();
    let bwd = parse(&plain.replace("# source", "# run: backward\n# source")).unwrap();
    let e = average_runs(&[fwd.clone(), bwd]).unwrap_err().to_string();
    assert!(e.contains("S01") && e.contains("measure"), "{e}");
    fwd.spec.sense = [0.0, 0.0, 1.0];
    assert!(parse(&fwd.to_text()).unwrap().spec.sense == [0.0, 0.0, 1.0]);
}

#[test]
fn a_bad_sense_is_a_one_line_error_naming_the_file_and_line() {
    for (from, to, words) in [
        ("# sense: 0,1,0", "# sense: 0.001,1,0", "not perpendicular"),
        ("# sense: 0,1,0", "# sense: 0,1.01,0", "not a unit vector"),
        ("# sense: 0,1,0\n", "", "needs '# sense"),
        (
            "# measures: straightness",
            "# measures: flatness",
            "measures must be",
        ),
        (
            "# measures: straightness\n",
            "",
            "sense is for a straightness line",
        ),
    ] {
        let e = parse(&LINE.replace(from, to)).unwrap_err().to_string();
        assert!(e.contains("s01.csv") && e.contains(words), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
    // The line number of the offending key.
    let e = parse(&LINE.replace("# sense: 0,1,0", "# sense: 1,0,0"))
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("s01.csv:7:"), "{e}");
}

/// One machine of the rich writer measured along the rich-optics plan.
fn rich_optics_machine(dir: &Path, seed: u64) -> (Vec<LineObs>, TabulatedTruth) {
    let lines = rich_optics_lines(STROKE, 100.0, 100.0);
    let v: Vec<serde_json::Value> = (lines.iter())
        .map(|l| {
            let e = [0, 1, 2].map(|k| l.start_mm[k] + l.length_mm * l.direction[k]);
            let mut j = serde_json::json!({"line": l.id, "start_mm": l.start_mm,
                "end_mm": e, "tool_offset_mm": l.tool_offset_mm});
            if l.kind == LineKind::Straightness {
                j["sense"] = serde_json::json!(l.sense);
            }
            j
        })
        .collect();
    let plan = dir.join("plan.json");
    std::fs::write(&plan, serde_json::to_string(&v).unwrap()).unwrap();
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tcomp/tests/data/geometry_rich_gen.py");
    let out = dir.join("m");
    let run = std::process::Command::new("python3")
        .arg(&script)
        .args(["--seed", &seed.to_string(), "--noise-um", "0.5", "--plan"])
        .arg(&plan)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let files = read_dir_lines(&out).unwrap();
    let obs: Vec<LineObs> = average_runs(&files)
        .unwrap()
        .into_iter()
        .map(|a| a.obs)
        .collect();
    (obs, TabulatedTruth::read(&out.join("truth.json")).unwrap())
}

#[test]
fn the_generic_identifier_uses_a_straightness_line_and_covers_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (obs, truth) = rich_optics_machine(dir.path(), 103);
    assert_eq!(obs.len(), 28);
    let k = obs
        .iter()
        .position(|l| l.id == RICH_OPTICS_REPLACES)
        .unwrap();
    assert_eq!(obs[k].kind, LineKind::Straightness);
    let st = tcomp_geometry::Structure::parse("XY/Z").unwrap();
    let g = identify_generic(&st, &obs, STROKE).unwrap();
    let noise = StatedNoise::new(Some(0.5)).unwrap();
    let adq = g.adequacy(&vec![0.5 / 2f64.sqrt(); obs.len()], noise);
    let f = adq.sigma_inflation;
    let cover = coverage_3sigma(&g.fit.errors, &truth, |t, i, q| match t {
        Some(t) => f * g.sigma(t, q),
        None => f * g.squareness_sigma(i),
    });
    println!(
        "3σ covers {cover:.1} %, adequate {}, residual {:.3} µm",
        adq.adequate, g.fit.residual_rms_um
    );
    assert!(cover >= 95.0, "3σ covers {cover:.1} %");

    // The same line read with the wrong sign of its sense: the fit changes.
    let mut wrong = obs.clone();
    wrong[k].sense = wrong[k].sense.map(|c| -c);
    let w = identify_generic(&st, &wrong, STROKE).unwrap();
    // What the line reads (EXY, and ECY through its z arm) moves by more
    // than its posterior σ somewhere along Y.
    let moved = [
        Term::all().find(|t| t.name() == "EXY"),
        Term::all().find(|t| t.name() == "ECY"),
    ]
    .into_iter()
    .flatten()
    .flat_map(|t| (1..20).map(move |i| (t, STROKE[1] * i as f64 / 20.0)))
    .map(|(t, q)| (g.fit.errors.value(t, q) - w.fit.errors.value(t, q)).abs() / g.sigma(t, q))
    .fold(0.0, f64::max);
    println!(
        "wrong sense: residual {:.3} → {:.3} µm, largest move {moved:.1} σ",
        g.fit.residual_rms_um, w.fit.residual_rms_um
    );
    assert!(moved > 1.0, "moved {moved:.2} σ");
    assert!(w.fit.residual_rms_um > g.fit.residual_rms_um);
}

#[test]
fn the_methods_that_read_only_displacement_refuse_a_straightness_line() {
    let dir = tempfile::tempdir().unwrap();
    let (obs, _) = rich_optics_machine(dir.path(), 104);
    let st = tcomp_geometry::Structure::parse("XY/Z").unwrap();
    let e = identify(&st, &obs, Degrees::default(), STROKE)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains(RICH_OPTICS_REPLACES) && e.contains("straightness"),
        "{e}"
    );
    let e = tcomp_geometry::smooth::identify_smooth(&st, &obs, 10, STROKE)
        .unwrap_err()
        .to_string();
    assert!(e.contains("smooth") && !e.contains('\n'), "{e}");
}

//! K-means++ grouping and sensor choice on clearly clustered synthetic series.

use tcomp_data::runcsv::Run;
use tcomp_model::select::{kmeans_pp, select};
use tcomp_numerics::stats::pearson;

fn clustered_run() -> Run {
    let n = 600;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 10.0).collect();
    // Three shapes: ramp, sine, step; sensors are noisy copies, scaled.
    let shape = |g: usize, k: usize| -> f64 {
        let x = k as f64 / n as f64;
        match g {
            0 => 10.0 * x,
            1 => 3.0 * (x * 12.0).sin(),
            _ => {
                if x > 0.5 {
                    4.0
                } else {
                    0.0
                }
            }
        }
    };
    let noise =
        |k: usize, s: usize| (((k * 7919 + s * 104729) % 1000) as f64 / 1000.0 - 0.5) * 0.05;
    // Sensor s belongs to group s % 3; within each group the first sensor is
    // the cleanest (the others get extra noise of their own).
    let mut columns = vec!["time_s".to_string()];
    let mut data = vec![t.iter().map(|v| Some(*v)).collect::<Vec<_>>()];
    for s in 0..9 {
        let g = s % 3;
        let extra = (s / 3) as f64 * 0.6;
        columns.push(format!("T_s{s}"));
        data.push(
            (0..n)
                .map(|k| {
                    Some(
                        20.0 + shape(g, k) * (1.0 + 0.1 * s as f64)
                            + noise(k, s)
                            + extra * ((k * 31 + s * 17) % 13) as f64 / 13.0,
                    )
                })
                .collect(),
        );
    }
    // Two error directions: x follows the ramp, z the step.
    columns.push("dx_um".into());
    data.push((0..n).map(|k| Some(2.0 * shape(0, k))).collect());
    columns.push("dz_um".into());
    data.push((0..n).map(|k| Some(-3.0 * shape(2, k))).collect());
    Run {
        meta: vec![],
        columns,
        data,
    }
}

#[test]
fn kmeans_pp_separates_clear_clusters() {
    let pts: Vec<Vec<f64>> = (0..30)
        .map(|i| {
            let c = (i % 3) as f64 * 10.0;
            vec![c + (i as f64 * 0.01), c - (i as f64 * 0.02)]
        })
        .collect();
    let (labels, _) = kmeans_pp(&pts, 3, 5, 0);
    for i in 0..30 {
        for j in 0..30 {
            assert_eq!(labels[i] == labels[j], i % 3 == j % 3);
        }
    }
    // Seeded: same answer twice.
    assert_eq!(kmeans_pp(&pts, 3, 5, 0), kmeans_pp(&pts, 3, 5, 0));
}

#[test]
fn select_groups_sensors_and_picks_the_most_correlated() {
    let run = clustered_run();
    let s = select(&[run], 3, 0).unwrap();
    assert_eq!(s.clusters.len(), 3);
    for g in &s.clusters {
        let grp: Vec<usize> = g
            .iter()
            .map(|n| n[3..].parse::<usize>().unwrap() % 3)
            .collect();
        assert!(grp.iter().all(|x| *x == grp[0]), "mixed group {g:?}");
    }
    for (g, chosen) in s.clusters.iter().zip(&s.chosen) {
        let best = g
            .iter()
            .max_by(|a, b| s.scores[*a].total_cmp(&s.scores[*b]))
            .unwrap();
        assert_eq!(best, chosen);
        // Score = Σ|r| over directions.
        let sum: f64 = s.correlations[chosen].values().map(|r| r.abs()).sum();
        assert!((sum - s.scores[chosen]).abs() < 1e-12);
    }
    assert!(select(&[clustered_run()], 0, 0).is_err());
    assert!(select(&[clustered_run()], 10, 0).is_err());
    let a = [Some(1.0), Some(2.0), None, Some(3.0)];
    let b = [Some(2.0), Some(4.0), Some(0.0), Some(6.0)];
    assert!((pearson(&a, &b) - 1.0).abs() < 1e-12);
}

#[test]
fn a_dead_or_frozen_sensor_is_left_out_and_never_chosen() {
    let mut run = clustered_run();
    let n = run.rows();
    // an unplugged sensor (every field empty), one that reads in a third of
    // the rows, and one stuck at a value
    for (name, col) in [
        ("T_dead", vec![None; n]),
        (
            "T_flaky",
            (0..n)
                .map(|k| (k % 3 == 0).then_some(20.0 + k as f64 * 0.01))
                .collect(),
        ),
        ("T_stuck", vec![Some(21.5); n]),
    ] {
        run.columns.push(name.into());
        run.data.push(col);
    }
    // four groups: a dead sensor would otherwise form a group of its own
    let s = select(&[run], 4, 0).unwrap();
    for name in ["T_dead", "T_flaky", "T_stuck"] {
        assert!(
            s.left_out.contains_key(name),
            "{name} not left out: {:?}",
            s.left_out
        );
        assert!(!s.chosen.iter().any(|c| c == name), "{name} chosen");
        assert!(!s.clusters.iter().flatten().any(|c| c == name));
    }
    assert!(s.left_out["T_flaky"].contains("reads in 200 of 600 rows"));
    assert_eq!(s.chosen.len(), 4);
    // more groups than usable sensors: said, not refused
    let mut run = clustered_run();
    run.columns.push("T_dead".into());
    run.data.push(vec![None; n]);
    let s = select(&[run], 10, 0).unwrap();
    assert_eq!(s.clusters.len(), 9);
    assert!(s.notes[0].contains("9 usable sensors"), "{:?}", s.notes);
}

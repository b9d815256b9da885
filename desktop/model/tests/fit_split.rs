//! Chronological / held-out splits never leak validation rows into training.

use std::collections::HashSet;

use tcomp_data::runcsv::Run;
use tcomp_model::fit::pipeline::Plan;
use tcomp_model::fit::*;

fn run(n: usize) -> Run {
    Run {
        meta: vec![],
        columns: vec!["time_s".into(), "T_a".into(), "dx_um".into()],
        data: vec![
            (0..n).map(|k| Some(k as f64 * 15.0)).collect(),
            (0..n)
                .map(|k| Some(20.0 + (k as f64 / 50.0).sin()))
                .collect(),
            (0..n)
                .map(|k| if k % 7 == 3 { None } else { Some(k as f64) })
                .collect(),
        ],
    }
}

#[test]
fn chrono_split_matches_published_rows() {
    // FL_THERMAL: 11,115 rows, test rows 6,669..8,891.
    let (tr, va) = chrono_split(11115, 0.6, 0.8).unwrap();
    assert_eq!(tr, 0..6669);
    assert_eq!(va, 6669..8892);
    assert!(chrono_split(100, 0.8, 0.6).is_err());
    assert!(chrono_split(100, 0.0, 0.6).is_err());
}

#[test]
fn no_validation_row_is_ever_used_for_training() {
    let runs = vec![run(1000), run(400), run(300)];
    let labels = vec!["a".into(), "b".into(), "c".into()];
    for split in [Some((0.6, 0.8)), None] {
        let plan = Plan::new(runs.clone(), labels.clone(), 2, split).unwrap();
        let kinds = vec![(FeatureKind::SensorRise("T_a".into()), Some(600.0))];
        let cache = SeriesCache::new(&plan.runs, kinds).unwrap();
        let tr = cache
            .samples(&plan.runs, &plan.train, &[0], "dx_um")
            .unwrap();
        let va = cache.samples(&plan.runs, &plan.val, &[0], "dx_um").unwrap();
        let trs: HashSet<_> = tr.rows.iter().copied().collect();
        assert!(
            va.rows.iter().all(|r| !trs.contains(r)),
            "leak with {split:?}"
        );
        // The held-out run never appears in training.
        assert!(tr.rows.iter().all(|(r, _)| *r < 2));
        assert!(va.rows.iter().any(|(r, _)| *r == 2));
        if split.is_some() {
            // Validation rows of a split run all come after its training rows.
            for run_i in 0..2 {
                let max_tr = tr
                    .rows
                    .iter()
                    .filter(|(r, _)| *r == run_i)
                    .map(|x| x.1)
                    .max()
                    .unwrap();
                let min_va = va
                    .rows
                    .iter()
                    .filter(|(r, _)| *r == run_i)
                    .map(|x| x.1)
                    .min()
                    .unwrap();
                assert!(max_tr < min_va);
            }
        }
        // The early-stopping block and the selection folds stay inside training rows.
        let (inner, block) = plan.inner_block(0.15);
        let folds = blocked_folds(&plan.runs, &plan.train, 5);
        for segs in [inner, block]
            .iter()
            .chain(folds.iter().flat_map(|(a, b)| [a, b]))
        {
            let s = cache.samples(&plan.runs, segs, &[0], "dx_um").unwrap();
            assert!(s.rows.iter().all(|r| trs.contains(r)));
        }
        for (fit, val) in &folds {
            let a: HashSet<_> = cache
                .samples(&plan.runs, fit, &[0], "dx_um")
                .unwrap()
                .rows
                .into_iter()
                .collect();
            let b = cache.samples(&plan.runs, val, &[0], "dx_um").unwrap().rows;
            assert!(b.iter().all(|r| !a.contains(r)));
        }
        // Rows without a target are skipped.
        assert!(tr.rows.iter().all(|(_, k)| k % 7 != 3));
    }
    assert!(
        Plan::new(runs.clone(), labels.clone(), 3, None).is_err(),
        "nothing to validate on"
    );
}

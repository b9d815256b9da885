//! Issue 52 item 4's aggregation on small synthetic tallies: the ambiguous
//! rule (with the truth: honest; without: wrong; on a clean case: a false
//! alarm), the worst world per column by rate and per the column's own
//! criteria, ties, and worlds without the cases a rate divides by.

use serde_json::json;
use tcomp_bench::harness::third::count_case;
use tcomp_bench::harness::worst::{criteria, worst_row, Criterion, WorldTally};
use tcomp_bench::harness::Column;

fn tally(
    named: usize,
    honest: usize,
    wrong: usize,
    silent: usize,
    clean: usize,
    fa: usize,
) -> WorldTally {
    WorldTally {
        named,
        honest_untestable: honest,
        wrong_named: wrong,
        silent,
        clean,
        false_alarms: fa,
        ..WorldTally::default()
    }
}

fn worlds_of(row: &[tcomp_bench::harness::worst::Worst], c: Criterion) -> Vec<String> {
    row.iter()
        .find(|w| w.criterion == c)
        .map(|w| w.worlds.iter().map(|(n, _, _)| n.clone()).collect())
        .unwrap_or_default()
}

#[test]
fn ambiguous_answers_count_honest_with_the_truth_and_wrong_without() {
    let mut t = WorldTally::default();
    count_case(
        "ballscrew",
        "honest",
        "ambiguous: ballscrew/convection",
        &mut t,
    )
    .unwrap();
    count_case(
        "chiller",
        "wrong",
        "ambiguous: sensor_lag/bearing_nonlinear",
        &mut t,
    )
    .unwrap();
    count_case("convection", "honest", "", &mut t).unwrap();
    count_case("sensor_lag", "wrong", "bearing_nonlinear", &mut t).unwrap();
    count_case("none", "false_alarm", "ambiguous: coolant/periodic", &mut t).unwrap();
    count_case("none", "quiet", "", &mut t).unwrap();
    count_case(
        "bearing_nonlinear",
        "right_param",
        "parameter:heat:front_brg",
        &mut t,
    )
    .unwrap();
    count_case("ambient_drift", "missed", "", &mut t).unwrap();
    assert_eq!(
        (t.ambiguous_with_truth, t.honest_untestable, t.honest()),
        (1, 1, 2)
    );
    assert_eq!(
        (t.ambiguous_without_truth, t.wrong_named, t.wrong()),
        (1, 1, 2)
    );
    assert_eq!((t.named, t.named_as_parameter, t.silent), (1, 1, 1));
    assert_eq!((t.clean_cases(), t.false_alarms), (2, 1));
    assert_eq!(t.effect_cases(), 6);
    let j = t.json();
    assert_eq!(j["honest"], json!(2));
    assert_eq!(j["wrong"], json!(2));
    // an error is neither named nor silent, but stays in the cases a rate divides by
    count_case("chiller", "error", "tcomp failed", &mut t).unwrap();
    assert_eq!(t.effect_cases(), 7);
    assert!(count_case("chiller", "bogus", "", &mut t).is_err());
}

#[test]
fn the_in_process_tally_splits_its_ambiguous_answers_back_out() {
    // approx.rs' honest and wrong already hold the ambiguous answers
    let v = json!({"named": 5, "honest": 4, "wrong": 3, "silent": 2,
                   "ambiguous_with_truth": 1, "ambiguous_without_truth": 2,
                   "clean_cases": 6, "false_alarms": 1});
    let t = WorldTally::from_column_json(&v);
    assert_eq!((t.honest(), t.wrong()), (4, 3));
    assert_eq!((t.honest_untestable, t.wrong_named), (3, 1));
    assert_eq!(t.effect_cases(), 14);
}

#[test]
fn file_columns_take_the_lowest_named_rate_not_count() {
    // big: 30 named of 100 (30 %), small: 5 of 10 (50 %), mid: 8 of 20 (40 %)
    let pw = vec![
        ("big".to_string(), tally(30, 10, 10, 50, 20, 0)),
        ("small".to_string(), tally(5, 0, 0, 5, 4, 1)),
        ("mid".to_string(), tally(8, 2, 2, 8, 4, 0)),
    ];
    for col in [Column::Exact, Column::Design] {
        assert_eq!(
            criteria(col),
            &[Criterion::LowestNamed, Criterion::HighestFalseAlarms]
        );
        let row = worst_row(col, &pw);
        assert_eq!(worlds_of(&row, Criterion::LowestNamed), vec!["big"]);
        assert_eq!(
            worlds_of(&row, Criterion::HighestFalseAlarms),
            vec!["small"]
        );
        let named = row
            .iter()
            .find(|w| w.criterion == Criterion::LowestNamed)
            .unwrap();
        assert_eq!(named.rate, Some(0.3));
    }
}

#[test]
fn fit_column_takes_named_or_honest_and_wrong_with_ambiguous_folded_in() {
    // a: fewest named but most honest; b: an ambiguous answer without the
    // truth; c: two ambiguous answers with the truth
    let a = tally(1, 8, 1, 0, 3, 0);
    let mut b = tally(4, 2, 2, 2, 3, 0);
    b.ambiguous_without_truth = 1;
    let mut c = tally(3, 1, 1, 3, 3, 0);
    c.ambiguous_with_truth = 2;
    let pw = vec![
        ("a".to_string(), a),
        ("b".to_string(), b),
        ("c".to_string(), c),
    ];
    let row = worst_row(Column::Fit, &pw);
    // the lowest named (a, 1/10) is not a criterion of the fit column
    assert!(row.iter().all(|w| w.criterion != Criterion::LowestNamed));
    // named+honest: a 9/10, b 6/11, c 6/10 -> b
    assert_eq!(worlds_of(&row, Criterion::LowestNamedOrHonest), vec!["b"]);
    // wrong: a 1/10, b 3/11, c 1/10 -> b
    assert_eq!(worlds_of(&row, Criterion::HighestWrong), vec!["b"]);
    // the same answers of c without the truth among them: wrong, so c is
    // now worst by both (named+honest 4/10, wrong 3/10 > 3/11)
    c.ambiguous_without_truth = 2;
    c.ambiguous_with_truth = 0;
    let pw = vec![
        ("a".to_string(), a),
        ("b".to_string(), b),
        ("c".to_string(), c),
    ];
    let row = worst_row(Column::Fit, &pw);
    assert_eq!(worlds_of(&row, Criterion::LowestNamedOrHonest), vec!["c"]);
    assert_eq!(worlds_of(&row, Criterion::HighestWrong), vec!["c"]);
}

#[test]
fn ties_name_every_world_and_empty_worlds_take_no_part() {
    // equal rates with different counts (2/10 and 4/20) tie exactly
    let pw = vec![
        ("x".to_string(), tally(2, 0, 0, 8, 0, 0)),
        ("y".to_string(), tally(4, 0, 0, 16, 5, 0)),
        ("z".to_string(), tally(0, 0, 0, 0, 5, 0)),
    ];
    let row = worst_row(Column::Exact, &pw);
    // z has no effect case: not the lowest named at 0/0
    assert_eq!(worlds_of(&row, Criterion::LowestNamed), vec!["x", "y"]);
    // x has no clean case: the false-alarm tie is y and z only
    assert_eq!(
        worlds_of(&row, Criterion::HighestFalseAlarms),
        vec!["y", "z"]
    );
    let fa = row
        .iter()
        .find(|w| w.criterion == Criterion::HighestFalseAlarms)
        .unwrap();
    assert_eq!(fa.rate, Some(0.0));
    // no world with a case: no rate, no world
    let none = worst_row(Column::Fit, &[("e".to_string(), WorldTally::default())]);
    assert!(none.iter().all(|w| w.rate.is_none() && w.worlds.is_empty()));
}

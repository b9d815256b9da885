//! The worst world per column (issue 52 item 4): one world × column's
//! counts (`WorldTally`), the ambiguous rule that folds an ambiguous answer
//! into honest or wrong, and the `worst` row that names, per column and per
//! criterion, the world that does worst.
//!
//! Criteria: the file columns (exact, design) by the lowest named rate;
//! `diagnose fit` by the lowest named-or-honest rate and the highest wrong
//! rate; every column by the highest false-alarm rate on clean cases. Rates,
//! not counts, because the worlds hold different numbers of cases; a world
//! with no case of the kind a rate divides by takes no part in it; tied
//! worlds are all named.

use serde_json::{json, Value};

use super::approx::Column;

/// One world × column, every effect case in exactly one class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WorldTally {
    /// The true effect named first (right sensor for sensor effects), or a
    /// parameter finding that states its physics.
    pub named: usize,
    /// Of `named`: by a parameter finding.
    pub named_as_parameter: usize,
    /// Nothing named, the truth listed untestable.
    pub honest_untestable: usize,
    /// Nothing named, an ambiguous answer that contains the truth: honest.
    pub ambiguous_with_truth: usize,
    /// Nothing named, an ambiguous answer without the truth: wrong.
    pub ambiguous_without_truth: usize,
    /// Something else named first.
    pub wrong_named: usize,
    /// Nothing named, nothing listed.
    pub silent: usize,
    /// Effect cases the diagnosis failed on (no answer).
    pub effect_errors: usize,
    /// Clean cases answered (errors apart).
    pub clean: usize,
    /// Of `clean`: something named (an ambiguous answer included).
    pub false_alarms: usize,
    /// Clean cases the diagnosis failed on.
    pub clean_errors: usize,
}

/// `k / n`, None when `n` is 0.
fn rate(k: usize, n: usize) -> Option<f64> {
    (n > 0).then(|| k as f64 / n as f64)
}

impl WorldTally {
    pub fn effect_cases(&self) -> usize {
        self.named
            + self.honest_untestable
            + self.ambiguous_with_truth
            + self.ambiguous_without_truth
            + self.wrong_named
            + self.silent
            + self.effect_errors
    }

    pub fn clean_cases(&self) -> usize {
        self.clean + self.clean_errors
    }

    /// Honest: listed untestable, or ambiguous with the truth among them.
    pub fn honest(&self) -> usize {
        self.honest_untestable + self.ambiguous_with_truth
    }

    /// Wrong: something else named, or ambiguous without the truth.
    pub fn wrong(&self) -> usize {
        self.wrong_named + self.ambiguous_without_truth
    }

    pub fn add(&mut self, o: &WorldTally) {
        self.named += o.named;
        self.named_as_parameter += o.named_as_parameter;
        self.honest_untestable += o.honest_untestable;
        self.ambiguous_with_truth += o.ambiguous_with_truth;
        self.ambiguous_without_truth += o.ambiguous_without_truth;
        self.wrong_named += o.wrong_named;
        self.silent += o.silent;
        self.effect_errors += o.effect_errors;
        self.clean += o.clean;
        self.false_alarms += o.false_alarms;
        self.clean_errors += o.clean_errors;
    }

    /// From one column of `run_approx_bench`'s table (`approx.rs`' tally,
    /// whose honest and wrong already hold the ambiguous answers).
    pub fn from_column_json(v: &Value) -> WorldTally {
        let n = |k: &str| v[k].as_u64().unwrap_or(0) as usize;
        let (amb_with, amb_without) = (n("ambiguous_with_truth"), n("ambiguous_without_truth"));
        WorldTally {
            named: n("named"),
            named_as_parameter: 0,
            honest_untestable: n("honest").saturating_sub(amb_with),
            ambiguous_with_truth: amb_with,
            ambiguous_without_truth: amb_without,
            wrong_named: n("wrong").saturating_sub(amb_without),
            silent: n("silent"),
            effect_errors: 0,
            clean: n("clean_cases"),
            false_alarms: n("false_alarms"),
            clean_errors: 0,
        }
    }

    pub fn json(&self) -> Value {
        let (e, c) = (self.effect_cases(), self.clean_cases());
        json!({
            "effect_cases": e,
            "named": self.named,
            "named_as_parameter": self.named_as_parameter,
            "honest": self.honest(),
            "honest_untestable": self.honest_untestable,
            "ambiguous_with_truth": self.ambiguous_with_truth,
            "ambiguous_without_truth": self.ambiguous_without_truth,
            "wrong": self.wrong(),
            "wrong_named": self.wrong_named,
            "silent": self.silent,
            "errors": self.effect_errors + self.clean_errors,
            "clean_cases": c,
            "false_alarms": self.false_alarms,
            "named_rate": rate(self.named, e),
            "named_or_honest_rate": rate(self.named + self.honest(), e),
            "wrong_rate": rate(self.wrong(), e),
            "false_alarm_rate": rate(self.false_alarms, c),
        })
    }
}

/// What a world is judged worst by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Criterion {
    LowestNamed,
    LowestNamedOrHonest,
    HighestWrong,
    HighestFalseAlarms,
}

impl Criterion {
    pub fn key(self) -> &'static str {
        match self {
            Criterion::LowestNamed => "lowest_named_rate",
            Criterion::LowestNamedOrHonest => "lowest_named_or_honest_rate",
            Criterion::HighestWrong => "highest_wrong_rate",
            Criterion::HighestFalseAlarms => "highest_false_alarm_rate",
        }
    }

    /// (count, cases) the rate is.
    fn fraction(self, t: &WorldTally) -> (usize, usize) {
        match self {
            Criterion::LowestNamed => (t.named, t.effect_cases()),
            Criterion::LowestNamedOrHonest => (t.named + t.honest(), t.effect_cases()),
            Criterion::HighestWrong => (t.wrong(), t.effect_cases()),
            Criterion::HighestFalseAlarms => (t.false_alarms, t.clean_cases()),
        }
    }

    fn lower_is_worse(self) -> bool {
        matches!(
            self,
            Criterion::LowestNamed | Criterion::LowestNamedOrHonest
        )
    }
}

/// The criteria of a column (issue 52 item 4).
pub fn criteria(col: Column) -> &'static [Criterion] {
    match col {
        Column::Exact | Column::Design => &[Criterion::LowestNamed, Criterion::HighestFalseAlarms],
        Column::Fit => &[
            Criterion::LowestNamedOrHonest,
            Criterion::HighestWrong,
            Criterion::HighestFalseAlarms,
        ],
    }
}

/// The worst world(s) of one column by one criterion.
#[derive(Clone, Debug, PartialEq)]
pub struct Worst {
    pub criterion: Criterion,
    /// The worst rate (None: no world has a case to divide by).
    pub rate: Option<f64>,
    /// Every world at that rate, with its count and cases.
    pub worlds: Vec<(String, usize, usize)>,
}

impl Worst {
    pub fn json(&self) -> Value {
        json!({
            "criterion": self.criterion.key(),
            "rate": self.rate,
            "worlds": self.worlds.iter().map(|(w, k, n)| json!({"world": w, "count": k, "of": n})).collect::<Vec<_>>(),
        })
    }
}

/// The worst row of one column over `per_world` (world name, tally): one
/// entry per criterion of the column.
pub fn worst_row(col: Column, per_world: &[(String, WorldTally)]) -> Vec<Worst> {
    criteria(col)
        .iter()
        .map(|&c| {
            let mut worst: Vec<(String, usize, usize)> = Vec::new();
            for (w, t) in per_world {
                let (k, n) = c.fraction(t);
                if n == 0 {
                    continue;
                }
                // compare k/n with the current worst exactly: k·n0 against k0·n
                let order = worst.first().map(|(_, k0, n0)| (k * n0).cmp(&(k0 * n)));
                let worse = |o: std::cmp::Ordering| {
                    if c.lower_is_worse() {
                        o.is_lt()
                    } else {
                        o.is_gt()
                    }
                };
                match order {
                    None => worst.push((w.clone(), k, n)),
                    Some(o) if worse(o) => worst = vec![(w.clone(), k, n)],
                    Some(o) if o.is_eq() => worst.push((w.clone(), k, n)),
                    Some(_) => {}
                }
            }
            Worst {
                criterion: c,
                rate: worst.first().and_then(|(_, k, n)| rate(*k, *n)),
                worlds: worst,
            }
        })
        .collect()
}

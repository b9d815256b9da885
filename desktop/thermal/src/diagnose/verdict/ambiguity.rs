//! "Ambiguous": when the evidence cannot separate the best explanation from
//! the next *different* one (another effect class, not the same class with
//! other parameters), nothing is named as the cause; the answer lists the
//! explanations the data cannot tell apart and the measurement that would.
//!
//! The test is the noise gate's own (`gate::z_of`, `gate::Z_MIN`): per
//! held-out block, d = ln((M₀ + 1)/(M₁ + 1)) of each candidate against its
//! own reference (the gate's per-block log reduction); the best candidate's
//! advantage over the other is the paired difference of their d over the
//! blocks where either acts (0 where one does not), and it is significant
//! when z = mean / (sd / √blocks) reaches the gate's one-sided 1 % line.
//! Fewer than two such blocks: no test, so not separated.

use super::gate::{z_of, Z_MIN};

/// The ranking rule's sentence.
pub const RULE: &str = "when the selected effect's held-out advantage over the best-ranked claimed effect of another class (not the same effect with other parameters) is not significant by the gate's own test (per held-out block the difference of their d = ln((M₀ + 1)/(M₁ + 1)), each against its own reference, over the blocks where either acts; z = mean/(sd/√blocks) < 2.33, the one-sided 1 % line, or fewer than two blocks), the answer is ambiguous: nothing is named, `ambiguous` lists the selected effect and up to two such effects of other classes, ranked, and `separate_by` the measurement that would tell them apart";

/// At most this many explanations in an ambiguous answer (the best first).
pub const MAX_AMBIGUOUS: usize = 3;

/// The effect class of a finding's name: the same physics with other
/// parameters (another sensor, the other form of the speed law) is one
/// class; a coolant line found in `diagnose fit`, a chiller and a periodic
/// line are one class (a periodic driver).
pub fn class_of(name: &str) -> &str {
    let head = name.split([' ', ':']).next().unwrap_or(name);
    match head {
        "coolant" | "chiller" | "periodic" => "periodic",
        _ => head,
    }
}

/// Whether the best candidate's held-out advantage over `other` is
/// significant at the gate's level. `best` and `other` hold one entry per
/// held-out block (the same blocks, in the same order): the candidate's d
/// there, or None where it does not act.
pub fn separated(best: &[Option<f64>], other: &[Option<f64>]) -> bool {
    let diff: Vec<f64> = best
        .iter()
        .zip(other)
        .filter(|(a, b)| a.is_some() || b.is_some())
        .map(|(a, b)| a.unwrap_or(0.0) - b.unwrap_or(0.0))
        .collect();
    // NaN (fewer than two blocks) is no test: not separated
    z_of(&diff) >= Z_MIN
}

/// The ambiguous set among claimed candidates in rank order, each given as
/// (name, per-block d): empty when the first is separated from every
/// candidate of another class (it is named); otherwise the indices of the
/// first and of the best-ranked candidate of each other class it is not
/// separated from, at most `MAX_AMBIGUOUS` in all, ranked.
pub fn ambiguous_set(ranked: &[(&str, &[Option<f64>])]) -> Vec<usize> {
    let Some(&(best_name, best_d)) = ranked.first() else {
        return Vec::new();
    };
    let mut out = vec![0];
    let mut classes = vec![class_of(best_name)];
    for (i, &(name, d)) in ranked.iter().enumerate().skip(1) {
        let class = class_of(name);
        if classes.contains(&class) {
            continue;
        }
        classes.push(class);
        if !separated(best_d, d) {
            out.push(i);
            if out.len() == MAX_AMBIGUOUS {
                break;
            }
        }
    }
    if out.len() < 2 {
        Vec::new()
    } else {
        out
    }
}

/// The measurement that would separate two effect classes (a short fixed
/// sentence per pair, a generic one otherwise).
pub fn separating_measurement(a: &str, b: &str) -> &'static str {
    let (a, b) = (class_of(a), class_of(b));
    let pair = |x: &str, y: &str| (a == x && b == y) || (a == y && b == x);
    if pair("sensor_lag", "ballscrew") {
        "a run at another feed rate, or a sensor on the ball-screw nut"
    } else if pair("sensor_lag", "convection") {
        "a run with the enclosure door open and one with it closed, at the same duty"
    } else if pair("sensor_lag", "bearing_nonlinear") {
        "a run at another spindle speed, or a second sensor beside the one that may lag (a lag delays that sensor alone; bearing heat warms both)"
    } else if pair("sensor_lag", "ambient_drift") {
        "an air sensor at the machine (the air it sees, not the room's), or a second sensor beside the one that may lag"
    } else if pair("sensor_lag", "sensor_offset") {
        "a reference thermometer held beside the sensor through a warm-up (a lag delays the change, an offset shifts the level)"
    } else if pair("sensor_lag", "periodic") {
        "a run with the chiller holding a fixed temperature, or a sensor on the coolant return (a lag smooths a cycle, a periodic driver makes one)"
    } else if pair("bearing_nonlinear", "ballscrew") {
        "a run at high spindle speed with the axes still, and one with feed and the spindle stopped"
    } else if pair("bearing_nonlinear", "convection") {
        "runs at two spindle speeds, each with the enclosure door open and closed"
    } else if pair("bearing_nonlinear", "periodic") {
        "a run at constant spindle speed with the chiller holding a fixed temperature"
    } else if pair("bearing_nonlinear", "ambient_drift") {
        "a run at constant spindle speed with an air sensor at the machine"
    } else if pair("bearing_nonlinear", "sensor_offset") {
        "a second sensor beside the one that may have stepped, or a run at another spindle speed"
    } else if pair("ambient_drift", "convection") {
        "an air sensor inside the enclosure, with the door open and closed"
    } else if pair("ambient_drift", "sensor_offset") {
        "a reference thermometer beside the sensor that may have stepped, and an air sensor at the machine"
    } else if pair("ambient_drift", "periodic") {
        "an air sensor at the machine and a sensor on the coolant return"
    } else if pair("sensor_offset", "periodic") {
        "a second sensor beside the one that may have stepped, or a run with the chiller holding a fixed temperature"
    } else if pair("ballscrew", "convection") {
        "a run at another feed rate with the enclosure door open and closed"
    } else if pair("ballscrew", "ambient_drift") {
        "a run with feed and the spindle stopped, and an air sensor at the machine"
    } else {
        "a run whose duty changes what drives one of them and not the other (another spindle speed, feed rate or coolant setting), or a sensor where only one of them would warm the machine"
    }
}

/// The report's sentence per pair: the best against each other member.
pub fn separating_sentences(names: &[String]) -> Vec<String> {
    let Some(best) = names.first() else {
        return Vec::new();
    };
    names
        .iter()
        .skip(1)
        .map(|o| {
            format!(
                "{} or {}: {}",
                class_of(best),
                class_of(o),
                separating_measurement(best, o)
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    // per-block d of a candidate: `mean` plus a fixed ripple of ±`sd`
    fn blocks(mean: f64, sd: f64, n: usize, phase: usize) -> Vec<Option<f64>> {
        (0..n)
            .map(|k| {
                Some(
                    mean + if (k + phase).is_multiple_of(2) {
                        sd
                    } else {
                        -sd
                    },
                )
            })
            .collect()
    }

    #[test]
    fn two_classes_within_noise_are_ambiguous() {
        // the lag reduces slightly more than the bearing law, well inside
        // the spread of the blocks
        let lag = blocks(0.50, 0.3, 40, 0);
        let law = blocks(0.48, 0.3, 40, 1);
        let set = ambiguous_set(&[("sensor_lag", &lag), ("bearing_nonlinear", &law)]);
        assert_eq!(set, vec![0, 1]);
    }

    #[test]
    fn clearly_separated_candidates_name_the_best() {
        let lag = blocks(0.9, 0.05, 40, 0);
        let law = blocks(0.1, 0.05, 40, 0);
        assert!(separated(&lag, &law));
        assert!(ambiguous_set(&[("sensor_lag", &lag), ("bearing_nonlinear", &law)]).is_empty());
    }

    #[test]
    fn the_same_class_twice_is_not_ambiguous() {
        // the lag on another sensor, the speed law in its other form:
        // the same explanation with other parameters
        let a = blocks(0.50, 0.3, 40, 0);
        let b = blocks(0.49, 0.3, 40, 1);
        assert!(ambiguous_set(&[("sensor_lag", &a), ("sensor_lag", &b)]).is_empty());
        assert!(ambiguous_set(&[("bearing_nonlinear", &a), ("bearing_nonlinear", &b)]).is_empty());
        assert!(ambiguous_set(&[("coolant", &a), ("periodic", &b)]).is_empty());
        // a same-class runner-up is skipped: the next different class decides
        let c = blocks(0.1, 0.05, 40, 0);
        assert!(
            ambiguous_set(&[("sensor_lag", &a), ("sensor_lag", &b), ("coolant", &c)]).is_empty()
        );
    }

    #[test]
    fn at_most_three_ranked_and_blocks_where_neither_acts_are_left_out() {
        let a = blocks(0.5, 0.3, 40, 0);
        let b = blocks(0.5, 0.3, 40, 1);
        let set = ambiguous_set(&[
            ("sensor_lag", &a),
            ("sensor_lag", &b),
            ("bearing_nonlinear", &b),
            ("sensor_offset", &a),
            ("coolant", &b),
            ("ambient_drift", &b),
        ]);
        assert_eq!(set, vec![0, 2, 3]);
        // one acting block: no test, so not separated
        let one = [Some(2.0), None, None];
        let none = [None, None, None];
        assert!(!separated(&one, &none));
    }

    #[test]
    fn every_pair_has_a_sentence() {
        assert_eq!(
            separating_measurement("ballscrew", "sensor_lag"),
            "a run at another feed rate, or a sensor on the ball-screw nut"
        );
        assert!(separating_measurement("convection", "sensor_lag").contains("door"));
        assert!(separating_measurement("bending", "sensor_lag").starts_with("a run whose duty"));
        let s = separating_sentences(&["sensor_lag".into(), "bearing_nonlinear".into()]);
        assert_eq!(s.len(), 1);
        assert!(s[0].starts_with("sensor_lag or bearing_nonlinear: a run at another spindle speed"));
    }
}

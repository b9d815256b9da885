//! Issue 49 item 3: the harmonic order of each rotary axis's error motions
//! chosen by the evidence (`rotary::orders`), on the project's own
//! simulator: a machine whose A axis carries a third harmonic no larger
//! than the reading noise gets order ≥ 3 on A, one with first and second
//! harmonics only keeps ≤ 2, each axis judged on its own.

use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::rotary::identify::{identify_rotary, RotaryOptions};
use tcomp_geometry::rotary::orders::{choose_orders, Order, OrderChoice, MAX_ORDER};
use tcomp_geometry::rotary::Axis5;
use tcomp_geometry::rtest::RTestFile;

mod common;
use common::{machine, NOISE_UM};

/// The choices of both axes (`auto`) for the files.
fn choose(files: &[RTestFile]) -> (OrderChoice, OrderChoice) {
    let noise = StatedNoise::new(Some(NOISE_UM)).unwrap();
    let fit = |o: &RotaryOptions| identify_rotary(files, None, o);
    let base = RotaryOptions::default();
    let (o, ch) = choose_orders(fit, &base, Order::Auto, Order::Auto, noise).unwrap();
    let get = |a: &str| ch.iter().find(|c| c.axis == a).unwrap().clone();
    let (a, c) = (get("A"), get("C"));
    assert_eq!((o.order_a, o.order_c), (a.order, c.order));
    for x in [&a, &c] {
        assert_eq!(x.chosen_by, "evidence");
        assert_eq!(x.candidates.len(), MAX_ORDER + 1);
        // the chosen order is the candidate with the largest evidence
        let chosen = &x.candidates[x.order];
        assert_eq!(chosen.order, x.order);
        assert!(x
            .candidates
            .iter()
            .all(|k| k.ln_evidence <= chosen.ln_evidence));
    }
    (a, c)
}

fn show(what: &str, seed: u64, a: &OrderChoice, c: &OrderChoice) {
    let ev = |x: &OrderChoice| {
        (x.candidates.iter())
            .map(|k| format!("{}:{:.1}", k.order, k.ln_evidence))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!(
        "{what} seed {seed}: A {} [{}], C {} [{}]",
        a.order,
        ev(a),
        c.order,
        ev(c)
    );
}

#[test]
fn a_third_harmonic_within_the_noise_on_a_gets_order_three_or_more() {
    for seed in [41, 42, 43] {
        // third-harmonic coefficients ≤ 0.5 µm and ≤ 1.5 µrad (0.3 µm at
        // a 200 mm lever): each reading's share is within its noise
        let (truth, files) = machine(seed, &[Axis5::A], 0.5, 1.5);
        assert_eq!(truth.components["EXA"].cos.len(), 3);
        let (a, c) = choose(&files);
        show("A third", seed, &a, &c);
        assert!(a.order >= 3, "seed {seed}: A order {}", a.order);
        assert!(c.order <= 2, "seed {seed}: C order {}", c.order);
    }
}

#[test]
fn first_and_second_harmonics_only_keep_order_two_or_less() {
    for seed in [41, 42, 43] {
        let (_, files) = machine(seed, &[], 0.0, 0.0);
        let (a, c) = choose(&files);
        show("no third", seed, &a, &c);
        assert!(a.order <= 2, "seed {seed}: A order {}", a.order);
        assert!(c.order <= 2, "seed {seed}: C order {}", c.order);
        // … but not less than the data show: harmonic 2 is there (the
        // simulator's second harmonics are up to half the first's)
        assert!(a.order >= 1 && c.order >= 1, "seed {seed}");
    }
}

#[test]
fn a_third_harmonic_on_c_gets_order_three_or_more_on_c() {
    for seed in [44, 45] {
        let (_, files) = machine(seed, &[Axis5::C], 0.5, 1.5);
        let (a, c) = choose(&files);
        show("C third", seed, &a, &c);
        assert!(c.order >= 3, "seed {seed}: C order {}", c.order);
    }
}

/// Noise alone sometimes pays for a harmonic (seed 44's A above: its
/// third harmonic's χ² gain 31 on 12 coefficients, p ≈ 0.002, took the
/// evidence to order 3): over 30 clean machines not looked at before this
/// test was written, at most 5 % of the axes get more than they have, and
/// a third harmonic within the noise is missed on none.
#[test]
fn false_alarms_and_misses_over_thirty_machines() {
    let (mut over, mut missed) = (0, 0);
    for seed in 200..230 {
        let (_, files) = machine(seed, &[], 0.0, 0.0);
        let (a, c) = choose(&files);
        over += usize::from(a.order > 2) + usize::from(c.order > 2);
        let (_, files) = machine(seed, &[Axis5::A], 0.5, 1.5);
        let (a3, _) = choose(&files);
        missed += usize::from(a3.order < 3);
    }
    println!("30 machines: {over}/60 clean axes above order 2, {missed}/30 third harmonics missed");
    assert!(over <= 3, "{over}/60 clean axes above order 2");
    assert_eq!(missed, 0);
}

#[test]
fn given_orders_are_kept_without_a_fit() {
    let (_, files) = machine(46, &[Axis5::A], 0.5, 1.5);
    let noise = StatedNoise::new(Some(NOISE_UM)).unwrap();
    let fit = |_: &RotaryOptions| -> anyhow::Result<_> { panic!("no fit needed") };
    let (o, ch) = choose_orders(
        fit,
        &RotaryOptions::default(),
        Order::Given(3),
        Order::Given(2),
        noise,
    )
    .unwrap();
    assert_eq!((o.order_c, o.order_a), (3, 2));
    assert!(ch
        .iter()
        .all(|c| c.chosen_by == "given" && c.candidates.is_empty()));
    // and the files fit at those orders
    let id = identify_rotary(&files, None, &o).unwrap();
    assert!(id.unobservable.is_empty());
    assert_eq!("auto".parse::<Order>(), Ok(Order::Auto));
    assert_eq!("4".parse::<Order>(), Ok(Order::Given(4)));
    assert!("7".parse::<Order>().is_err() && "two".parse::<Order>().is_err());
}

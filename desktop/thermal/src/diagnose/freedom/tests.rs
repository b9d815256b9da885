//! The compressed freedom (kept directions, coarser time grid, fit-row
//! SSE without the held-out rows) against the full one, on a
//! machine file 12–15 % off its truth.
use super::*;
use crate::diagnose::calibrate::calibrate;
use crate::diagnose::effect_fit::Stats;
use crate::diagnose::{prepare_all, Options};
use crate::sim::{sim_run, Duty, Effect, SimOptions};
use std::path::PathBuf;

fn desktop() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Two 4 h runs of the truth with a ball-screw heat the design lacks.
fn setup() -> (Machine, Vec<Prepared>) {
    let truth = Machine::load(&desktop().join("machines/turning-center-16.toml")).unwrap();
    let duty = Duty::load(&desktop().join("duty/production-mixed.toml")).unwrap();
    let runs: Vec<_> = (0..2)
        .map(|i| {
            let o = SimOptions {
                effects: vec![Effect::Ballscrew { k_w: 60.0 }],
                seed: 71 + i,
                hours: Some(4.0),
                sample_period_s: Some(10.0),
                noise: true,
            };
            (format!("run{i}"), sim_run(&truth, &duty, &o).unwrap())
        })
        .collect();
    let mut design = truth.clone();
    let f = |k: usize| if k.is_multiple_of(2) { 1.15 } else { 0.88 };
    design
        .c
        .iter_mut()
        .enumerate()
        .for_each(|(k, c)| *c *= f(k));
    design
        .g_amb
        .iter_mut()
        .enumerate()
        .for_each(|(k, g)| *g *= f(k + 1));
    design
        .links
        .iter_mut()
        .enumerate()
        .for_each(|(k, l)| l.2 *= f(k + 3));
    let ps = prepare_all(&design, &runs, &Options::default()).unwrap();
    (design, ps)
}

/// The fit criterion with fit-row SSEs replaced.
fn j_with(st: &Stats, sse: &[f64]) -> f64 {
    let mut st = st.clone();
    st.ch.iter_mut().zip(sse).for_each(|(c, s)| c.sse_fit = *s);
    st.j_fit()
}

#[test]
fn compressed_freedom_matches_the_full_one() {
    let (design, ps) = setup();
    let cal = calibrate(&design, &ps, 2).unwrap();
    let (ks, th) = (&cal.knobs, &cal.theta);
    let full = Freedom::with_tol(&design, ks, th, &ps, 2, 0.0).unwrap();
    let comp = Freedom::new(&design, ks, th, &ps, 2).unwrap();
    let (nd, f) = comp.compression();
    assert!(
        nd < ks.len() || f > 1,
        "nothing compressed: {nd} of {}, every {f} rows",
        ks.len()
    );
    assert_eq!(full.compression(), (ks.len(), 1));
    let ev = crate::diagnose::effect_fit::Evaluator::new(&cal.machine, &ps).unwrap();
    // the calibrated null, the ball-screw explained, and a wrong effect
    let trials = [
        vec![],
        vec![Effect::Ballscrew { k_w: 60.0 }],
        vec![Effect::Convection { h_w_per_m2k: 5.0 }],
    ];
    let mut base = None;
    for eff in &trials {
        let raw = ev.residuals(eff).unwrap();
        let st = ev.stats_of(&raw);
        let (mut rf, mut rc) = (raw.clone(), raw.clone());
        full.correct(&mut rf);
        comp.correct(&mut rc);
        let (sf, sc) = (ev.stats_of(&rf), ev.stats_of(&rc));
        let (jf, jc) = (sf.j_fit(), sc.j_fit());
        // what a claim is judged by: the criterion (a claim needs a BIC
        // gain of 10) and its change from the null, within 1
        assert!(
            (jf - jc).abs() <= 1.0,
            "{eff:?}: j full {jf} compressed {jc}"
        );
        let (bf, bc) = *base.get_or_insert((jf, jc));
        let (gf, gc) = (jf - bf, jc - bc);
        assert!(
            (gf - gc).abs() <= 1.0,
            "{eff:?}: Δj full {gf} compressed {gc}"
        );
        // and the held-out gap (noise units) within 0.1 %
        let (mf, mc) = (sf.m_held(), sc.m_held());
        assert!(
            (mf - mc).abs() <= 1e-3 * mf.max(1.0),
            "{eff:?}: held-out {mf} vs {mc}"
        );
        // the corrections themselves (single design values are collinear,
        // only their combined effect is determined): the corrected
        // residuals differ by at most 0.01 noise units RMS on every channel
        for (p, (a, b)) in ps.iter().zip(rf.iter().zip(&rc)) {
            for (ch, (x, y)) in p.channels.iter().zip(a.iter().zip(b)) {
                let d2: Vec<f64> = x
                    .iter()
                    .zip(y)
                    .map(|(u, v)| ((u - v) / ch.s).powi(2))
                    .filter(|d| d.is_finite())
                    .collect();
                let rms = (d2.iter().sum::<f64>() / d2.len().max(1) as f64).sqrt();
                assert!(
                    rms < 0.01,
                    "{eff:?} {}: corrections differ by {rms} noise units",
                    ch.name
                );
            }
        }
        // the fit rows' SSE without forming the residuals = summing them
        let sse = comp.fit_sse_of(&raw).expect("no missing rows");
        let js = j_with(&st, &sse);
        assert!(
            (js - jc).abs() < 1e-6 * jc.abs().max(1.0),
            "{eff:?}: {js} vs {jc}"
        );
    }
}

//! The compressed freedom (kept directions, coarser time grid, fit-row
//! SSE without the held-out rows) against the full one, on a
//! machine file 12–15 % off its truth.
use super::super::calibrate::calibrate;
use super::*;
use crate::diagnose::effects::Stats;
use crate::diagnose::{prepare_all, Options};
use crate::sim::{sim_run, Duty, Effect, SimOptions};
use std::path::PathBuf;

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Two 4 h runs of the truth with a ball-screw heat the design lacks.
pub(crate) fn setup() -> (Machine, Vec<Prepared>) {
    let truth = Machine::load(&examples().join("machines/turning-center-16.toml")).unwrap();
    let duty = Duty::load(&examples().join("duty/production-mixed.toml")).unwrap();
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
    let ev = crate::diagnose::effects::Evaluator::new(&cal.machine, &ps).unwrap();
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

/// B̃ᵀr over the fit rows from scratch: every row, every direction, B̃
/// as each channel's basis holds it at its fit knots.
fn products_from_scratch(fr: &Freedom, res: &[Vec<Vec<f64>>]) -> Vec<Vec<f64>> {
    let nkn = fr.knots.n_knots;
    let nd = fr.knots_b.len() / nkn;
    // knot → its row of B̃ (one past the end: zeros)
    let kb: Vec<Vec<f64>> = (0..=nkn)
        .map(|k| {
            let held = fr.chans.iter().find_map(|c| c.basis.row(k));
            held.unwrap_or_else(|| {
                (0..nd)
                    .map(|d| {
                        if k < nkn {
                            fr.knots_b[d * nkn + k] as f64
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
        })
        .collect();
    let b = |k: usize, d: usize| kb[k][d];
    let mut out = Vec::new();
    let mut row = 0;
    for ch in res.iter().flatten() {
        let mut h = vec![0.0; nd];
        for &v in ch {
            if fr.fit[row] && v.is_finite() {
                let (j, wb) = (fr.row_knot[row] as usize, fr.row_wb[row]);
                for (d, hd) in h.iter_mut().enumerate() {
                    *hd += ((1.0 - wb) * b(j, d) + wb * b(j + 1, d)) * v;
                }
            }
            row += 1;
        }
        out.push(h);
    }
    out
}

#[test]
fn b_transpose_r_from_the_nominal_s_matches_it_from_scratch_and_reads_only_what_changed() {
    let (design, ps) = setup();
    let cal = calibrate(&design, &ps, 2).unwrap();
    let fr = Freedom::new(&design, &cal.knobs, &cal.theta, &ps, 2).unwrap();
    let ev = crate::diagnose::effects::Evaluator::new(&cal.machine, &ps).unwrap();
    let r0 = ev.residuals(&[]).unwrap();
    // one channel of the second run changed after row 700 (a step), and
    // every channel changed (a thermal effect)
    let mut step = r0.clone();
    step[1][2].iter_mut().skip(700).for_each(|v| *v += 0.4);
    let thermal = ev.residuals(&[Effect::Ballscrew { k_w: 30.0 }]).unwrap();
    for (what, res) in [("nominal", &r0), ("step", &step), ("thermal", &thermal)] {
        let before = (fr.knots_read.load(Relaxed), fr.knots_all.load(Relaxed));
        let (h, rr) = fr.fit_products(res);
        let read = fr.knots_read.load(Relaxed) - before.0;
        let all = fr.knots_all.load(Relaxed) - before.1;
        let want = products_from_scratch(&fr, res);
        for (c, (hc, wc)) in h.iter().zip(&want).enumerate() {
            let scale = wc.iter().map(|x| x.abs()).fold(1e-12, f64::max);
            for (x, y) in hc.iter().zip(wc) {
                assert!(
                    (x - y).abs() <= 1e-9 * scale,
                    "{what} channel {c}: {x} vs {y}"
                );
            }
        }
        assert!(rr.is_some(), "{what}: no missing rows");
        match what {
            "nominal" => assert_eq!(read, 0, "the nominal itself reads nothing"),
            "step" => assert!(
                read > 0 && read * 10 < all,
                "a one-channel step read {read} of {all} knots"
            ),
            _ => assert!(read * 10 > all * 9, "a thermal effect read {read} of {all}"),
        }
    }
}

//! The noise gate: an effect is claimed only when the held-out gap it
//! removes is significant against the measured noise.

use crate::diagnose::runs::Prepared;
use crate::diagnose::signal::mean_finite;

/// Residuals: run → channel → row.
type Residuals = [Vec<Vec<f64>>];

/// One-sided z at 1 %: a claimed reduction must reach it.
pub const Z_MIN: f64 = 2.33;
/// Longest held-out block [s]: a held-out stretch is cut into blocks of at
/// most this length (the slow thermal misfit changes little within one).
pub const BLOCK_S: f64 = 600.0;

/// Held-out blocks: each contiguous stretch of held-out rows of a run
/// where `touched` (the effect changes the prediction there), cut into
/// equal pieces of at most `BLOCK_S`.
fn blocks(
    ps: &[Prepared],
    touched: impl Fn(usize, usize, usize) -> bool,
) -> Vec<(usize, usize, usize)> {
    let mut segs = Vec::new();
    for (pi, p) in ps.iter().enumerate() {
        let mut k = 0;
        while k < p.rows() {
            if p.held[k] {
                let a = k;
                while k < p.rows() && p.held[k] {
                    k += 1;
                }
                if touched(pi, a, k) {
                    segs.push((pi, a, k));
                }
            } else {
                k += 1;
            }
        }
    }
    let mut out = Vec::new();
    for (pi, a, b) in segs {
        let max = ((BLOCK_S / ps[pi].inputs.dt).floor() as usize).max(1);
        let cut = (b - a).div_ceil(max).max(1);
        let len = (b - a).div_ceil(cut).max(1);
        let mut s = a;
        while s < b {
            out.push((pi, s, (s + len).min(b)));
            s += len;
        }
    }
    out
}

/// z of the held-out reduction of the gap against the noise: per held-out
/// block the effect acts on (a sensor step acts after its onset only),
/// d = ln((M₀ + 1)/(M₁ + 1)) with M the block's mean squared gap in noise
/// units (the + 1 is the measured noise: a reduction inside it counts
/// for little), then mean(d) / (sd(d) / √blocks). NaN with fewer than two
/// blocks.
pub fn held_out_z(ps: &[Prepared], r0: &[Vec<Vec<f64>>], r1: &[Vec<Vec<f64>>]) -> f64 {
    held_out_z_acting(ps, r0, r1, (r0, r1))
}

/// `held_out_z` with the blocks an effect acts on read from `acts` (the
/// residuals before and after it *before* the calibration's freedom: the
/// freedom re-solves its correction for every trial and so moves every
/// row a little, which would count every held-out block as acted on and
/// dilute a local effect, a step late in one run, among blocks with d ≈ 0).
pub fn held_out_z_acting(
    ps: &[Prepared],
    r0: &[Vec<Vec<f64>>],
    r1: &[Vec<Vec<f64>>],
    acts: (&Residuals, &Residuals),
) -> f64 {
    let touched = |pi: usize, a: usize, b: usize| {
        let p = &ps[pi];
        p.channels.iter().enumerate().any(|(ci, c)| {
            (a..b).any(|k| {
                let e = acts.0[pi][ci][k] - acts.1[pi][ci][k];
                e.is_finite() && e.abs() > 1e-3 * c.s
            })
        })
    };
    let d: Vec<f64> = blocks(ps, touched)
        .into_iter()
        .filter_map(|(pi, a, b)| {
            let p = &ps[pi];
            let (mut s0, mut s1, mut n) = (0.0, 0.0, 0usize);
            for (ci, c) in p.channels.iter().enumerate() {
                for k in a..b {
                    let (x, y) = (r0[pi][ci][k], r1[pi][ci][k]);
                    if x.is_finite() && y.is_finite() && c.s > 0.0 {
                        s0 += x * x / (c.s * c.s);
                        s1 += y * y / (c.s * c.s);
                        n += 1;
                    }
                }
            }
            (n > 0).then(|| ((s0 / n as f64 + 1.0) / (s1 / n as f64 + 1.0)).ln())
        })
        .collect();
    z_of(&d)
}

/// mean(d) / (sd(d) / √n) of the per-block log reductions; NaN with fewer
/// than two blocks.
pub fn z_of(d: &[f64]) -> f64 {
    if d.len() < 2 {
        return f64::NAN;
    }
    let nb = d.len() as f64;
    let mean = d.iter().sum::<f64>() / nb;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (nb - 1.0);
    if var <= 0.0 {
        return if mean > 0.0 { f64::INFINITY } else { 0.0 };
    }
    mean / (var / nb).sqrt()
}

/// Whether `more` (a pair) beats `base` (its base single) by the gate
/// itself, not only by the margins: a small partner (a low-exponent bearing
/// heat, a slow drift) otherwise soaks up what is left of a design error.
pub fn beats_in_noise(
    ev: &crate::diagnose::effects::Evaluator,
    base: &[crate::sim::Effect],
    more: &[crate::sim::Effect],
) -> anyhow::Result<bool> {
    let (raw_base, r_base) = ev.raw_and_residuals(base)?;
    let (raw_more, r_more) = ev.raw_and_residuals(more)?;
    let z = held_out_z_acting(ev.runs, &r_base, &r_more, (&raw_base, &raw_more));
    Ok(passes(ev.stats_of(&r_base).m_held(), z))
}

/// Whether a reduction passes the gate: the held-out gap before is above
/// one noise unit and the reduction's z reaches `Z_MIN`.
pub fn passes(m_before: f64, z: f64) -> bool {
    m_before > 1.0 && z >= Z_MIN
}

/// Rows on each side of a step's onset over which its jump is measured.
pub const JUMP_ROWS: usize = 3;
/// A step inside a run is a sensor fault only if the nominal residual jumps
/// by at least this share of the fitted step at its onset: a fault is a
/// jump, while a design error (a capacity, a loss to air) changes the
/// residual smoothly, at the pace of the machine's time constants, and a
/// constant fitted from the warm-up on absorbs it without any jump there.
pub const JUMP_SHARE_MIN: f64 = 0.5;

/// The smallest jump share over the steps inside a run among `effects`
/// (sensor offsets with an onset): the nominal residual's mean over
/// `JUMP_ROWS` rows from the onset minus over the `JUMP_ROWS` rows before,
/// in the step's direction, over the step's size (averaged over the runs
/// it acts in; at the onset or, when held-out rows precede it, at the best
/// of those rows). None when there is no such step; NaN when no run has rows
/// on both sides of the onset.
pub fn step_jump_share(
    ps: &[Prepared],
    r0: &[Vec<Vec<f64>>],
    effects: &[crate::sim::Effect],
) -> Option<f64> {
    let mut worst: Option<f64> = None;
    for e in effects {
        let crate::sim::Effect::SensorOffset {
            sensor,
            offset_c,
            at_s,
            run,
        } = e
        else {
            continue;
        };
        if *at_s <= 0.0 {
            continue;
        }
        let mut jumps = Vec::new();
        for (pi, p) in ps.iter().enumerate() {
            if run.as_ref().is_some_and(|r| *r != p.name) {
                continue;
            }
            let Some(ci) = p.channels.iter().position(|c| {
                c.name == *sensor && matches!(c.kind, crate::diagnose::runs::Kind::Temp(_))
            }) else {
                continue;
            };
            let Some(k0) = (0..p.rows()).find(|&k| p.inputs.time(k) >= *at_s) else {
                continue;
            };
            if k0 < JUMP_ROWS || k0 + JUMP_ROWS > p.rows() {
                continue;
            }
            // the onset is placed on fit rows: after held-out rows it may
            // lie anywhere among them, so the jump is sought there too
            let mut lo = k0;
            while lo > JUMP_ROWS && p.held[lo - 1] {
                lo -= 1;
            }
            let r = &r0[pi][ci];
            let j = (lo..=k0)
                .map(|k| {
                    (mean_finite(r[k..k + JUMP_ROWS].iter().copied())
                        - mean_finite(r[k - JUMP_ROWS..k].iter().copied()))
                        * offset_c.signum()
                })
                .filter(|j| j.is_finite())
                .fold(f64::NAN, f64::max);
            if j.is_finite() {
                jumps.push(j);
            }
        }
        let share = if jumps.is_empty() || *offset_c == 0.0 {
            f64::NAN
        } else {
            jumps.iter().sum::<f64>() / jumps.len() as f64 / offset_c.abs()
        };
        worst = Some(match worst {
            None => share,
            Some(w) if w.is_nan() || share.is_nan() => f64::NAN,
            Some(w) => w.min(share),
        });
    }
    worst
}

/// A lone step inside a run (`sensor_offset` with an onset) that the gate
/// cannot test: fewer than two held-out blocks of its run lie after its
/// onset (a step late in the last fit block). Its `untestable` entry (name,
/// why); None for anything else.
pub fn late_step(ps: &[Prepared], effects: &[crate::sim::Effect]) -> Option<(String, String)> {
    let [crate::sim::Effect::SensorOffset {
        sensor,
        offset_c,
        at_s,
        run: Some(run),
    }] = effects
    else {
        return None;
    };
    let pi = ps.iter().position(|p| p.name == *run)?;
    let p = &ps[pi];
    let k0 = (0..p.rows()).find(|&k| p.inputs.time(k) >= *at_s)?;
    let after = blocks(ps, |i, _, b| i == pi && b > k0)
        .into_iter()
        .filter(|&(_, _, b)| b > k0)
        .count();
    (*at_s > 0.0 && after < 2).then(|| {
        (
            format!("sensor_offset (step after the last held-out block) on {sensor}"),
            format!(
                "a step of {offset_c:+.2} °C at {at_s:.0} s in run {run} fits the fit rows, but {after} held-out block(s) of at most {BLOCK_S:.0} s follow its onset: the noise gate needs two; a run held out after the onset (or a longer run) can test it"
            ),
        )
    })
}

/// A sensor fault (lag, offset) changes no displacement: a wider µm gap
/// beside it is the calibration freedom's re-fit to the corrected readings
/// (the null had bent a design value to follow the fault), so the µm gate
/// does not judge it.
pub(super) fn sensor_only(f: &crate::diagnose::types::Finding) -> bool {
    !f.effects.is_empty() && f.effects.iter().all(|e| e.is_sensor_only())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Effect, Inputs};

    // one run of 10 s rows with one sensor channel `T1`; rows 40..60 held out
    fn run(n: usize) -> Prepared {
        Prepared {
            name: "r".into(),
            inputs: Inputs {
                t0: 0.0,
                dt: 10.0,
                rpm: vec![0.0; n],
                feed: vec![0.0; n],
                coolant: vec![0.0; n],
                ambient: vec![20.0; n],
            },
            channels: vec![crate::diagnose::runs::Channel {
                name: "T1".into(),
                kind: crate::diagnose::runs::Kind::Temp(0),
                meas: vec![0.0; n],
                s: 0.02,
            }],
            held: (0..n).map(|k| (40..60).contains(&k)).collect(),
            decimation: 1,
            notes: Vec::new(),
            missing: Vec::new(),
        }
    }

    fn offset(c: f64, at_s: f64) -> Effect {
        Effect::SensorOffset {
            sensor: "T1".into(),
            offset_c: c,
            at_s,
            run: None,
        }
    }

    #[test]
    fn a_step_jumps_and_a_warm_up_misfit_does_not() {
        let n = 100;
        let ps = [run(n)];
        // a 0.5 °C fault at row 20 (200 s)
        let step: Vec<f64> = (0..n).map(|k| if k >= 20 { 0.5 } else { 0.0 }).collect();
        let j = step_jump_share(&ps, &[vec![step]], &[offset(0.5, 200.0)]).unwrap();
        assert!((j - 1.0).abs() < 1e-9, "{j}");
        // a design error: the residual rises with a 10 min time constant,
        // an offset fitted from row 20 on absorbs its level, with no jump
        let smooth: Vec<f64> = (0..n)
            .map(|k| 0.5 * (1.0 - (-(k as f64) * 10.0 / 600.0).exp()))
            .collect();
        let j = step_jump_share(&ps, &[vec![smooth]], &[offset(0.4, 200.0)]).unwrap();
        assert!(j < JUMP_SHARE_MIN, "{j}");
        // a step of the other sign than fitted is no jump of the fit
        let down: Vec<f64> = (0..n).map(|k| if k >= 20 { -0.5 } else { 0.0 }).collect();
        let j = step_jump_share(&ps, &[vec![down]], &[offset(0.5, 200.0)]).unwrap();
        assert!(j < 0.0, "{j}");
        // no step inside a run: nothing to test
        assert!(step_jump_share(&ps, &[vec![vec![0.0; n]]], &[offset(0.5, 0.0)]).is_none());
    }

    #[test]
    fn a_step_among_held_out_rows_is_found_at_the_next_fit_row() {
        let n = 100;
        let ps = [run(n)];
        // the fault happens at row 50 (held out); the scan placed it on the
        // first fit row after, 60
        let step: Vec<f64> = (0..n).map(|k| if k >= 50 { 0.5 } else { 0.0 }).collect();
        let j = step_jump_share(&ps, &[vec![step]], &[offset(0.5, 600.0)]).unwrap();
        assert!((j - 1.0).abs() < 1e-9, "{j}");
    }

    #[test]
    fn a_late_step_is_judged_on_the_blocks_it_acts_on_not_on_the_freedom_s_ripple() {
        // 600 rows of 10 s; held out: 60..120, 180..240, …: five 600 s blocks
        let n = 600;
        let mut p = run(n);
        p.held = (0..n).map(|k| (k / 60) % 2 == 1).collect();
        let ps = [p];
        // a 0.5 °C step from row 400 (two held-out blocks after it)
        let ripple = |k: usize| 0.01 * (k % 7) as f64;
        let r0: Vec<f64> = (0..n)
            .map(|k| ripple(k) + if k >= 400 { 0.5 } else { 0.0 })
            .collect();
        let raw1: Vec<f64> = (0..n).map(ripple).collect();
        // the freedom's re-solved correction moves every row a little
        let r1: Vec<f64> = raw1.iter().map(|v| v + 0.001).collect();
        let (r0, raw1, r1) = ([vec![r0]], [vec![raw1]], [vec![r1]]);
        let diluted = held_out_z(&ps, &r0, &r1);
        let acting = held_out_z_acting(&ps, &r0, &r1, (&r0, &raw1));
        assert!(diluted < Z_MIN, "{diluted}");
        assert!(acting >= Z_MIN, "{acting}");
    }

    #[test]
    fn a_step_with_fewer_than_two_held_out_blocks_after_it_is_untestable() {
        // 300 rows of 10 s; rows 40..140 held out: 1000 s, two blocks
        let mut p = run(300);
        p.held = (0..300).map(|k| (40..140).contains(&k)).collect();
        let ps = [p];
        let step = |at_s: f64| Effect::SensorOffset {
            sensor: "T1".into(),
            offset_c: 0.8,
            at_s,
            run: Some("r".into()),
        };
        // before the held-out stretch: the gate has its two blocks
        assert!(late_step(&ps, &[step(200.0)]).is_none());
        // inside its second block: one left
        let (name, why) = late_step(&ps, &[step(1100.0)]).expect("one block left");
        assert!(
            name.starts_with("sensor_offset") && name.ends_with("on T1"),
            "{name}"
        );
        assert!(why.contains("1 held-out block"), "{why}");
        assert!(why.contains("+0.80 °C"), "{why}");
        // after it: none
        assert!(late_step(&ps, &[step(2000.0)])
            .unwrap()
            .1
            .contains("0 held-out"));
        // a constant offset, a step in no named run, or a pair: not this test's
        assert!(late_step(&ps, &[step(0.0)]).is_none());
        assert!(late_step(&ps, &[offset(0.8, 2000.0)]).is_none());
        assert!(late_step(&ps, &[step(2000.0), step(2500.0)]).is_none());
    }
}

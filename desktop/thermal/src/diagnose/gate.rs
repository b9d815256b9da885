//! The noise gate: an effect is claimed only when the held-out gap it
//! removes is significant against the measured noise.

use super::prep::Prepared;

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
    let touched = |pi: usize, a: usize, b: usize| {
        let p = &ps[pi];
        p.channels.iter().enumerate().any(|(ci, c)| {
            (a..b).any(|k| {
                let e = r0[pi][ci][k] - r1[pi][ci][k];
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

/// Whether a reduction passes the gate: the held-out gap before is above
/// one noise unit and the reduction's z reaches `Z_MIN`.
pub fn passes(m_before: f64, z: f64) -> bool {
    m_before > 1.0 && z >= Z_MIN
}

//! Periodic drivers: a chiller's on/off or sawtooth on the coolant, a
//! shop's HVAC cycle on the air, door cycles (periods 5 min – 2 h) leave a
//! line (and its harmonics) in the residual spectrum of every channel they
//! reach. Found per channel from a least-squares periodogram of the
//! residual, tested against the residual's own local spectrum.
//!
//! Hand-written rather than a crate's Lomb–Scargle: the test needs a
//! sinusoid *and its harmonics* (a sawtooth, an on/off cycle), a phase free
//! per run (runs are separate recordings), nuisance terms per run and rows
//! with gaps, which the generalised least-squares form below gives in a
//! few lines over `nalgebra`; the chi-square tail for even degrees of
//! freedom is a closed form.
//!
//! The test, per channel and trial frequency f: the residual is first
//! differenced (a sensor step becomes one impulse, whose spectrum is flat,
//! and the slow misfit of a thermal model, red, becomes nearly flat), a
//! per-run level and slope are projected out, and sin/cos of f, 2f, 3f are
//! fitted per run. Their explained sum of squares over the local background
//! σ² (the median, per degree of freedom, of the same statistic over
//! [f/2, 2f] away from f's harmonic relatives) is χ² with 2·H·runs degrees
//! of freedom when the residual has no line at f. The smallest tail
//! probability over channels and frequencies, multiplied by (channels ×
//! trial frequencies, 5 per independent one), must be below `ALPHA`.

use nalgebra::DMatrix;
use rayon::prelude::*;

/// Periods searched [s]: 5 min – 2 h.
pub const PERIOD_MIN_S: f64 = 300.0;
pub const PERIOD_MAX_S: f64 = 7200.0;
/// Sinusoid plus harmonics fitted at each trial frequency (a sawtooth's
/// and an on/off cycle's first three lines).
pub const HARMONICS: usize = 3;
/// Level of the test after the correction for the channels and the
/// trial frequencies.
pub const ALPHA: f64 = 1e-3;
/// Trial frequencies per independent frequency (1 / longest run).
const OVERSAMPLE: f64 = 5.0;
/// Background ordinates needed for the local median: four independent
/// frequencies (a median of fewer is too loose a yardstick).
const MIN_BACKGROUND: usize = 4 * OVERSAMPLE as usize;
/// Cycles the shortest run must hold of the longest period searched.
pub const MIN_CYCLES: f64 = 3.0;

/// One channel's residual, per run.
#[derive(Clone, Debug)]
pub struct Chan {
    pub name: String,
    pub is_disp: bool,
    /// Noise scale (°C or µm).
    pub noise: f64,
    /// run → row: measured − model (NaN where missing).
    pub resid: Vec<Vec<f64>>,
}

/// The residuals searched: times and held-out rows per run, and channels.
#[derive(Clone, Debug)]
pub struct Scan {
    pub times: Vec<Vec<f64>>,
    pub held: Vec<Vec<bool>>,
    pub chans: Vec<Chan>,
}

/// The strongest line found.
#[derive(Clone, Debug)]
pub struct Line {
    pub chan: usize,
    pub period_s: f64,
    /// χ² of the line against the local background, its degrees of freedom.
    pub chi2: f64,
    pub dof: usize,
    /// ln of the single-test tail probability.
    pub ln_p: f64,
    /// Tail probability × number of tests (capped at 1).
    pub p_corrected: f64,
    pub n_tests: f64,
}

impl Line {
    pub fn significant(&self) -> bool {
        self.p_corrected < ALPHA
    }
}

/// Rows of one run (mid times when differenced) and the orthonormal
/// nuisance basis (Legendre polynomials up to `deg`).
struct RunBasis {
    tm: Vec<f64>,
    nuis: Vec<Vec<f64>>,
    dt: f64,
}

fn run_basis(t: &[f64], diff: bool, deg: usize) -> RunBasis {
    let t0 = t.first().copied().unwrap_or(0.0);
    let tm: Vec<f64> = if diff {
        (0..t.len().saturating_sub(1))
            .map(|k| 0.5 * (t[k] + t[k + 1]) - t0)
            .collect()
    } else {
        t.iter().map(|x| x - t0).collect()
    };
    let n = t.len().saturating_sub(1);
    let dt = if n > 0 { (t[n] - t[0]) / n as f64 } else { 1.0 };
    let span = tm.last().copied().unwrap_or(1.0).max(1e-9);
    let mut nuis: Vec<Vec<f64>> = Vec::new();
    for d in 0..=deg {
        let mut v: Vec<f64> = tm
            .iter()
            .map(|x| (2.0 * x / span - 1.0).powi(d as i32))
            .collect();
        for u in &nuis {
            let c: f64 = v.iter().zip(u).map(|(x, y)| x * y).sum();
            v.iter_mut().zip(u).for_each(|(x, y)| *x -= c * y);
        }
        normalise(&mut v);
        nuis.push(v);
    }
    RunBasis { tm, nuis, dt }
}

fn normalise(v: &mut [f64]) {
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 {
        v.iter_mut().for_each(|x| *x /= n);
    }
}

fn project_out(v: &mut [f64], b: &RunBasis) {
    for u in &b.nuis {
        let c: f64 = v.iter().zip(u).map(|(x, y)| x * y).sum();
        v.iter_mut().zip(u).for_each(|(x, y)| *x -= c * y);
    }
}

/// The residual (differenced when the basis is), missing values as 0,
/// nuisance removed.
fn prepared_resid(e: &[f64], b: &RunBasis) -> Vec<f64> {
    let diff = b.tm.len() < e.len();
    let mut d: Vec<f64> = (0..b.tm.len())
        .map(|k| {
            let v = if diff { e[k + 1] - e[k] } else { e[k] };
            if v.is_finite() {
                v
            } else {
                0.0
            }
        })
        .collect();
    if !diff {
        // the mean of the finite rows stands in for the missing ones
        let (s, n) = e
            .iter()
            .filter(|v| v.is_finite())
            .fold((0.0, 0usize), |a, v| (a.0 + v, a.1 + 1));
        let m = if n > 0 { s / n as f64 } else { 0.0 };
        d.iter_mut()
            .zip(e)
            .filter(|(_, v)| !v.is_finite())
            .for_each(|(x, _)| *x = m);
    }
    project_out(&mut d, b);
    d
}

/// Explained sum of squares of sin/cos at f, 2f, … per channel (summed
/// over runs) and its degrees of freedom.
///
/// Speed (≈ 3,000 calls of ≈ 6 k rows per diagnosis): the q ≤ 6 columns
/// are kept interleaved by row, and the sums that read them (the
/// nuisance's coefficients, the Gram matrix, each channel's projections)
/// run side by side in one pass, each still one running sum over the rows
/// in order — the same sums as one dot at a time, not waiting on each
/// other's additions.
fn explained(bases: &[RunBasis], diffs: &[Vec<Vec<f64>>], f: f64) -> (Vec<f64>, usize) {
    let nc = diffs.len();
    let mut out = vec![0.0; nc];
    let mut dof = 0usize;
    for (r, b) in bases.iter().enumerate() {
        let n = b.tm.len();
        // harmonics below 0.45 of the Nyquist rate only
        let h_max = (1..=HARMONICS)
            .filter(|&h| h as f64 * f * b.dt < 0.45)
            .count();
        if h_max == 0 || n < 4 * HARMONICS + 4 {
            continue;
        }
        let w = std::f64::consts::TAU * f;
        let q = 2 * h_max;
        // row t: sin, cos of f, then of 2f, …
        let mut m = vec![0.0; n * q];
        for (row, t) in m.chunks_exact_mut(q).zip(&b.tm) {
            harmonics(w * t, row);
        }
        for u in &b.nuis {
            let c = row_sums(&m, q, u);
            for (row, &uv) in m.chunks_exact_mut(q).zip(u) {
                for (x, ci) in row.iter_mut().zip(&c) {
                    *x -= ci * uv;
                }
            }
        }
        // q is 2·h_max, h_max ≤ HARMONICS = 3
        let g = match q {
            2 => gram::<2>(&m),
            4 => gram::<4>(&m),
            _ => gram::<6>(&m),
        };
        let Some(ch) = g.cholesky() else {
            continue;
        };
        for (c, d) in diffs.iter().enumerate() {
            let bv = nalgebra::DVector::from_column_slice(&row_sums(&m, q, &d[r]));
            out[c] += bv.dot(&ch.solve(&bv));
        }
        dof += q;
    }
    (out, dof)
}

/// sin, cos of x, 2x, 3x into `row` (as many as it holds), from one
/// sin_cos by the angle-sum formulas (within a few ulp of each its own
/// sin_cos, at a third of the cost).
fn harmonics(x: f64, row: &mut [f64]) {
    let (s1, c1) = x.sin_cos();
    let (s2, c2) = (2.0 * s1 * c1, (c1 - s1) * (c1 + s1));
    let (s3, c3) = (s2 * c1 + c2 * s1, c2 * c1 - s2 * s1);
    for (o, v) in row.iter_mut().zip([s1, c1, s2, c2, s3, c3]) {
        *o = v;
    }
}

/// Σ_t m[t][i]·v[t] for every column i of the row-interleaved `m` (q
/// columns), each one running sum over t in order.
fn row_sums(m: &[f64], q: usize, v: &[f64]) -> Vec<f64> {
    match q {
        2 => row_sums_of::<2>(m, v).to_vec(),
        4 => row_sums_of::<4>(m, v).to_vec(),
        _ => row_sums_of::<6>(m, v).to_vec(),
    }
}

/// `row_sums` for Q columns: the Q sums in registers (a fixed count).
fn row_sums_of<const Q: usize>(m: &[f64], v: &[f64]) -> [f64; Q] {
    let mut acc = [0.0f64; Q];
    for (row, &x) in m.chunks_exact(Q).zip(v) {
        for k in 0..Q {
            acc[k] += row[k] * x;
        }
    }
    acc
}

/// The Gram matrix of the Q row-interleaved columns of `m`, a row of
/// sums per pass (Q running sums in registers; the lower triangle is
/// the upper one's, the same products).
fn gram<const Q: usize>(m: &[f64]) -> DMatrix<f64> {
    let mut g = DMatrix::zeros(Q, Q);
    for i in 0..Q {
        let mut acc = [0.0f64; Q];
        for row in m.chunks_exact(Q) {
            let x = row[i];
            for j in 0..Q {
                acc[j] += x * row[j];
            }
        }
        for j in i..Q {
            g[(i, j)] = acc[j];
            g[(j, i)] = acc[j];
        }
    }
    g
}

/// ln P(χ²_dof > x) for even `dof` (closed form: a Poisson sum).
pub fn ln_chi2_tail_even(x: f64, dof: usize) -> f64 {
    let m = dof / 2;
    if x <= 0.0 || m == 0 {
        return 0.0;
    }
    let h = x / 2.0;
    // ln Σ_{j<m} h^j / j!, by log-sum-exp
    let terms: Vec<f64> = (0..m)
        .scan(0.0, |acc, j| {
            if j > 0 {
                *acc += h.ln() - (j as f64).ln();
            }
            Some(*acc)
        })
        .collect();
    let top = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let s: f64 = terms.iter().map(|t| (t - top).exp()).sum();
    (-h + top + s.ln()).min(0.0)
}

/// Median of χ²_q / q (Wilson–Hilferty).
fn chi2_median_per_dof(q: usize) -> f64 {
    let q = q.max(1) as f64;
    (1.0 - 2.0 / (9.0 * q)).powi(3)
}

/// The residuals prepared per channel and run, and the run bases.
struct Prepared {
    bases: Vec<RunBasis>,
    diffs: Vec<Vec<Vec<f64>>>,
    /// Longest and shortest run [s].
    t_max: f64,
    t_min: f64,
}

/// Differenced with a level and slope per run (the test), or as read with
/// a cubic per run (which of a line's relatives is its fundamental).
fn prepare(scan: &Scan, diff: bool) -> Prepared {
    let deg = if diff { 1 } else { 3 };
    let bases: Vec<RunBasis> = scan.times.iter().map(|t| run_basis(t, diff, deg)).collect();
    let diffs = scan
        .chans
        .iter()
        .map(|c| {
            c.resid
                .iter()
                .zip(&bases)
                .map(|(e, b)| prepared_resid(e, b))
                .collect()
        })
        .collect();
    let spans: Vec<f64> = scan
        .times
        .iter()
        .map(|t| t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0))
        .collect();
    Prepared {
        bases,
        diffs,
        t_max: spans.iter().copied().fold(0.0, f64::max),
        t_min: spans.iter().copied().fold(f64::INFINITY, f64::min),
    }
}

/// The searched frequency band [Hz] (None: the runs are too short or too
/// coarse for any period of the range).
// No caller: public API while `periodic` was `diagnose::periodic`; kept
// (moves only, issue 48) until someone decides to drop it.
#[allow(dead_code)]
pub fn band(scan: &Scan) -> Option<(f64, f64)> {
    let pr = prepare(scan, true);
    band_of(&pr)
}

fn band_of(pr: &Prepared) -> Option<(f64, f64)> {
    let dt = pr.bases.iter().map(|b| b.dt).fold(0.0, f64::max);
    // at least `MIN_CYCLES` cycles in the shortest run, four rows per cycle
    let p_hi = PERIOD_MAX_S.min(pr.t_min / MIN_CYCLES);
    let p_lo = PERIOD_MIN_S.max(4.0 * dt);
    (p_lo < p_hi && pr.t_max > 0.0).then(|| (1.0 / p_hi, 1.0 / p_lo))
}

/// Whether g is near a harmonic relative of f (h'·g ≈ h·f), so it carries
/// part of f's line and must not set the background.
fn related(f: f64, g: f64, width: f64) -> bool {
    (1..=HARMONICS).any(|h| (1..=HARMONICS).any(|k| (k as f64 * g - h as f64 * f).abs() < width))
}

/// Strongest line in the search band `search` [Hz], with the number of
/// tests it is corrected for (`n_tests`, or channels × trial
/// frequencies of the band when None). Among the significant frequencies
/// of a channel, the one whose sinusoid and harmonics explain the most of
/// the residual as read (`raw`) is the line's fundamental; of those within
/// `TIE` of that, the highest (a line's subharmonics fit it as a harmonic).
fn detect(pr: &Prepared, raw: &Prepared, search: (f64, f64), n_tests: Option<f64>) -> Option<Line> {
    let (grid, spec, lines) = detect_all(pr, raw, search, n_tests);
    let mut b = lines.into_iter().next()?;
    refine(pr, &grid, &spec, &mut b, detect_width(pr));
    Some(b)
}

fn detect_width(pr: &Prepared) -> f64 {
    1.0 / pr.t_min.max(1.0)
}

/// Every channel's line as `detect` picks it (not refined), strongest
/// (smallest tail probability) first, with the grid and its spectrum.
type Detected = (Vec<f64>, Vec<(Vec<f64>, usize)>, Vec<Line>);

fn detect_all(pr: &Prepared, raw: &Prepared, search: (f64, f64), n_tests: Option<f64>) -> Detected {
    let df = 1.0 / (OVERSAMPLE * pr.t_max);
    let (lo, hi) = (search.0 / 4.0, (search.1 * 2.0).max(search.0 * 4.0));
    let n_grid = ((hi - lo) / df).ceil() as usize + 1;
    let grid: Vec<f64> = (0..n_grid).map(|i| lo + i as f64 * df).collect();
    let spec: Vec<(Vec<f64>, usize)> = grid
        .par_iter()
        .map(|&f| explained(&pr.bases, &pr.diffs, f))
        .collect();
    let nc = pr.diffs.len();
    // every trial frequency of the band counts as a test (the grid is
    // oversampled: this over-counts the independent ones, which pays for
    // the background being a median of a few ordinates, not a known σ²)
    let n_tests = n_tests.unwrap_or_else(|| {
        let tried = grid
            .iter()
            .filter(|&&f| f >= search.0 && f <= search.1)
            .count();
        nc as f64 * tried.max(1) as f64
    });
    let ln_level = (ALPHA / n_tests).ln();
    let width = detect_width(pr);
    // per channel: (grid index, ln p, χ², dof) of every searched frequency
    let mut tested: Vec<Vec<(usize, f64, f64, usize)>> = vec![Vec::new(); nc];
    for (i, &f) in grid.iter().enumerate() {
        if f < search.0 || f > search.1 || spec[i].1 == 0 {
            continue;
        }
        for (c, t) in tested.iter_mut().enumerate() {
            let Some(s2) = background(&grid, &spec, c, f, width) else {
                continue;
            };
            let (z, q) = (spec[i].0[c], spec[i].1);
            t.push((i, ln_chi2_tail_even(z / s2, q), z / s2, q));
        }
    }
    let line = |c: usize, t: &(usize, f64, f64, usize)| Line {
        chan: c,
        period_s: 1.0 / grid[t.0],
        chi2: t.2,
        dof: t.3,
        ln_p: t.1,
        p_corrected: (t.1.exp() * n_tests).min(1.0),
        n_tests,
    };
    let mut lines: Vec<Line> = Vec::new();
    for (c, t) in tested.iter().enumerate() {
        let sig: Vec<&(usize, f64, f64, usize)> = t.iter().filter(|x| x.1 < ln_level).collect();
        let pick = if sig.is_empty() {
            t.iter().min_by(|a, b| a.1.total_cmp(&b.1))
        } else {
            let power = |x: &(usize, f64, f64, usize)| {
                explained(&raw.bases, std::slice::from_ref(&raw.diffs[c]), grid[x.0]).0[0]
            };
            let pw: Vec<f64> = sig.iter().map(|x| power(x)).collect();
            let top = pw.iter().copied().fold(0.0, f64::max);
            sig.iter()
                .zip(&pw)
                .filter(|(_, p)| **p >= TIE * top)
                .map(|(x, _)| *x)
                .max_by_key(|x| x.0)
        };
        if let Some(x) = pick {
            lines.push(line(c, x));
        }
    }
    // strongest first; of equals, the first channel (as one pass kept it)
    lines.sort_by(|a, b| a.ln_p.total_cmp(&b.ln_p));
    (grid, spec, lines)
}

/// Share of the largest explained power within which a higher frequency is
/// preferred as the fundamental.
const TIE: f64 = 0.95;

/// Local background σ² per degree of freedom of channel `c` around f:
/// over [f/2, 2f], or [f/4, 4f] when too few ordinates are left there.
fn background(
    grid: &[f64],
    spec: &[(Vec<f64>, usize)],
    c: usize,
    f: f64,
    width: f64,
) -> Option<f64> {
    for wide in [2.0, 4.0] {
        let mut bg: Vec<f64> = grid
            .iter()
            .zip(spec)
            .filter(|(&g, s)| g >= f / wide && g <= wide * f && s.1 > 0 && !related(f, g, width))
            .map(|(_, s)| s.0[c] / (s.1 as f64 * chi2_median_per_dof(s.1)))
            .collect();
        if bg.len() < MIN_BACKGROUND {
            continue;
        }
        bg.sort_by(f64::total_cmp);
        let m = bg[bg.len() / 2];
        return (m > 0.0).then_some(m);
    }
    None
}

/// The line's period refined on a finer grid around the peak (the
/// background kept from the grid).
fn refine(pr: &Prepared, grid: &[f64], spec: &[(Vec<f64>, usize)], b: &mut Line, width: f64) {
    let f0 = 1.0 / b.period_s;
    let Some(s2) = background(grid, spec, b.chan, f0, width) else {
        return;
    };
    let df = 1.0 / (OVERSAMPLE * pr.t_max);
    let one = [pr.diffs[b.chan].clone()];
    for j in -10..=10 {
        let f = f0 + df * j as f64 / 10.0;
        let (z, q) = explained(&pr.bases, &one, f);
        if q == 0 {
            continue;
        }
        let chi2 = z[0] / s2;
        let ln_p = ln_chi2_tail_even(chi2, q);
        if ln_p < b.ln_p {
            b.period_s = 1.0 / f;
            b.chi2 = chi2;
            b.dof = q;
            b.ln_p = ln_p;
            b.p_corrected = (ln_p.exp() * b.n_tests).min(1.0);
        }
    }
}

/// The strongest line of the residuals over the whole period range.
pub fn strongest_line(scan: &Scan) -> Option<Line> {
    let pr = prepare(scan, true);
    let band = band_of(&pr)?;
    detect(&pr, &prepare(scan, false), band, None)
}

/// Each channel's strongest line over the whole period range, strongest
/// first (each refined as `strongest_line` refines its one): a weaker
/// channel's line may pass what the strongest fails (a duty misfit on a
/// heated node outranks a chiller's line on the coolant sensor).
pub fn lines_by_channel(scan: &Scan) -> Vec<Line> {
    let pr = prepare(scan, true);
    let Some(band) = band_of(&pr) else {
        return Vec::new();
    };
    let (grid, spec, mut lines) = detect_all(&pr, &prepare(scan, false), band, None);
    for l in lines.iter_mut() {
        refine(&pr, &grid, &spec, l, detect_width(&pr));
    }
    lines
}

/// The strongest line within ±10 % of `period_s`, corrected for as many
/// tests as `n_tests` (the original search's): whether a line survives
/// another model.
pub fn line_near(scan: &Scan, period_s: f64, n_tests: f64) -> Option<Line> {
    let pr = prepare(scan, true);
    let f = 1.0 / period_s;
    detect(
        &pr,
        &prepare(scan, false),
        (f / 1.1, f / 0.9),
        Some(n_tests),
    )
}

/// Per channel: the single-frequency test at `period_s` (ln p, corrected
/// for the channels only: the frequency is fixed).
pub fn at_period(scan: &Scan, period_s: f64) -> Vec<f64> {
    let pr = prepare(scan, true);
    let f = 1.0 / period_s;
    let df = 1.0 / (OVERSAMPLE * pr.t_max);
    let (lo, hi) = (f / 4.0, f * 4.0);
    let n_grid = ((hi - lo) / df).ceil() as usize + 1;
    let grid: Vec<f64> = (0..n_grid).map(|i| lo + i as f64 * df).collect();
    let spec: Vec<(Vec<f64>, usize)> = grid
        .par_iter()
        .map(|&g| explained(&pr.bases, &pr.diffs, g))
        .collect();
    let (z, q) = explained(&pr.bases, &pr.diffs, f);
    let width = 1.0 / pr.t_min.max(1.0);
    (0..pr.diffs.len())
        .map(|c| match background(&grid, &spec, c, f, width) {
            Some(s2) if q > 0 => ln_chi2_tail_even(z[c] / s2, q),
            _ => 0.0,
        })
        .collect()
}

/// The periodic waveform of one channel at `period_s`, fitted per run on
/// the rows `use_row` picks, with a cubic per run for the slow misfit:
/// (half peak-to-peak amplitude averaged over the runs by rows, the
/// waveform at every row of every run).
pub fn waveform(
    scan: &Scan,
    chan: usize,
    period_s: f64,
    use_row: &dyn Fn(usize, usize) -> bool,
) -> (f64, Vec<Vec<f64>>) {
    let w = std::f64::consts::TAU / period_s;
    let (mut amp_sum, mut n_sum) = (0.0, 0usize);
    let mut waves = Vec::new();
    for (r, t) in scan.times.iter().enumerate() {
        let e = &scan.chans[chan].resid[r];
        let n = t.len();
        let t0 = t.first().copied().unwrap_or(0.0);
        let span = (t.last().copied().unwrap_or(0.0) - t0).max(1e-9);
        let row = |k: usize| -> Vec<f64> {
            let u = 2.0 * (t[k] - t0) / span - 1.0;
            let mut v = vec![1.0, u, 1.5 * u * u - 0.5, 2.5 * u * u * u - 1.5 * u];
            for h in 1..=HARMONICS {
                let (s, c) = (h as f64 * w * (t[k] - t0)).sin_cos();
                v.push(s);
                v.push(c);
            }
            v
        };
        let rows: Vec<usize> = (0..n)
            .filter(|&k| e[k].is_finite() && use_row(r, k))
            .collect();
        let p = 4 + 2 * HARMONICS;
        let coef = if rows.len() > 2 * p {
            // each row's terms once (not once per column)
            let xr: Vec<Vec<f64>> = rows.iter().map(|&k| row(k)).collect();
            let x = DMatrix::from_fn(rows.len(), p, |i, j| xr[i][j]);
            let y = nalgebra::DVector::from_fn(rows.len(), |i, _| e[rows[i]]);
            tcomp_numerics::linalg::ridge(&x, &y, 1e-9)
        } else {
            None
        };
        let Some(coef) = coef else {
            waves.push(vec![0.0; n]);
            continue;
        };
        let periodic = |t: f64| -> f64 {
            (1..=HARMONICS)
                .map(|h| {
                    let (s, c) = (h as f64 * w * t).sin_cos();
                    coef[2 + 2 * h] * s + coef[3 + 2 * h] * c
                })
                .sum()
        };
        let (lo, hi) = (0..240)
            .map(|i| periodic(period_s * i as f64 / 240.0))
            .fold((f64::MAX, f64::MIN), |a, v| (a.0.min(v), a.1.max(v)));
        amp_sum += 0.5 * (hi - lo) * rows.len() as f64;
        n_sum += rows.len();
        waves.push((0..n).map(|k| periodic(t[k] - t0)).collect());
    }
    (amp_sum / n_sum.max(1) as f64, waves)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chi2_tail_matches_known_values() {
        // P(χ²_2 > x) = e^(−x/2); P(χ²_4 > 9.488) ≈ 0.05
        assert!((ln_chi2_tail_even(3.0, 2) + 1.5).abs() < 1e-12);
        assert!((ln_chi2_tail_even(9.488, 4).exp() - 0.05).abs() < 1e-3);
        assert!((ln_chi2_tail_even(26.217, 12).exp() - 0.01).abs() < 1e-3);
    }

    fn noise(seed: u64, n: usize) -> Vec<f64> {
        let mut g = tcomp_numerics::rng::Rng::paired(seed);
        (0..n).map(|_| g.normal()).collect()
    }

    fn scan_of(resid: Vec<Vec<f64>>, dt: f64) -> Scan {
        let times: Vec<Vec<f64>> = resid
            .iter()
            .map(|r| (0..r.len()).map(|k| k as f64 * dt).collect())
            .collect();
        Scan {
            held: times.iter().map(|t| vec![false; t.len()]).collect(),
            times,
            chans: vec![Chan {
                name: "T".into(),
                is_disp: false,
                noise: 1.0,
                resid,
            }],
        }
    }

    /// `explained` as written first: one column, one dot at a time.
    fn explained_by_single_dots(
        bases: &[RunBasis],
        diffs: &[Vec<Vec<f64>>],
        f: f64,
    ) -> (Vec<f64>, usize) {
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (mut out, mut dof) = (vec![0.0; diffs.len()], 0);
        for (r, b) in bases.iter().enumerate() {
            let h_max = (1..=HARMONICS)
                .filter(|&h| h as f64 * f * b.dt < 0.45)
                .count();
            if h_max == 0 || b.tm.len() < 4 * HARMONICS + 4 {
                continue;
            }
            let w = std::f64::consts::TAU * f;
            let mut cols = vec![Vec::new(); 2 * h_max];
            for t in &b.tm {
                let mut row = vec![0.0; 2 * h_max];
                harmonics(w * t, &mut row);
                cols.iter_mut().zip(row).for_each(|(c, v)| c.push(v));
            }
            cols.iter_mut().for_each(|c| project_out(c, b));
            let q = cols.len();
            let g = DMatrix::from_fn(q, q, |i, j| dot(&cols[i], &cols[j]));
            let ch = g.cholesky().expect("independent columns");
            for (c, d) in diffs.iter().enumerate() {
                let bv = nalgebra::DVector::from_fn(q, |i, _| dot(&cols[i], &d[r]));
                out[c] += bv.dot(&ch.solve(&bv));
            }
            dof += q;
        }
        (out, dof)
    }

    #[test]
    fn harmonics_are_the_sines_and_cosines_of_the_multiples() {
        for x in [0.0, 0.3, -2.0, 17.5, 1234.567, -98765.4321] {
            let mut row = [0.0; 6];
            harmonics(x, &mut row);
            for h in 1..=3 {
                let (s, c) = (h as f64 * x).sin_cos();
                // the multiple h·x itself is rounded: allow for that
                let tol = 1e-15 * (1.0 + h as f64 * x.abs());
                assert!((row[2 * h - 2] - s).abs() < tol, "sin {h}·{x}");
                assert!((row[2 * h - 1] - c).abs() < tol, "cos {h}·{x}");
            }
        }
    }

    #[test]
    fn the_side_by_side_sums_are_the_single_dots_bit_for_bit() {
        // two runs of different lengths, three channels, a gap in one
        let dt = 10.0;
        let resid: Vec<Vec<f64>> = vec![noise(3, 700), noise(4, 513)];
        let mut scan = scan_of(resid, dt);
        for k in [5, 6, 7] {
            scan.chans[0].resid[1][k] = f64::NAN;
        }
        for c in 1..3 {
            let mut ch = scan.chans[0].clone();
            ch.resid = vec![noise(10 + c as u64, 700), noise(20 + c as u64, 513)];
            scan.chans.push(ch);
        }
        for diff in [true, false] {
            let pr = prepare(&scan, diff);
            // one to three harmonics under the rate's limit
            for f in [1.0 / 4000.0, 1.0 / 700.0, 1.0 / 55.0, 1.0 / 31.0] {
                let (a, qa) = explained(&pr.bases, &pr.diffs, f);
                let (b, qb) = explained_by_single_dots(&pr.bases, &pr.diffs, f);
                assert_eq!(qa, qb, "f {f}");
                assert!(qa > 0);
                for (x, y) in a.iter().zip(&b) {
                    assert_eq!(x.to_bits(), y.to_bits(), "f {f}, differenced {diff}");
                }
            }
        }
    }

    #[test]
    fn a_sine_in_white_noise_is_found_and_white_noise_alone_is_not() {
        let n = 1440;
        let dt = 10.0;
        let sine: Vec<Vec<f64>> = (0..2)
            .map(|r| {
                noise(r, n)
                    .iter()
                    .enumerate()
                    .map(|(k, e)| {
                        0.02 * e + 0.02 * (k as f64 * dt / 1500.0 * std::f64::consts::TAU).sin()
                    })
                    .collect()
            })
            .collect();
        let l = strongest_line(&scan_of(sine, dt)).unwrap();
        assert!(l.significant(), "{l:?}");
        assert!((l.period_s / 1500.0 - 1.0).abs() < 0.03, "{l:?}");
        for seed in 10..40 {
            let white: Vec<Vec<f64>> = (0..2).map(|r| noise(seed * 2 + r, n)).collect();
            let l = strongest_line(&scan_of(white, dt)).unwrap();
            assert!(!l.significant(), "seed {seed}: {l:?}");
        }
    }
}

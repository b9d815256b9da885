//! The periodic driver as a candidate of both modes: the residual scan of
//! `periodic.rs` on the nominal's residual, a finding with its period and
//! amplitude, and where it ranks against the other effects: a line still
//! there after the selected effect is something that effect does not
//! explain; it goes first when the selected effect is a sensor step (a
//! sawtooth's ramp-and-drop reads locally as one) or explains less of
//! the held-out gap.

use serde_json::{json, Value};

use super::effect_fit::Evaluator;
pub use super::periodic::Line;

/// A periodic candidate: its finding, its line, whether it is claimed.
pub type Candidate = (Finding, Line, bool);
use super::periodic::{self, Chan, Scan, ALPHA, HARMONICS, PERIOD_MAX_S, PERIOD_MIN_S};
use crate::diagnose::ident::{ModelFit, Problem, Structure};
use crate::diagnose::runs::Kind;
use crate::diagnose::signal::r4;
use crate::diagnose::types::Finding;

/// Smallest amplitude claimed, in noise units of the channel (amplitude
/// of the fundamental, so a swing of ± that many noise σ). A line is found
/// against the residual's own background, so with hours of 10 s samples a
/// line of one or two noise units is highly significant — and a model's
/// misfit of a varying duty leaves such lines on a healthy machine (the
/// seed-13 benches: 1.8–2.2 noise units on clean cases with a design file
/// 15 % off). A driver a user acts on (a chiller band, an HVAC cycle) moves
/// its sensor by tenths of a degree, ten and more noise units.
pub const MIN_AMP_NOISE: f64 = 3.0;

/// Share of the held-out gap (noise units) of the channels a line shows
/// on that its waveform, fitted on the fit rows, must take away.
pub const MIN_HELD_SHRINK: f64 = 0.1;

/// The ranking rule's sentence on periodic drivers.
pub fn rule() -> String {
    format!("; periodic drivers (periodic, {PERIOD_MIN_S:.0}–{PERIOD_MAX_S:.0} s): per channel, the residual differenced, a level and slope per run projected out, sin/cos of f and {} harmonics fitted per run (phase free per run); their χ² against the local background (median over [f/2, 2f] away from f's harmonic relatives) must have a tail probability × (channels × trial frequencies, 5 per independent one) below {ALPHA}, an amplitude ≥ {MIN_AMP_NOISE} noise units, the inputs (spindle_rpm, feed_activity) must not repeat at that period (the same test on them: then the line is the model's misfit of a repeating duty), its waveform fitted on the fit rows must take ≥ {:.0} % of the held-out gap of the channels it shows on away, and it must not widen the held-out gap; it ranks first when the line survives the selected effect (still significant and ≥ {MIN_AMP_NOISE} noise units in that effect's residual) and that effect is a sensor offset or step (a sawtooth reads locally as a step; a lag cannot make a line) or leaves a larger held-out gap", HARMONICS - 1, MIN_HELD_SHRINK * 100.0)
}

/// Machine-file mode: the scan of the nominal residual (`res0`).
pub fn scan_machine(ev: &Evaluator, res: &[Vec<Vec<f64>>]) -> Scan {
    let ps = ev.runs;
    let times = ps
        .iter()
        .map(|p| (0..p.rows()).map(|k| p.inputs.time(k)).collect())
        .collect();
    let held = ps.iter().map(|p| p.held.clone()).collect();
    // channels by name over the runs (a channel missing in a run is NaN there)
    let mut chans: Vec<Chan> = Vec::new();
    for (pi, p) in ps.iter().enumerate() {
        for (ci, c) in p.channels.iter().enumerate() {
            let i = match chans.iter().position(|x| x.name == c.name) {
                Some(i) => i,
                None => {
                    chans.push(Chan {
                        name: c.name.clone(),
                        is_disp: matches!(c.kind, Kind::Disp(_)),
                        noise: c.s,
                        resid: ps.iter().map(|q| vec![f64::NAN; q.rows()]).collect(),
                    });
                    chans.len() - 1
                }
            };
            chans[i].resid[pi] = res[pi][ci].clone();
        }
    }
    Scan { times, held, chans }
}

/// `diagnose fit`: the scan of a fitted model's residual (outputs whose
/// fit has no residual take the nominal's).
pub fn scan_fit(p: &Problem, fit: &ModelFit, nominal: &ModelFit) -> Scan {
    let ds = p.ds;
    let chans = p
        .outputs
        .iter()
        .enumerate()
        .map(|(o, out)| {
            let f = if fit.outs[o].resid.len() == ds.runs.len() {
                &fit.outs[o]
            } else {
                &nominal.outs[o]
            };
            Chan {
                name: out.name.clone(),
                is_disp: out.is_disp,
                noise: out.noise,
                resid: f.resid.clone(),
            }
        })
        .collect();
    Scan {
        times: ds.runs.iter().map(|r| r.time.clone()).collect(),
        held: ds.runs.iter().map(|r| r.held.clone()).collect(),
        chans,
    }
}

/// Held-out gap of a scan: mean over (run, channel) of the held-out mean
/// square in noise units, and per unit (RMS, peak).
struct Gap {
    m: f64,
    um: Option<(f64, f64)>,
    c: Option<(f64, f64)>,
}

fn gap(scan: &Scan, sub: &[Option<Vec<Vec<f64>>>], only: Option<&[usize]>) -> Gap {
    let (mut m, mut nm) = (0.0, 0usize);
    let mut unit = [(0.0, 0usize, 0.0f64); 2];
    for (ci, c) in scan.chans.iter().enumerate() {
        if only.is_some_and(|o| !o.contains(&ci)) {
            continue;
        }
        for (r, e) in c.resid.iter().enumerate() {
            let (mut s, mut n) = (0.0, 0usize);
            for (k, v) in e.iter().enumerate() {
                let v = v - sub[ci].as_ref().map_or(0.0, |w| w[r][k]);
                if scan.held[r][k] && v.is_finite() {
                    s += v * v;
                    n += 1;
                    let u = &mut unit[c.is_disp as usize];
                    u.0 += v * v;
                    u.1 += 1;
                    u.2 = u.2.max(v.abs());
                }
            }
            if n > 0 {
                m += s / n as f64 / (c.noise * c.noise).max(1e-18);
                nm += 1;
            }
        }
    }
    let rms = |u: (f64, usize, f64)| (u.1 > 0).then(|| ((u.0 / u.1 as f64).sqrt(), u.2));
    Gap {
        m: if nm > 0 { m / nm as f64 } else { f64::NAN },
        c: rms(unit[0]),
        um: rms(unit[1]),
    }
}

/// The periodic candidate of a scan: the strongest line, the channels it
/// shows on (each tested at the line's period, corrected for the
/// channels), their amplitudes, the held-out gap with the waveforms fitted
/// on the fit rows; `claimed` when the line is significant, large enough
/// and does not widen the held-out gap.
///
/// `gap_scan`: the residual the held-out gap is scored on (its model fitted
/// on the fit rows); `scan`, the one searched, may be the same model
/// fitted on every row (`diagnose fit`: a model fitted on the fit blocks
/// alone leaves a residual whose size alternates with the blocks, a line
/// of its own).
pub fn candidate(scan: &Scan, gap_scan: &Scan, inputs: &Scan) -> Option<(Finding, Line, bool)> {
    let line = periodic::strongest_line(scan)?;
    Some(candidate_of(line, scan, gap_scan, None, inputs))
}

/// `scan` with every residual less its centred moving mean over one
/// `period_s` (NaN rows left out of the mean; the window shortened at a
/// run's ends): what is at the line's frequency and above. A line's
/// waveform averages to zero over its period and stays; a slow misfit
/// (a level, a drift, the model's lag behind a duty) goes.
fn high_pass(scan: &Scan, period_s: f64) -> Scan {
    let mut out = scan.clone();
    for ch in out.chans.iter_mut() {
        for (e, t) in ch.resid.iter_mut().zip(&scan.times) {
            let n = e.len();
            let dt = if n > 1 {
                (t[n - 1] - t[0]) / (n - 1) as f64
            } else {
                1.0
            };
            let half = ((0.5 * period_s / dt.max(1e-9)).round() as usize).max(1);
            // prefix sums of the finite values and their count
            let (mut sum, mut cnt) = (vec![0.0; n + 1], vec![0usize; n + 1]);
            for k in 0..n {
                let ok = e[k].is_finite();
                sum[k + 1] = sum[k] + if ok { e[k] } else { 0.0 };
                cnt[k + 1] = cnt[k] + ok as usize;
            }
            for k in 0..n {
                let (a, b) = (k.saturating_sub(half), (k + half + 1).min(n));
                let c = cnt[b] - cnt[a];
                if e[k].is_finite() && c > 0 {
                    e[k] -= (sum[b] - sum[a]) / c as f64;
                }
            }
        }
    }
    out
}

/// The periodic candidate of one line of `scan` (see [`candidate`]).
/// `share_scan` (machine-file mode): the residual the line's share of the
/// held-out gap is judged on — the selected explanation's when there is
/// one, else the nominal's — high-passed at the line's period, so that
/// it is judged at its own frequency: a slow misfit (a tank the cycling
/// chiller holds away from its design level) must not dwarf the line.
/// None (`diagnose fit`): `gap_scan` as read.
pub fn candidate_of(
    line: Line,
    scan: &Scan,
    gap_scan: &Scan,
    share_scan: Option<&Scan>,
    inputs: &Scan,
) -> (Finding, Line, bool) {
    // a duty that repeats at the line's period drives the line through the
    // model's misfit of the duty: not a driver of its own
    let ni = inputs.chans.len().max(1) as f64;
    let duty_lnp = periodic::at_period(inputs, line.period_s);
    let duty_periodic = duty_lnp.iter().any(|l| *l < (ALPHA / ni).ln());
    let nc = scan.chans.len();
    let ln_alpha = (ALPHA / nc.max(1) as f64).ln();
    let at = periodic::at_period(scan, line.period_s);
    let mut on: Vec<usize> = (0..nc).filter(|&c| at[c] < ln_alpha).collect();
    if !on.contains(&line.chan) {
        on.push(line.chan);
    }
    let mut sub: Vec<Option<Vec<Vec<f64>>>> = vec![None; nc];
    let mut sub_share: Vec<Option<Vec<Vec<f64>>>> = vec![None; nc];
    let share = share_scan.map(|sh| high_pass(sh, line.period_s));
    let mut chans_json = Vec::new();
    let mut amp_best = 0.0;
    for &c in &on {
        let (amp, _) = periodic::waveform(scan, c, line.period_s, &|_, _| true);
        let (_, held_wave) =
            periodic::waveform(gap_scan, c, line.period_s, &|r, k| !gap_scan.held[r][k]);
        sub[c] = Some(held_wave);
        if let Some(sh) = &share {
            let (_, w) = periodic::waveform(sh, c, line.period_s, &|r, k| !sh.held[r][k]);
            sub_share[c] = Some(w);
        }
        let ch = &scan.chans[c];
        if c == line.chan {
            amp_best = amp;
        }
        chans_json.push(json!({
            "channel": ch.name,
            "unit": if ch.is_disp { "µm" } else { "°C" },
            "amplitude": r4(amp),
            "amplitude_over_noise": r4(amp / ch.noise.max(1e-12)),
            "ln_p_at_period": r4(at[c]),
        }));
    }
    let before = gap(gap_scan, &vec![None; nc], None);
    let after = gap(gap_scan, &sub, None);
    // on the channels it shows on, the line must take a share of the
    // held-out gap away (a line inside what the model misses is no driver)
    let (sh, sh_sub) = match &share {
        Some(sh) => (sh, &sub_share),
        None => (gap_scan, &sub),
    };
    let on_before = gap(sh, &vec![None; nc], Some(&on)).m;
    let on_after = gap(sh, sh_sub, Some(&on)).m;
    let held_shrink = 1.0 - on_after / on_before.max(1e-18);

    let best = &scan.chans[line.chan];
    let big_enough = amp_best >= MIN_AMP_NOISE * best.noise;
    let no_worse = |b: Option<(f64, f64)>, a: Option<(f64, f64)>| match (b, a) {
        (Some(b), Some(a)) => a.0 <= b.0 * 1.02 + 1e-12,
        _ => true,
    };
    let claimed = line.significant()
        && !duty_periodic
        && held_shrink >= MIN_HELD_SHRINK
        && big_enough
        && after.m.is_finite()
        && after.m <= before.m
        && no_worse(before.um, after.um)
        && no_worse(before.c, after.c);
    let unit_key = if best.is_disp {
        "amplitude_um"
    } else {
        "amplitude_c"
    };
    let mut params = json!({
        "channel": best.name,
        "period_s": r4(line.period_s),
        "period_min": r4(line.period_s / 60.0),
        "channels": chans_json,
    });
    params[unit_key] = json!(r4(amp_best));
    let n_fit: usize = scan.held.iter().flatten().filter(|h| !**h).count();
    let f = Finding {
        name: "periodic".into(),
        effects: Vec::new(),
        // the line's χ² as a −2 ln LR, with BIC's penalty for its dof
        dbic: -line.chi2 + line.dof as f64 * (n_fit.max(2) as f64).ln(),
        m_before: before.m,
        m_after: after.m,
        gap_um: before.um.zip(after.um),
        gap_c: before.c.zip(after.c),
        evidence: json!({
            "channel": best.name,
            "period_s": r4(line.period_s),
            "amplitude": r4(amp_best),
            "unit": if best.is_disp { "µm" } else { "°C" },
            "chi2": r4(line.chi2),
            "dof": line.dof,
            "p_value_single": line.ln_p.exp(),
            "tests": line.n_tests,
            "p_value_corrected": line.p_corrected,
            "level": ALPHA,
            "significant": line.significant(),
            "duty_repeats_at_period": duty_periodic,
            "held_out_shrink_on_its_channels": r4(held_shrink),
            "held_out_shrink_of": if share_scan.is_some() { "the selected explanation's residual" } else { "the nominal's residual" },
            "amplitude_over_noise": r4(amp_best / best.noise.max(1e-12)),
            "held_out_norm_gap_before": r4(before.m.sqrt()),
            "held_out_norm_gap_after": r4(after.m.sqrt()),
            "test": "least-squares periodogram of the differenced residual, sinusoid + harmonics per run against the local background, χ² tail × tests",
        }),
        params: Some(params),
    };
    (f, line, claimed)
}

fn set_role(f: &mut Finding, role: &str) {
    if let Some(o) = f.evidence.as_object_mut() {
        o.insert("role".into(), json!(role));
    }
}

/// A selected effect made only of sensor offsets (steps): a sawtooth's
/// ramp-and-drop reads locally as one. A lag is not among them: it only
/// filters what the sensor's node does, so it cannot make a line — a line
/// on a lagging sensor is the node's own swing, which the lag explains.
fn reads_as_step(f: &Finding) -> bool {
    f.name.split('+').all(|n| n == "sensor_offset")
}

/// Put the periodic candidate among the findings. `survives`: whether the
/// line is still significant in the residual of the selected effect
/// (None: nothing selected).
pub fn merge(
    findings: &mut Vec<Finding>,
    tried: &mut Vec<Finding>,
    cand: Option<(Finding, Line, bool)>,
    survives: impl FnOnce(&Line) -> bool,
) {
    let Some((mut f, line, claimed)) = cand else {
        return;
    };
    tried.push(f.clone());
    if !claimed {
        return;
    }
    let Some(sel) = findings.first() else {
        set_role(&mut f, "selected");
        findings.push(f);
        return;
    };
    let survives = survives(&line);
    if let Some(o) = f.evidence.as_object_mut() {
        o.insert("survives_selected_effect".into(), json!(survives));
    }
    if !survives {
        set_role(
            &mut f,
            "alternative: the selected effect explains this periodic line",
        );
        findings.push(f);
    } else if reads_as_step(sel) || f.m_after <= sel.m_after {
        set_role(&mut f, "selected");
        for g in findings.iter_mut() {
            if g.evidence["role"] == "selected" {
                set_role(
                    g,
                    "alternative: explains less than the periodic line, which it leaves",
                );
            }
        }
        findings.insert(0, f);
    } else {
        set_role(
            &mut f,
            "also present: a periodic line the selected effect leaves",
        );
        findings.insert(1, f);
    }
}

/// Whether the line (period, tests) is still claimable in `scan`:
/// significant and at least `MIN_AMP_NOISE` noise units on its channel,
/// as a claim must be (a selected effect that leaves a trace of the line,
/// significant over hours of samples but under the floor, explains it).
pub fn line_survives(scan: &Scan, line: &Line) -> bool {
    periodic::line_near(scan, line.period_s, line.n_tests).is_some_and(|l| {
        let (amp, _) = periodic::waveform(scan, l.chan, l.period_s, &|_, _| true);
        l.significant() && amp >= MIN_AMP_NOISE * scan.chans[l.chan].noise
    })
}

/// The report's paragraph on the periodic scan (empty when none ran).
pub fn report_md(tried: &[Finding]) -> String {
    let Some(f) = tried.iter().find(|f| f.name == "periodic") else {
        return String::new();
    };
    let e = &f.evidence;
    let v = |k: &str| e.get(k).cloned().unwrap_or(Value::Null);
    format!(
        "### Periodic drivers\n\nStrongest line of the residual spectrum: period {} s on `{}`, amplitude {} {} ({} noise units); χ² {} on {} dof, p = {:.2e} single, {:.2e} × {} tests (level {}): {}.\n\n",
        v("period_s"),
        e["channel"].as_str().unwrap_or("?"),
        v("amplitude"),
        e["unit"].as_str().unwrap_or(""),
        v("amplitude_over_noise"),
        v("chi2"),
        v("dof"),
        e["p_value_single"].as_f64().unwrap_or(f64::NAN),
        e["p_value_corrected"].as_f64().unwrap_or(f64::NAN),
        e["tests"].as_f64().unwrap_or(f64::NAN),
        ALPHA,
        if e["significant"].as_bool() == Some(true) { "significant" } else { "not significant" }
    )
}

/// Machine-file mode: the scan of the nominal residual and its periodic
/// candidate: the first line, strongest first over the channels, that
/// earns a claim (each channel's line corrected for every channel and
/// trial frequency, as the strongest is; its share of the held-out gap
/// judged on `selected`, the residual of the explanation selected so far,
/// when there is one); none claimed: the strongest line's candidate, for
/// the report. None when `--only` leaves it out or no line is found.
pub fn machine_candidate(
    ev: &Evaluator,
    res0: &[Vec<Vec<f64>>],
    selected: Option<&[Vec<Vec<f64>>]>,
    only: &[String],
) -> Option<Candidate> {
    if !wanted(only) {
        return None;
    }
    let scan = scan_machine(ev, res0);
    let share = selected.map_or_else(|| scan.clone(), |r| scan_machine(ev, r));
    let inputs = Scan {
        chans: ["spindle_rpm", "feed_activity"]
            .iter()
            .enumerate()
            .map(|(i, n)| Chan {
                name: n.to_string(),
                is_disp: false,
                noise: 1.0,
                resid: ev
                    .runs
                    .iter()
                    .map(|p| {
                        if i == 0 {
                            p.inputs.rpm.clone()
                        } else {
                            p.inputs.feed.clone()
                        }
                    })
                    .collect(),
            })
            .collect(),
        ..scan.clone()
    };
    let mut cand: Option<(Finding, Line, bool)> = None;
    for (i, line) in periodic::lines_by_channel(&scan).into_iter().enumerate() {
        // a line that is not significant cannot be claimed (the strongest
        // is kept for the report)
        if i > 0 && !line.significant() {
            break;
        }
        let c = candidate_of(line, &scan, &scan, Some(&share), &inputs);
        if c.2 {
            cand = Some(c);
            break;
        }
        cand.get_or_insert(c);
    }
    cand
}

/// Machine-file mode: merge the candidate of [`machine_candidate`] (the
/// line tested again on `selected`, the residual of the selected effects;
/// None: nothing selected or it has no effects).
pub fn machine(
    ev: &Evaluator,
    cand: Option<(Finding, Line, bool)>,
    selected: Option<&[Vec<Vec<f64>>]>,
    findings: &mut Vec<Finding>,
    tried: &mut Vec<Finding>,
) {
    merge(findings, tried, cand, |line| match selected {
        Some(r) => line_survives(&scan_machine(ev, r), line),
        None => true,
    });
}

/// The residual `res` (run → channel → row) with the line's waveform at
/// `period_s` taken out of the channels named `names`, each fitted on the
/// fit rows (with a cubic per run for the slow misfit, which stays): what
/// a model leaves away from the line.
pub fn minus_line(
    ev: &Evaluator,
    res: &[Vec<Vec<f64>>],
    period_s: f64,
    names: &[String],
) -> Vec<Vec<Vec<f64>>> {
    let scan = scan_machine(ev, res);
    let mut out = res.to_vec();
    for (c, ch) in scan.chans.iter().enumerate() {
        if !names.contains(&ch.name) {
            continue;
        }
        let (_, wave) = periodic::waveform(&scan, c, period_s, &|r, k| !scan.held[r][k]);
        for (pi, p) in ev.runs.iter().enumerate() {
            if let Some(ci) = p.channels.iter().position(|x| x.name == ch.name) {
                for (v, w) in out[pi][ci].iter_mut().zip(&wave[pi]) {
                    *v -= w;
                }
            }
        }
    }
    out
}

/// The strongest line of the nominal's residual (the nominal's structure
/// fitted on every row; the input channels searched beside it) with its
/// finding and whether the periodic test claims it. It does not depend on
/// any selected effect: `diagnose fit` asks it before choosing one (a
/// `coolant` candidate needs a line at its period, `coolant_line.rs`) and
/// merges it after ([`merge_line`]). `None` when the all-rows fit fails
/// (the test cannot run), `Some(None)` when the residual has no line.
pub type LineCand = Option<(Finding, Line, bool)>;

pub fn line(p: &Problem, st: &Structure, nominal: &ModelFit) -> Option<LineCand> {
    // the nominal's structure fitted on every row: the residual searched
    let mut all_rows = p.ds.clone();
    for r in all_rows.runs.iter_mut() {
        r.held.iter_mut().for_each(|h| *h = false);
    }
    let pa = Problem::new(&all_rows);
    let fa = pa.fit(st, None, None);
    if fa.outs.iter().any(|o| o.failed) {
        return None;
    }
    let scan = scan_fit(&pa, &fa, &fa);
    let runs = &p.ds.runs;
    let inputs = Scan {
        chans: [
            |r: &crate::diagnose::runs::RunData| r.rpm.clone(),
            |r: &crate::diagnose::runs::RunData| r.feed.clone(),
        ]
        .iter()
        .filter(|get| runs.iter().all(|r| get(r).is_some()))
        .map(|get| Chan {
            name: "input".into(),
            is_disp: false,
            noise: 1.0,
            resid: runs.iter().map(|r| get(r).unwrap_or_default()).collect(),
        })
        .collect(),
        ..scan.clone()
    };
    Some(candidate(&scan, &scan_fit(p, nominal, nominal), &inputs))
}

/// Periodic drivers in `diagnose fit`: the [`line`] merged into the
/// findings (unless `--only` leaves it out); beside a `selected` effect's
/// fit it must survive that effect's residual to be named first.
pub fn merge_line(
    p: &Problem,
    nominal: &ModelFit,
    selected: Option<&ModelFit>,
    cand: LineCand,
    (findings, tried): (&mut Vec<Finding>, &mut Vec<Finding>),
    only: &[String],
) {
    if !wanted(only) {
        return;
    }
    merge(findings, tried, cand, |line| match selected {
        Some(s) => line_survives(&scan_fit(p, s, nominal), line),
        None => true,
    });
}

/// Whether `--only` leaves the periodic scan in.
pub fn wanted(only: &[String]) -> bool {
    only.is_empty() || only.iter().any(|o| o == "periodic")
}

//! `tcomp diagnose fit <runs…>`: the diagnosis without a machine file.
//! The nominal model is identified from the runs (`ident`), the gap is
//! located on its residual, and only the effects an identified nominal
//! cannot absorb are tested (`open_effects`); everything else is listed as
//! untestable with the reason.

use anyhow::Result;
use serde_json::{json, Value};

use super::fit_nominal::{no_effect_evidence, nominal_json, run_phases, where_of};
pub use super::fit_untestable::untestable;
pub use super::margins::*;
use super::{coolant_line, reach, undecided};
use crate::diagnose::effects::open_effects::{self, Candidate, LAG_MIN_FIT_REL, LAG_MIN_RUN_REL};
use crate::diagnose::effects::{lag_specific, periodic_claim};
use crate::diagnose::ident::{ModelFit, Problem, Structure};
use crate::diagnose::signal::r4;
use crate::diagnose::types::{Diagnosis, Finding, Options, SelectedGaps};
use crate::diagnose::verdict;
use tcomp_data::runcsv::Run;

/// A candidate scored against its reference fit (the nominal, or for
/// `sensor_lag` the static displacement map).
struct Scored {
    finding: Finding,
    claimed: bool,
    /// Held-out reduction in noise units summed over the affected outputs.
    gain: f64,
    /// The fit with the effect and the reference it is scored against
    /// (`None`: the nominal).
    fit: ModelFit,
    before: Option<ModelFit>,
    /// The gate's d per held-out block against its reference (`held_out_d`):
    /// what the ambiguity test compares between candidates.
    blocks_d: Vec<Option<f64>>,
}

/// A candidate's fit against its reference (the nominal or its own).
struct Measures {
    /// Held-out gap (noise units, affected outputs) before and after.
    m_b: f64,
    m_a: f64,
    dbic: f64,
    /// Held-out µm and °C gaps (RMS, peak) before and after.
    gum: Option<((f64, f64), (f64, f64))>,
    gc: Option<((f64, f64), (f64, f64))>,
}

fn measure(p: &Problem, c: &Candidate, before: &ModelFit) -> Measures {
    let outs = &p.outputs;
    let n = before.n_fit().max(2) as f64;
    Measures {
        m_b: before.m_held_of(outs, &c.affected),
        m_a: c.fit.m_held_of(outs, &c.affected),
        dbic: c.fit.j_fit(outs) - before.j_fit(outs) + c.k_extra as f64 * n.ln(),
        gum: before.gap_held(outs, true).zip(c.fit.gap_held(outs, true)),
        gc: before
            .gap_held(outs, false)
            .zip(c.fit.gap_held(outs, false)),
    }
}

/// Held-out reduction in noise units summed over the affected outputs.
fn held_out_gain(p: &Problem, c: &Candidate, before: &ModelFit, nominal: &ModelFit) -> f64 {
    let outs = &p.outputs;
    let gain_over = |b: &ModelFit| -> f64 {
        c.affected
            .iter()
            .filter(|&&o| b.outs[o].n_held > 0)
            .map(|&o| {
                (b.outs[o].sse_held - c.fit.outs[o].sse_held)
                    / b.outs[o].n_held as f64
                    / outs[o].noise.powi(2)
            })
            .sum()
    };
    // the speed law ranks by the smaller shrink (over its reference, over
    // the nominal): the other candidates are ranked against the nominal
    if c.name == "bearing_nonlinear" {
        gain_over(before).min(gain_over(nominal))
    } else {
        gain_over(before)
    }
}

/// Whether the candidate is claimed, and (for the speed law against its
/// own reference) whether it also beats the nominal.
fn claim(
    p: &Problem,
    c: &Candidate,
    has_reference: bool,
    nominal: &ModelFit,
    ms: &Measures,
    min: &Options,
) -> (bool, bool) {
    let outs = &p.outputs;
    let (m_b, m_a) = (ms.m_b, ms.m_a);
    let no_worse =
        |g: Option<((f64, f64), (f64, f64))>| g.is_none_or(|g| g.1 .0 <= g.0 .0 * (1.0 + 1e-9));
    // sensor lag is judged against the lagged body map, which is itself
    // approximate: the relative held-out shrink of the other effects
    // (its fit rows must also shrink by `LAG_MIN_FIT_REL`, below)
    // a sensor fault belongs to one channel: modelled, it takes most of that
    // channel's gap away (found steps and lags on the open-world cases left
    // ≤ 0.57 of it; on clean runs the nominal's misfit read as a step or a
    // lag that left 0.63–0.70)
    let min_rel = if matches!(c.name, "sensor_offset" | "sensor_lag") {
        SENSOR_MIN_REL
    } else {
        FIT_MIN_REL
    };
    let periodic_ok = c.name != "coolant"
        || c.evidence["peak_over_median_power"]
            .as_f64()
            .is_some_and(|v| v >= PERIODIC_MIN_PEAK);
    // ambient_drift beyond a measured T_ambient is tried (when `reach` finds
    // the runs can show an air ramp) and reported, never claimed: on the
    // open-world truth model it was not told apart from clean runs; without
    // a T_ambient column it is the room's own change and stays
    let claimable = !(c.name == "ambient_drift" && p.ds.has_ambient);
    // `held_out_z` is reported, not required: the speed law's gain sits in
    // the few high-speed held-out blocks, so its per-block z stays low on
    // true laws (cross model seed 11 case 8: gap 11.4 → 5.8 noise units at
    // z 0.11). Inside the noise nothing is claimed all the same: the absolute
    // margin (≥ FIT_MIN_ABS noise variance) needs a gap before above one
    // noise unit
    // the speed law is scored against its own reference (the switched
    // inputs and the fixed textbook law): on the outputs it changes it must
    // also beat the nominal by the same margins, so a reference that fits
    // them worse than the nominal never lends it a shrink
    let beats_nominal = !has_reference || c.name != "bearing_nonlinear" || {
        let m_n = nominal.m_held_of(outs, &c.affected);
        m_a <= m_n * (1.0 - FIT_MIN_REL) && m_n - m_a >= FIT_MIN_ABS
    };
    // the lag's reference is the lag-smoothed body map, whose noise is far
    // below the channel's: its fit rows must shrink by half instead of an
    // absolute margin in channel-noise units
    let margin_ok = if c.name == "sensor_lag" {
        c.evidence["fit_rel_gain"]
            .as_f64()
            .is_some_and(|g| g >= LAG_MIN_FIT_REL)
            && c.evidence["fit_rel_gain_least_run"]
                .as_f64()
                .is_some_and(|g| g >= LAG_MIN_RUN_REL)
            && lag_specific::is_specific(&c.evidence)
    } else {
        m_b - m_a >= FIT_MIN_ABS
    };
    // a step late in a run leaves few fit rows after it, where the nominal's
    // slow modes absorb a constant: for a step the held-out rows may decide
    // instead of the fit-row BIC, if they halve the gap
    // the steeper speed law differs from the nominal's free a·n + b·n^e
    // mostly where the speeds leave the fit rows' range: on the fit rows the
    // nominal's terms absorb it (ΔBIC near 0), on the held-out rows it shows.
    // It may be claimed by them if they halve the nominal's gap (besides the
    // general 30 % over its own reference, below)
    let nominal_halved = c.name == "bearing_nonlinear"
        && has_reference
        && m_a.is_finite()
        && m_a <= SPEED_HELD_REL * nominal.m_held_of(outs, &c.affected);
    let bic_ok = ms.dbic <= -min.min_dbic
        || nominal_halved
        || (c.name == "sensor_offset"
            && c.evidence["few_fit_rows_after"].as_bool() == Some(true)
            && m_a.is_finite()
            && m_a <= STEP_HELD_REL * m_b);
    // the speed law (against its reference or the nominal itself) must
    // take most of the gap: the nominal's own speed terms may have absorbed
    // part of the law, and a nominal that extrapolates badly to another
    // speed, or a misfit that grows with load, reads as a steeper law (on
    // clean runs the heat-adding law left ≥ 54 % of the gap on the truth
    // model, 4 seeds, ≥ 60 % on the first simulator's machines, 2 seeds,
    // and 47–54 % on the cross model, 5 seeds; every true law named on the
    // cross model's development seeds 11 and 13 left ≤ 37 % on one form,
    // one on the open world's seed 11 (case 18) 44 %: a thin margin)
    let steep_enough = c.name != "bearing_nonlinear" || m_a <= SPEED_CLAIM_REL * m_b;
    let claimed = claimable
        && steep_enough
        && beats_nominal
        && bic_ok
        && m_a.is_finite()
        && c.at_bound.is_empty()
        && periodic_ok
        && m_a <= m_b * (1.0 - min_rel)
        && margin_ok
        && no_worse(ms.gum)
        && no_worse(ms.gc);
    (claimed, beats_nominal)
}

/// The candidate's own evidence with its scores added.
fn scored_evidence(
    p: &Problem,
    c: &Candidate,
    has_reference: bool,
    nominal: &ModelFit,
    ms: &Measures,
    beats_nominal: bool,
) -> Value {
    let outs = &p.outputs;
    let mut ev = c.evidence.clone();
    if let Some(o) = ev.as_object_mut() {
        o.insert("delta_bic".into(), r4(ms.dbic));
        o.insert("held_out_norm_gap_before".into(), r4(ms.m_b.sqrt()));
        o.insert("held_out_norm_gap_after".into(), r4(ms.m_a.sqrt()));
        o.insert(
            "affected".into(),
            json!(c
                .affected
                .iter()
                .map(|&i| outs[i].name.clone())
                .collect::<Vec<_>>()),
        );
        o.insert("at_bound".into(), json!(c.at_bound));
        if has_reference && c.name == "bearing_nonlinear" {
            o.insert(
                "held_out_norm_gap_nominal".into(),
                r4(nominal.m_held_of(outs, &c.affected).sqrt()),
            );
            o.insert("beats_nominal".into(), json!(beats_nominal));
        }
        o.insert("peak_before_um".into(), json!(ms.gum.map(|g| r4(g.0 .1))));
        o.insert("peak_after_um".into(), json!(ms.gum.map(|g| r4(g.1 .1))));
    }
    ev
}

fn score(
    p: &Problem,
    mut c: Candidate,
    reference: Option<ModelFit>,
    nominal: &ModelFit,
    min: &Options,
) -> Scored {
    let before = reference.as_ref().unwrap_or(nominal);
    let ms = measure(p, &c, before);
    let gain = held_out_gain(p, &c, before, nominal);
    let has_reference = reference.is_some();
    let blocks_d = held_out_d(p, before, &c.fit, &c.affected);
    let z = verdict::z_of(&blocks_d.iter().flatten().copied().collect::<Vec<_>>());
    if let Some(o) = c.evidence.as_object_mut() {
        o.insert(
            "held_out_z".into(),
            json!((!z.is_nan()).then(|| r4(z.min(1e9)))),
        );
    }
    let (claimed, beats_nominal) = claim(p, &c, has_reference, nominal, &ms, min);
    let evidence = scored_evidence(p, &c, has_reference, nominal, &ms, beats_nominal);
    Scored {
        finding: Finding {
            name: c.name.to_string(),
            effects: Vec::new(),
            dbic: ms.dbic,
            m_before: ms.m_b,
            m_after: ms.m_a,
            gap_um: ms.gum,
            gap_c: ms.gc,
            evidence,
            params: Some(c.params),
        },
        claimed,
        gain,
        fit: c.fit,
        before: reference,
        blocks_d,
    }
}

/// The z of the held-out reduction of the gap against the measured noise,
/// as the machine-file gate (`gate::held_out_z`), reads these: per held-out
/// block (a contiguous held-out stretch of a run, cut into pieces of at
/// most `verdict::BLOCK_S`) where the effect changes an affected output,
/// d = ln((M₀ + 1)/(M₁ + 1)), M the block's mean squared residual in noise
/// units over the affected outputs; z = mean(d) / (sd(d) / √blocks) (NaN
/// with fewer than two blocks). One entry per held-out block of the runs
/// (the same blocks for every candidate, in the same order): None where the
/// effect changes no affected output.
fn held_out_d(
    p: &Problem,
    before: &ModelFit,
    after: &ModelFit,
    affected: &[usize],
) -> Vec<Option<f64>> {
    let mut d = Vec::new();
    for (r, run) in p.ds.runs.iter().enumerate() {
        let max = ((verdict::BLOCK_S / run.dt).floor() as usize).max(1);
        let mut k = 0;
        while k < run.rows() {
            if !run.held[k] {
                k += 1;
                continue;
            }
            let a = k;
            while k < run.rows() && run.held[k] {
                k += 1;
            }
            let cut = (k - a).div_ceil(max).max(1);
            let len = (k - a).div_ceil(cut).max(1);
            let mut s = a;
            while s < k {
                let e = (s + len).min(k);
                let (mut s0, mut s1, mut n, mut touched) = (0.0, 0.0, 0usize, false);
                for &o in affected {
                    let noise = p.outputs[o].noise;
                    let (Some(r0), Some(r1)) =
                        (before.outs[o].resid.get(r), after.outs[o].resid.get(r))
                    else {
                        continue;
                    };
                    for j in s..e {
                        let (x, y) = (r0[j], r1[j]);
                        if x.is_finite() && y.is_finite() && noise > 0.0 {
                            touched |= (x - y).abs() > 1e-3 * noise;
                            s0 += x * x / (noise * noise);
                            s1 += y * y / (noise * noise);
                            n += 1;
                        }
                    }
                }
                d.push(
                    (n > 0 && touched)
                        .then(|| ((s0 / n as f64 + 1.0) / (s1 / n as f64 + 1.0)).ln()),
                );
                s = e;
            }
        }
    }
    d
}

/// Held-out RMS by channel and by phase before and after an effect.
fn selected_gaps(p: &Problem, name: &str, before: &ModelFit, after: &ModelFit) -> SelectedGaps {
    let channels = p
        .outputs
        .iter()
        .enumerate()
        .filter(|(o, _)| before.outs[*o].n_held > 0 && after.outs[*o].n_held > 0)
        .map(|(o, out)| {
            let rms = |f: &ModelFit| (f.outs[o].sse_held / f.outs[o].n_held as f64).sqrt();
            (out.name.clone(), out.is_disp, rms(before), rms(after))
        })
        .collect();
    let ph = run_phases(p);
    let mut acc: std::collections::BTreeMap<&str, (f64, f64, usize)> = Default::default();
    for (r, run) in p.ds.runs.iter().enumerate() {
        for (o, out) in p.outputs.iter().enumerate() {
            if out.is_disp || before.outs[o].resid.len() <= r || after.outs[o].resid.len() <= r {
                continue;
            }
            for k in (0..run.rows()).filter(|&k| run.held[k]) {
                let (b, a) = (before.outs[o].resid[r][k], after.outs[o].resid[r][k]);
                if b.is_finite() && a.is_finite() {
                    let e = acc.entry(ph[r][k]).or_default();
                    e.0 += b * b;
                    e.1 += a * a;
                    e.2 += 1;
                }
            }
        }
    }
    SelectedGaps {
        effect: name.to_string(),
        channels,
        phases: acc
            .into_iter()
            .map(|(k, (b, a, n))| (k.to_string(), (b / n as f64).sqrt(), (a / n as f64).sqrt()))
            .collect(),
    }
}

/// Candidates, each with the reference it is scored against (`None`: the
/// nominal; the lag against the body map).
fn fit_candidates(
    p: &Problem,
    st: &Structure,
    fit: &ModelFit,
    only: &dyn Fn(&str) -> bool,
    speed_kept: Option<f64>,
    ambient_kept: Option<f64>,
) -> Vec<(Candidate, Option<ModelFit>)> {
    let mut cands: Vec<(Candidate, Option<ModelFit>)> = Vec::new();
    if only("sensor_offset") {
        cands.extend(
            open_effects::sensor_steps(p, st, fit)
                .into_iter()
                .map(|c| (c, None)),
        );
    }
    if only("sensor_lag") {
        cands.extend(
            open_effects::sensor_lags(p)
                .into_iter()
                .map(|(c, b)| (c, Some(b))),
        );
    }
    if only("coolant") {
        cands.extend(open_effects::periodic(p, st, fit).map(|c| (c, None)));
    }
    // a speed law the runs cannot tell from the nominal's own terms
    // (`reach`, listed untestable) is not tried
    let speed_testable = speed_kept.is_none_or(|k| k >= reach::SPEED_MIN_KEPT);
    if only("bearing_nonlinear") && speed_testable {
        cands.extend(open_effects::speed_nonlinearity(p).map(|(c, b)| (c, Some(b))));
        cands.extend(
            open_effects::speed_nonlinearity_against_nominal(p, st, fit).map(|c| (c, None)),
        );
    }
    // likewise an air drift the nominal's T_ambient gain reproduces
    let ambient_testable = ambient_kept.is_none_or(|k| k >= reach::AMBIENT_MIN_KEPT);
    if only("ambient_drift") && ambient_testable {
        cands.extend(open_effects::ambient_drift(p, st, fit).map(|c| (c, None)));
    }
    cands
}

/// Per sensor, the shortest lag the test can see. Where the test itself
/// saw a lag at a tau, that sensor is testable there (the injected-lag
/// probe of `lag_reach` under-rates a sensor that already lags: its own
/// lag stays in the probe's data).
fn sensor_lag_reach(
    p: &Problem,
    cands: &[(Candidate, Option<ModelFit>)],
    lag_tested: bool,
) -> Vec<Option<f64>> {
    let mut lag_reach = if lag_tested {
        open_effects::lag_reach(p)
    } else {
        Vec::new()
    };
    for (c, _) in cands.iter().filter(|(c, _)| c.name == "sensor_lag") {
        let s =
            p.ds.sensors
                .iter()
                .position(|n| c.evidence["channel"] == n.as_str());
        if let (Some(s), Some(tau)) = (s, c.evidence["shortest_tau_seen_s"].as_f64()) {
            if let Some(r) = lag_reach.get_mut(s) {
                *r = Some(r.map_or(tau, |t| t.min(tau)));
            }
        }
    }
    lag_reach
}

/// Rank by the held-out shrink, largest first. Each lag candidate is
/// scored against its own reference (the body map lagged by its tau), so
/// their absolute shrinks do not compare: the lag family is ranked by its
/// best absolute shrink, and within it by the relative fit-row shrink of
/// the body map (the detector's own statistic, on the most rows; the
/// unsensed neighbour of a lagged sensor shows a smaller share of the
/// same gain).
fn rank(scored: &mut [Scored]) {
    let lag_gain = scored
        .iter()
        .filter(|s| s.finding.name == "sensor_lag")
        .map(|s| s.gain)
        .fold(f64::NEG_INFINITY, f64::max);
    let key = |s: &Scored| -> (f64, f64) {
        if s.finding.name == "sensor_lag" {
            (
                lag_gain,
                s.finding.evidence["fit_rel_gain"]
                    .as_f64()
                    .unwrap_or(f64::NEG_INFINITY),
            )
        } else {
            (s.gain, 0.0)
        }
    };
    scored.sort_by(|a, b| {
        let (ka, kb) = (key(a), key(b));
        kb.0.total_cmp(&ka.0).then(kb.1.total_cmp(&ka.1))
    });
}

/// The speed law when it was tried, not claimed in either form, and yet
/// took a material part of the held-out gap (the general margins: ≥
/// `FIT_MIN_REL` of it and ≥ `FIT_MIN_ABS`, adding heat) without the
/// `SPEED_CLAIM_REL` a claim needs: these runs show something steeper in
/// speed than the nominal but cannot tell a steeper bearing law from the
/// nominal's own misfit at the speeds they visit.
fn speed_law_inconclusive(scored: &[Scored]) -> Option<(String, String)> {
    let laws = || {
        scored
            .iter()
            .filter(|s| s.finding.name == "bearing_nonlinear")
    };
    if laws().any(|s| s.claimed) {
        return None;
    }
    let f = laws()
        .map(|s| &s.finding)
        .filter(|f| {
            f.evidence["at_bound"]
                .as_array()
                .is_some_and(|a| a.is_empty())
                && f.m_after.is_finite()
                && f.m_after <= (1.0 - FIT_MIN_REL) * f.m_before
                && f.m_before - f.m_after >= FIT_MIN_ABS
        })
        .min_by(|a, b| (a.m_after / a.m_before).total_cmp(&(b.m_after / b.m_before)))?;
    Some((
        "bearing_nonlinear".into(),
        format!(
            "a steeper speed law (exponent {}) takes the held-out mean squared gap from {:.2} to {:.2} (noise units²), {:.0} % left where a claim needs ≤ {:.0} %: these runs show heat steeper in speed than the nominal's but cannot tell a steeper bearing law from the nominal's own misfit at the speeds they visit",
            f.params.as_ref().map_or(Value::Null, |p| p["exponent"].clone()),
            f.m_before,
            f.m_after,
            100.0 * f.m_after / f.m_before,
            100.0 * SPEED_CLAIM_REL
        ),
    ))
}

/// The claimed findings in rank order, the first selected. The speed law
/// is tried against two references: reported once, in its best-ranked
/// claimed form.
fn claimed_findings(scored: &[Scored]) -> Vec<Finding> {
    let mut findings: Vec<Finding> = Vec::new();
    for s in scored.iter().filter(|s| s.claimed) {
        if s.finding.name == "bearing_nonlinear"
            && findings.iter().any(|f| f.name == s.finding.name)
        {
            continue;
        }
        let mut f = s.finding.clone();
        if let Some(o) = f.evidence.as_object_mut() {
            o.insert(
                "role".into(),
                json!(if findings.is_empty() {
                    "selected"
                } else {
                    "alternative: supported alone but explains less than the selected effect"
                }),
            );
        }
        findings.push(f);
    }
    findings
}

/// The claimed candidates the held-out data cannot separate from the
/// selected one (`verdict::ambiguity`): empty when it is named.
fn ambiguous_names(scored: &[Scored]) -> Vec<String> {
    let claimed: Vec<&Scored> = scored.iter().filter(|s| s.claimed).collect();
    let ranked: Vec<(&str, &[Option<f64>])> = claimed
        .iter()
        .map(|s| (s.finding.name.as_str(), &s.blocks_d[..]))
        .collect();
    verdict::ambiguity::ambiguous_set(&ranked)
        .into_iter()
        .map(|i| claimed[i].finding.name.clone())
        .collect()
}

fn fit_ranking_rule(opt: &Options) -> String {
    format!(
        "each effect is fitted jointly with the nominal on the fit blocks and scored on the held-out blocks; it is claimed when BIC improves by ≥ {} (a sensor step with at most one block of fit rows after it, where slow modes absorb a constant: or its held-out gap halves), the held-out gap of the outputs it changes shrinks by ≥ {:.0} % (a sensor step or lag: ≥ {:.0} %) and ≥ {} noise variance, and neither the µm nor the °C held-out gap grows (so nothing is claimed on a held-out gap at or under one noise unit); the machine-file gate's z (over the held-out blocks ≤ {:.0} s where the effect changes an output, d = ln((M₀ + 1)/(M₁ + 1)) with M the block's mean squared residual in noise units, z = mean(d)/(sd(d)/√blocks); {} is its 1 % line) is reported as `held_out_z`, not required: a speed law's gain sits in the few high-speed blocks; claimed effects are ranked by the held-out shrink summed over the outputs they change (noise units); sensor lags, each scored against the body map lagged by its own tau, rank as one family by their best shrink and within it by the relative fit-row shrink of the body map (claimed at ≥ 25 % of it and ≥ 10 % in every run; a tau at the long end of the grid is a lower bound)",
        opt.min_dbic,
        FIT_MIN_REL * 100.0,
        SENSOR_MIN_REL * 100.0,
        FIT_MIN_ABS,
        verdict::BLOCK_S,
        verdict::Z_MIN
    ) + &format!("; a steeper speed law (bearing_nonlinear, runs of different mean speed only) is scored against a reference identified with motor heat ∝ n, Palmgren bearing heat ∝ n^(5/3) and inputs switched with the spindle, must add heat, and must clear the same margins against the nominal on the outputs it changes (its BIC may be replaced by halving the nominal's held-out gap); it ranks by the smaller of the two shrinks. It is also scored against the nominal itself (the steeper heat through the nominal's modes); in either form it is claimed only when it leaves at most {claim:.0} % of the held-out gap it is scored on (between {claim:.0} % and {inconclusive:.0} %, adding heat, it is listed untestable: the runs show heat steeper in speed but cannot tell a steeper law from the nominal's own misfit), and reported once, in the better-ranked form; {ambiguity}", ambiguity = verdict::ambiguity::RULE, claim = SPEED_CLAIM_REL * 100.0, inconclusive = (1.0 - FIT_MIN_REL) * 100.0)
}

/// How the computed `untestable` entries are decided (for `ranking_rule`).
fn untestable_rule() -> String {
    format!(
        "; untestable is computed from the runs per effect: the speed law is listed when the runs lack spindle_rpm, runs of different mean speed or {} speed levels, or when the nominal fitted on the fit rows leaves less than {:.1} % (held-out RMS) of every steeper law's signature (n/n_max)^p through any of its modes (then it is not tried either); an air drift beyond T_ambient (ambient_drift) likewise when the nominal's columns leave less than {:.1} % of an air ramp through any of its modes (then not tried); a sensor lag where an injected lag would not clear the lag test's margins (`sensor_lag_reach_s`); effects without a driver column in the runs",
        open_effects::MIN_SPEED_LEVELS,
        reach::SPEED_MIN_KEPT * 100.0,
        reach::AMBIENT_MIN_KEPT * 100.0
    )
}

/// Diagnose runs without a machine file.
pub fn diagnose_fit(runs: &[(String, Run)], opt: &Options) -> Result<Diagnosis> {
    let t0 = std::time::Instant::now();
    let ds = crate::diagnose::runs::load(runs, opt.max_rows.min(1500))?;
    let p = Problem::new(&ds);
    let (st, fit) = p.identify();
    if let Some(o) = fit.outs.iter().position(|f| f.failed) {
        anyhow::bail!(
            "diagnose fit: the least-squares fit of the identified model failed for output {} (singular design or too few rows)",
            p.outputs.get(o).map_or("?", |x| x.name.as_str())
        );
    }
    let where_ = where_of(&p, &fit);
    let only = |n: &str| opt.only.is_empty() || opt.only.iter().any(|o| o == n);
    let speed_reach = reach::speed_law_kept(&p, &st);
    let speed_kept = speed_reach.as_ref().map(|r| r.0);
    let ambient_reach = reach::ambient_drift_kept(&p, &st);
    let ambient_kept = ambient_reach.as_ref().map(|r| r.0);
    let cands = fit_candidates(&p, &st, &fit, &only, speed_kept, ambient_kept);
    let lag_reach = sensor_lag_reach(&p, &cands, only("sensor_lag"));
    let n_cands = cands.len();
    let mut scored: Vec<Scored> = cands
        .into_iter()
        .map(|(c, b)| score(&p, c, b, &fit, opt))
        .collect();
    // the residual's line (periodic_claim.rs); coolant needs it (coolant_line.rs)
    let line = (only("coolant") || only("periodic"))
        .then(|| periodic_claim::line(&p, &st, &fit))
        .flatten();
    // what the runs show but cannot decide (undecided.rs), on the claims
    // before the line confirms any coolant
    let claims = || scored.iter().map(|s| (&s.finding, s.claimed));
    let mut undecided = undecided::steps_with_held_onset(claims());
    undecided.extend(undecided::cycling_not_stationary(
        line.as_ref(),
        claims(),
        opt.min_dbic,
    ));
    let no_line = coolant_line::demote(
        &p,
        line.as_ref(),
        scored.iter_mut().map(|s| (&s.finding, &mut s.claimed)),
    );
    rank(&mut scored);
    let mut untestable = untestable(&p, &lag_reach, speed_kept, ambient_kept);
    untestable.extend(no_line);
    untestable.extend(undecided);
    untestable.extend(speed_law_inconclusive(&scored));
    untestable.extend(lag_specific::untestable(scored.iter().map(|s| &s.finding)));
    let mut findings = claimed_findings(&scored);
    let selected = scored.iter().find(|s| s.claimed).map(|s| {
        selected_gaps(
            &p,
            &s.finding.name,
            s.before.as_ref().unwrap_or(&fit),
            &s.fit,
        )
    });
    let sel = scored.iter().find(|s| s.claimed).map(|s| s.fit.clone());
    let ambiguous = ambiguous_names(&scored);
    let mut tried: Vec<Finding> = scored.into_iter().map(|s| s.finding).collect();
    let (sel, line) = (sel.as_ref(), line.flatten());
    periodic_claim::merge_line(&p, &fit, sel, line, (&mut findings, &mut tried), &opt.only);
    // a periodic line the selected effect leaves is named first by its own
    // test; otherwise an ambiguous answer names nothing (claims stay tried)
    let ambiguous = if findings.first().is_some_and(|f| f.name == "periodic") {
        Vec::new()
    } else {
        ambiguous
    };
    if !ambiguous.is_empty() {
        findings.clear();
    }
    let mut notes = ds.notes.clone();
    notes.push(format!(
        "nominal identified on {} run(s), {} rows, fit and held-out blocks in every run",
        ds.runs.len(),
        ds.runs.iter().map(|r| r.rows()).sum::<usize>()
    ));
    Ok(Diagnosis {
        machine: "identified from the runs (no machine file)".into(),
        findings,
        tried,
        where_,
        nominal_m_held: fit.m_held_of(&p.outputs, &(0..p.outputs.len()).collect::<Vec<_>>()),
        nominal_gap_um: fit.gap_held(&p.outputs, true),
        nominal_gap_c: fit.gap_held(&p.outputs, false),
        notes,
        seconds: t0.elapsed().as_secs_f64(),
        sims: n_cands,
        untestable,
        lag_reach: p
            .ds
            .sensors
            .iter()
            .cloned()
            .zip(lag_reach.iter().copied())
            .collect(),
        missing: ds.missing.clone(),
        nominal: {
            let mut n = nominal_json(&p, &st, &fit);
            if let Some(o) = n.as_object_mut() {
                if let Some(r) = &speed_reach {
                    o.insert("speed_law_reach".into(), r.1.clone());
                }
                if let Some(r) = &ambient_reach {
                    o.insert("ambient_drift_reach".into(), r.1.clone());
                }
            }
            n
        },
        no_effect: no_effect_evidence(&p, &fit),
        selected_gaps: if ambiguous.is_empty() { selected } else { None },
        separate_by: verdict::ambiguity::separating_sentences(&ambiguous),
        ambiguous,
        ranking_rule: fit_ranking_rule(opt)
            + &crate::diagnose::effects::periodic_claim::rule()
            + &lag_specific::rule()
            + &untestable_rule()
            + &undecided::rule(),
    })
}

#[cfg(test)]
mod tests {
    use super::{ambiguous_names, speed_law_inconclusive, Scored};
    use crate::diagnose::ident::ModelFit;
    use crate::diagnose::Finding;
    use serde_json::json;

    fn law(claimed: bool, m_b: f64, m_a: f64, at_bound: &[&str]) -> Scored {
        Scored {
            finding: Finding {
                name: "bearing_nonlinear".into(),
                effects: Vec::new(),
                dbic: -100.0,
                m_before: m_b,
                m_after: m_a,
                gap_um: None,
                gap_c: None,
                evidence: json!({ "at_bound": at_bound }),
                params: Some(json!({ "exponent": 4.0 })),
            },
            claimed,
            gain: m_b - m_a,
            fit: ModelFit { outs: Vec::new() },
            before: None,
            blocks_d: Vec::new(),
        }
    }

    #[test]
    fn a_law_taking_half_the_gap_unclaimed_is_inconclusive() {
        let (name, why) = speed_law_inconclusive(&[law(false, 11.92, 5.62, &[])]).unwrap();
        assert_eq!(name, "bearing_nonlinear");
        assert!(why.contains("47 % left"), "{why}");
        assert!(why.contains("≤ 45 %"), "{why}");
    }

    #[test]
    fn a_claimed_weak_or_cooling_law_is_not_listed() {
        // claimed in its other form
        let both = [law(false, 11.0, 6.0, &[]), law(true, 10.0, 3.0, &[])];
        assert!(speed_law_inconclusive(&both).is_none());
        // under 30 % of the gap, or under one noise variance
        assert!(speed_law_inconclusive(&[law(false, 10.0, 8.0, &[])]).is_none());
        assert!(speed_law_inconclusive(&[law(false, 1.5, 0.9, &[])]).is_none());
        // fitted as cooling (on its bound)
        let cooling = law(false, 10.0, 5.0, &["extra heat c at its bound 0"]);
        assert!(speed_law_inconclusive(&[cooling]).is_none());
    }

    fn claimed(name: &str, blocks: Vec<Option<f64>>) -> Scored {
        let mut s = law(true, 10.0, 4.0, &[]);
        s.finding.name = name.into();
        s.blocks_d = blocks;
        s
    }

    #[test]
    fn two_claimed_classes_within_noise_name_nothing_and_one_clearly_ahead_is_named() {
        let ripple = |m: f64, ph: usize| -> Vec<Option<f64>> {
            (0..30)
                .map(|k| {
                    Some(
                        m + if (k + ph).is_multiple_of(2) {
                            0.3
                        } else {
                            -0.3
                        },
                    )
                })
                .collect()
        };
        let close = [
            claimed("sensor_lag", ripple(0.5, 0)),
            claimed("sensor_lag", ripple(0.45, 0)),
            claimed("coolant", ripple(0.48, 1)),
        ];
        assert_eq!(ambiguous_names(&close), vec!["sensor_lag", "coolant"]);
        let apart = [
            claimed("sensor_lag", vec![Some(0.9); 30]),
            claimed("coolant", vec![Some(0.1); 30]),
        ];
        assert!(ambiguous_names(&apart).is_empty());
        // an unclaimed rival is no explanation
        let mut rival = claimed("coolant", ripple(0.5, 1));
        rival.claimed = false;
        assert!(ambiguous_names(&[claimed("sensor_lag", ripple(0.5, 0)), rival]).is_empty());
    }
}

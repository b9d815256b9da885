//! What `diagnose fit` sees but cannot decide (issue 52, proposals P1 and
//! P2 of docs/notes/diagnose-silence.md): a candidate that passes every
//! test the runs can put to it in one half of the data and fails in the
//! other for a reason of the runs' layout, not of the data's misfit. Such
//! a candidate is listed `untestable` with what would separate it; it is
//! never named (the claim is unchanged). Every level is the claim's own
//! (`margins`, the gate's `Z_MIN`, the periodic test's `MIN_AMP_NOISE`):
//! nothing here is tuned to a case.
//!
//! - A sensor step whose onset lies in a held-out block: on the fit rows it
//!   is only a level change between two fit blocks, which the nominal's
//!   per-run levels and slow modes absorb, so the fit-row BIC cannot see
//!   it; the held-out rows, where it starts, can. Listed when it passes
//!   every held-out condition of the claim (shrink ≥ `SENSOR_MIN_REL`, ≥
//!   `FIT_MIN_ABS` noise variance, no µm or °C gap grows, nothing at a
//!   bound) and the gate's z corrected for the onset search
//!   (`z_searched`): the onset is the sharpest jump of the residual over
//!   all rows, held-out ones included, so it was chosen on the very rows
//!   whose z then judges it.
//! - A chiller whose cycling period is not stationary: the residual carries
//!   a line the periodic test finds significant (not the duty's own
//!   rhythm, ≥ `MIN_AMP_NOISE` noise units), and a `coolant` candidate
//!   passes the fit-row tests (spectral peak ≥ `PERIODIC_MIN_PEAK`, ΔBIC ≤
//!   −`min_dbic`, nothing at a bound) yet is not claimed: a fixed
//!   sinusoid fitted on the fit rows does not carry to the held-out rows
//!   when the period moves with load (a relay chiller's).

use super::margins::{FIT_MIN_ABS, FIT_MIN_REL, PERIODIC_MIN_PEAK, SENSOR_MIN_REL};
use crate::diagnose::effects::periodic_claim::{LineCand, MIN_AMP_NOISE};
use crate::diagnose::signal::normal_sf;
use crate::diagnose::types::Finding;
use crate::diagnose::verdict::Z_MIN;

/// Nothing at a bound (`evidence.at_bound` empty or absent).
fn free(f: &Finding) -> bool {
    f.evidence["at_bound"]
        .as_array()
        .is_none_or(|a| a.is_empty())
}

/// Neither held-out gap (µm, °C) grows, as `claim` requires.
fn no_gap_grows(f: &Finding) -> bool {
    let ok =
        |g: Option<((f64, f64), (f64, f64))>| g.is_none_or(|g| g.1 .0 <= g.0 .0 * (1.0 + 1e-9));
    ok(f.gap_um) && ok(f.gap_c)
}

/// The held-out z the candidate was scored with (`held_out_z`).
fn held_z(f: &Finding) -> Option<f64> {
    f.evidence["held_out_z"].as_f64().filter(|z| z.is_finite())
}

/// The held-out z a step's onset must reach when the search chose it among
/// `n` onset positions inside held-out rows (`onsets_searched_held` of
/// `sensor_step`). The search takes the sharpest jump over all rows, so an
/// onset in held-out rows is placed where those rows jump most, and its z
/// is then read on the same rows: the gate's z ≥ `Z_MIN` (one-sided 1 %)
/// holds for one onset fixed beforehand, not for the best of n. A listing
/// needs the best onset in held-out rows to pass, so under the nominal its
/// chance is at most that of any of those n positions passing: the gate's
/// 1 % is shared among them by Šidák (1 − (1 − α)^(1/n) each; conservative
/// here, as neighbouring onsets see nearly the same rows). Only this level
/// is corrected: it is the one that states a chance, which the search
/// multiplies; the shrink, noise-variance, gap and bound conditions are the
/// claim's own floors on what the step must change, kept as they are.
pub(super) fn z_searched(n: usize) -> f64 {
    if n <= 1 {
        return Z_MIN;
    }
    let alpha = normal_sf(Z_MIN);
    let each = -((-alpha).ln_1p() / n as f64).exp_m1();
    // normal_sf falls with z: bisect [Z_MIN, 12] (each ≥ 1e-30 for any n
    // a run holds)
    let (mut lo, mut hi) = (Z_MIN, 12.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if normal_sf(mid) > each {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// P1: one entry per unclaimed sensor step whose onset lies in held-out
/// rows and which passes every held-out condition of the claim.
pub(super) fn steps_with_held_onset<'a>(
    scored: impl Iterator<Item = (&'a Finding, bool)>,
) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (f, claimed) in scored {
        if claimed || f.name != "sensor_offset" {
            continue;
        }
        if f.evidence["onset_held"].as_bool() != Some(true) {
            continue;
        }
        let (m_b, m_a) = (f.m_before, f.m_after);
        let held_ok = m_a.is_finite()
            && m_b.is_finite()
            && m_a <= m_b * (1.0 - SENSOR_MIN_REL)
            && m_b - m_a >= FIT_MIN_ABS
            && no_gap_grows(f)
            && free(f);
        // no count of the onsets searched: the search cannot be allowed for
        let Some(n) = f.evidence["onsets_searched_held"].as_u64() else {
            continue;
        };
        let z_need = z_searched(n as usize);
        let Some(z) = held_z(f).filter(|z| *z >= z_need) else {
            continue;
        };
        if !held_ok {
            continue;
        }
        let pr = f.params.as_ref();
        let sensor = pr.and_then(|p| p["sensor"].as_str()).unwrap_or("?");
        let size = pr.and_then(|p| p["offset_c"].as_f64()).unwrap_or(f64::NAN);
        let run = pr.and_then(|p| p["run"].as_str()).unwrap_or("?");
        let from = pr.and_then(|p| p["from_s"].as_f64()).unwrap_or(f64::NAN);
        out.push((
            format!("sensor_offset (onset in held-out rows) on {sensor}"),
            format!(
                "a step of {size:+.2} °C on {sensor} from {from:.0} s of run {run} starts inside a held-out block: on the fit rows it is only a level change between fit blocks, which the identified nominal's run levels and slow modes absorb (ΔBIC {:+.1}, a claim needs ≤ −10), while on the held-out rows it takes {:.0} % of {sensor}'s gap away ({:.2} → {:.2} noise units², z {z:.2} ≥ {z_need:.2}, the gate's {Z_MIN} at 1 % shared among the {n} held-out onsets the search weighed, as the onset was chosen on these rows; every other held-out condition of a claim met: ≥ {:.0} %, ≥ {FIT_MIN_ABS} noise², no gap grows); a reference reading of {sensor} (a probe on its body, before and after that time) would separate a sensor step from the nominal's misfit",
                f.dbic,
                100.0 * (1.0 - m_a / m_b),
                m_b,
                m_a,
                100.0 * SENSOR_MIN_REL
            ),
        ));
    }
    out
}

/// P2: the entry for a cycling chiller whose period is not stationary
/// (None when the line or the candidate does not qualify). `line`: the
/// residual's strongest line (`periodic_claim::line`); `scored`: the
/// candidates with their claim before the line confirms any `coolant`.
pub(super) fn cycling_not_stationary<'a>(
    line: Option<&LineCand>,
    mut scored: impl Iterator<Item = (&'a Finding, bool)>,
    min_dbic: f64,
) -> Option<(String, String)> {
    let (lf, l, line_claimed) = line?.as_ref()?;
    let e = &lf.evidence;
    let line_ok = !*line_claimed
        && l.significant()
        && e["duty_repeats_at_period"].as_bool() == Some(false)
        && e["amplitude_over_noise"]
            .as_f64()
            .is_some_and(|a| a >= MIN_AMP_NOISE);
    if !line_ok {
        return None;
    }
    let c = scored.find_map(|(f, claimed)| {
        (!claimed
            && f.name == "coolant"
            && free(f)
            && f.dbic <= -min_dbic
            && f.evidence["peak_over_median_power"]
                .as_f64()
                .is_some_and(|v| v >= PERIODIC_MIN_PEAK))
        .then_some(f)
    })?;
    let pc = c
        .params
        .as_ref()
        .and_then(|p| p["period_s"].as_f64())
        .unwrap_or(f64::NAN);
    let shrink = 100.0 * (1.0 - c.m_after / c.m_before);
    Some((
        "coolant (cycling, period not stationary)".into(),
        format!(
            "the residual carries a significant line at {:.0} s on {} ({:.1} noise units, p {:.1e} corrected, not the duty's rhythm), and a chiller cycle fitted on the fit rows ({pc:.0} s) passes the fit-row tests (spectral peak {:.1} × the median, ΔBIC {:.1}) but takes {shrink:.0} % of the held-out gap away where a claim needs {:.0} %: a cycle whose period moves with load (a relay chiller's) is not carried by one fixed sinusoid from the fit rows to the held-out ones; a sensor on the coolant circuit, or the chiller's on/off signal as a column, would separate it from the model's misfit",
            l.period_s,
            e["channel"].as_str().unwrap_or("?"),
            e["amplitude_over_noise"].as_f64().unwrap_or(f64::NAN),
            l.p_corrected,
            c.evidence["peak_over_median_power"].as_f64().unwrap_or(f64::NAN),
            c.dbic,
            100.0 * FIT_MIN_REL
        ),
    ))
}

/// The ranking rule's sentence on these listings.
pub(super) fn rule() -> String {
    format!(
        "; listed, never named: a sensor step whose onset lies in a held-out block, not claimed but meeting every held-out condition of a claim (≥ {:.0} %, ≥ {FIT_MIN_ABS} noise variance, no gap grows, nothing at a bound) and the gate's z with its 1 % shared (Šidák) among the held-out onset positions the search weighed (the onset is chosen on the rows that judge it), as 'sensor_offset (onset in held-out rows) on S' (the fit-row BIC cannot see it); a coolant cycle passing the fit-row tests (spectral peak ≥ {PERIODIC_MIN_PEAK}, ΔBIC) but not the held-out ones while the residual's line is significant, ≥ {MIN_AMP_NOISE} noise units and not the duty's rhythm, as 'coolant (cycling, period not stationary)'",
        100.0 * SENSOR_MIN_REL
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_z_an_onset_must_reach_grows_with_the_onsets_searched() {
        // one onset fixed beforehand: the gate's own level
        assert_eq!(z_searched(0), Z_MIN);
        assert_eq!(z_searched(1), Z_MIN);
        // n onsets: each at 1 − (1 − α)^(1/n), the family at α
        let alpha = normal_sf(Z_MIN);
        for n in [2usize, 10, 500, 5000] {
            let z = z_searched(n);
            let family = 1.0 - (1.0 - normal_sf(z)).powi(n as i32);
            assert!(
                (family - alpha).abs() < 1e-3 * alpha,
                "n {n}: {family} vs {alpha}"
            );
            assert!(z > z_searched(n - 1), "n {n}");
        }
        // Bonferroni's familiar points: 1 % over 1000 is 1e-5, z ≈ 4.26
        assert!(
            (z_searched(1000) - 4.26).abs() < 0.02,
            "{}",
            z_searched(1000)
        );
    }
}

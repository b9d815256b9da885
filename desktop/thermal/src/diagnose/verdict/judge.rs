//! The nominal's fit and the margins every candidate is judged by
//! (`Judge`), and the evidence written beside each finding.

use anyhow::Result;
use serde_json::{json, Value};

use super::gate;
use crate::diagnose::calibration::Freedom;
use crate::diagnose::calibration::{design_heat, design_mimic};
use crate::diagnose::effects::{params_of, Evaluator, FitResult, Stats};
use crate::diagnose::runs::Kind;
use crate::diagnose::signal::{corr, first_order, r4, rms_of};
use crate::diagnose::types::{Finding, Options};
use crate::sim::Effect;

/// Evidence: signature correlation (nominal residual vs the effect's change
/// of the prediction, noise-normalised, held-out rows) and the correlation of
/// the most affected channel's residual with the effect's physical driver.
fn evidence(
    ev: &Evaluator,
    res0: &[Vec<Vec<f64>>],
    fr: &FitResult,
    st0: &Stats,
    st1: &Stats,
    dbic: f64,
) -> Value {
    let Ok(res1) = ev.residuals(&fr.effects) else {
        return json!({});
    };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for (pi, p) in ev.runs.iter().enumerate() {
        let none_held = p.held.iter().all(|h| !h);
        for (ci, c) in p.channels.iter().enumerate() {
            for k in 0..p.rows() {
                let r0 = res0[pi][ci][k];
                let r1 = res1[pi][ci][k];
                if p.held[k] || none_held {
                    a.push(r0 / c.s);
                    b.push((r0 - r1) / c.s);
                }
            }
        }
    }
    let sig = corr(&a, &b);
    // most affected channel
    let mut best = (0usize, 0usize, f64::MIN);
    for (c0, c1) in st0.ch.iter().zip(&st1.ch) {
        let n = (c0.n_fit + c0.n_held).max(1) as f64;
        let gain = (c0.sse_fit + c0.sse_held - c1.sse_fit - c1.sse_held) / n / (c0.s * c0.s);
        if gain > best.2 {
            best = (c0.run, c0.ch, gain);
        }
    }
    let (pi, ci) = (best.0, best.1);
    let p = &ev.runs[pi];
    let ch = &p.channels[ci];
    let dt = p.inputs.dt;
    let kind = fr.cands.iter().map(|c| c.kind).next().unwrap_or("");
    let (driver_name, driver): (&str, Vec<f64>) = match kind {
        "convection" => ("mean predicted rise above ambient", {
            let out = crate::sim::simulate(ev.m, &p.inputs, &[], 1).ok();
            match out {
                Some(o) => (0..p.rows())
                    .map(|k| {
                        o.temps.iter().map(|s| s[k]).sum::<f64>() / o.temps.len().max(1) as f64
                            - p.inputs.ambient[k]
                    })
                    .collect(),
                None => vec![],
            }
        }),
        "ambient_drift" => ("time", (0..p.rows()).map(|k| p.inputs.time(k)).collect()),
        "sensor_lag" => ("rate of change of the predicted reading", {
            let out = crate::sim::simulate(ev.m, &p.inputs, &[], 1).ok();
            match (out, ch.kind) {
                (Some(o), Kind::Temp(i)) => {
                    let s = &o.temps[i];
                    (0..s.len())
                        .map(|k| if k == 0 { 0.0 } else { (s[k] - s[k - 1]) / dt })
                        .collect()
                }
                _ => vec![],
            }
        }),
        "bearing_nonlinear" => (
            "spindle speed² (lagged 20 min)",
            first_order(
                &p.inputs.rpm.iter().map(|r| r * r).collect::<Vec<_>>(),
                dt,
                1200.0,
            ),
        ),
        "coolant" => (
            "coolant_on (lagged 20 min)",
            first_order(&p.inputs.coolant, dt, 1200.0),
        ),
        "chiller" => (
            "the cycling chiller's change of this channel's prediction",
            {
                let one: Vec<Effect> = fr.effects.clone();
                match (
                    crate::sim::simulate(ev.m, &p.inputs, &one, 1),
                    crate::sim::simulate(ev.m, &p.inputs, &[], 1),
                    ch.kind,
                ) {
                    (Ok(a), Ok(b), Kind::Temp(i)) => a.temps[i]
                        .iter()
                        .zip(&b.temps[i])
                        .map(|(x, y)| x - y)
                        .collect(),
                    (Ok(a), Ok(b), Kind::Disp(i)) => a.disp[i]
                        .iter()
                        .zip(&b.disp[i])
                        .map(|(x, y)| x - y)
                        .collect(),
                    _ => vec![],
                }
            },
        ),
        "ballscrew" => (
            "feed_activity (lagged 1 h)",
            first_order(&p.inputs.feed, dt, 3600.0),
        ),
        "bending" => ("predicted temperature gradient of the bending pair", {
            let d0 =
                crate::sim::simulate(ev.m, &p.inputs, &[Effect::Bending { k_um_per_k: 1.0 }], 1);
            let d1 = crate::sim::simulate(ev.m, &p.inputs, &[], 1);
            match (d0, d1, ev.m.bending) {
                (Ok(a), Ok(b), Some((_, _, di))) => a.disp[di]
                    .iter()
                    .zip(&b.disp[di])
                    .map(|(x, y)| x - y)
                    .collect(),
                _ => vec![],
            }
        }),
        _ => ("constant (a bias)", vec![1.0; p.rows()]),
    };
    let r = &res0[pi][ci];
    let driver_corr = if kind == "sensor_offset" {
        let (rms, _, _) = rms_of(r.iter().copied());
        let mean = r.iter().filter(|v| v.is_finite()).sum::<f64>()
            / r.iter().filter(|v| v.is_finite()).count().max(1) as f64;
        if rms > 0.0 {
            mean / rms
        } else {
            0.0
        }
    } else {
        corr(r, &driver)
    };
    json!({
        "signature_corr": r4(sig),
        "channel": ch.name,
        "driver": driver_name,
        "driver_corr": r4(driver_corr),
        "delta_bic": (dbic * 10.0).round() / 10.0,
        "held_out_norm_gap_before": r4(st0.m_held().sqrt()),
        "held_out_norm_gap_after": r4(st1.m_held().sqrt()),
        "gap_before_c": st0.gap_held(false).map(|g| r4(g.0)),
        "gap_after_c": st1.gap_held(false).map(|g| r4(g.0)),
        "peak_before_um": st0.gap_held(true).map(|g| r4(g.1)),
        "peak_after_um": st1.gap_held(true).map(|g| r4(g.1)),
    })
}

/// The nominal's fit and the margins every candidate is judged by.
pub(crate) struct Judge<'a> {
    pub(crate) ev: &'a Evaluator<'a>,
    pub(crate) res0: &'a [Vec<Vec<f64>>],
    /// The nominal's residuals before the freedom (where an effect acts).
    pub(crate) raw0: Vec<Vec<Vec<f64>>>,
    pub(crate) st0: Stats,
    /// The nominal's fit criterion on the fit rows.
    pub(crate) j0: f64,
    /// The nominal's held-out gap (noise units).
    pub(crate) m0: f64,
    /// BIC's penalty per parameter: ln of the fit rows.
    pub(crate) lnn: f64,
    pub(crate) opt: &'a Options,
    /// The calibration's freedom (None: the file taken as exact).
    pub(crate) freedom: Option<&'a Freedom>,
}

impl Judge<'_> {
    pub(crate) fn dbic(&self, fr: &FitResult) -> f64 {
        fr.j - self.j0 + fr.k as f64 * self.lnn
    }

    pub(crate) fn finding(&self, fr: &FitResult, dbic: f64) -> Result<(Finding, Stats)> {
        let (raw1, res1) = self.ev.raw_and_residuals(&fr.effects)?;
        let st = self.ev.stats_of(&res1);
        let st0 = &self.st0;
        let mut ev_json = evidence(self.ev, self.res0, fr, st0, &st, dbic);
        let acts = (&self.raw0[..], &raw1[..]);
        let z = gate::held_out_z_acting(self.ev.runs, self.res0, &res1, acts);
        if let Some(o) = ev_json.as_object_mut() {
            // NaN (fewer than two held-out blocks): no test, null
            let zj = if z.is_nan() {
                Value::Null
            } else {
                json!(r4(z.min(1e6)))
            };
            o.insert("held_out_z".into(), zj);
            if let Some(j) = gate::step_jump_share(self.ev.runs, self.res0, &fr.effects) {
                o.insert("step_jump_share".into(), json!(r4(j)));
            }
        }
        Ok((
            Finding {
                name: fr
                    .cands
                    .iter()
                    .map(|c| c.kind)
                    .collect::<Vec<_>>()
                    .join("+"),
                effects: fr.effects.clone(),
                dbic,
                m_before: self.m0,
                m_after: st.m_held(),
                gap_um: st0.gap_held(true).zip(st.gap_held(true)),
                gap_c: st0.gap_held(false).zip(st.gap_held(false)),
                evidence: ev_json,
                params: None,
            },
            st,
        ))
    }

    /// Why a finding's effect cannot be told from design errors within
    /// tolerance: a node's heat (`design_heat.rs`), the film coefficients
    /// or levers (`design_mimic.rs`); only against a calibrated file.
    pub(crate) fn barred(&self, f: &Finding) -> Option<String> {
        self.freedom?;
        f.effects.iter().find_map(|e| {
            design_heat::within_tolerance(self.ev.m, self.ev.runs, e)
                .or_else(|| design_mimic::within_tolerance(self.ev.m, e))
        })
    }

    // never an effect that widens the held-out displacement gap (beyond
    // 2 %, below what an RMS over the held-out rows can resolve)
    // and never a step inside a run that is no jump of the residual at
    // its onset (`gate::step_jump_share`)
    pub(crate) fn supported(&self, f: &Finding, m_ref: f64) -> bool {
        self.margins(f, m_ref) && self.barred(f).is_none() && self.jumps(f)
    }

    pub(crate) fn jumps(&self, f: &Finding) -> bool {
        gate::step_jump_share(self.ev.runs, self.res0, &f.effects)
            .is_none_or(|j| j >= gate::JUMP_SHARE_MIN)
    }

    pub(crate) fn margins(&self, f: &Finding, m_ref: f64) -> bool {
        let opt = self.opt;
        f.dbic <= -opt.min_dbic
            && (gate::sensor_only(f)
                || f.gap_um.is_none_or(|((b, _), (a, _))| a <= b * 1.02 + 1e-9))
            && f.m_after.is_finite()
            && f.m_after <= m_ref * (1.0 - opt.min_rel)
            && m_ref - f.m_after >= opt.min_abs
            && gate::passes(
                self.m0,
                f.evidence["held_out_z"].as_f64().unwrap_or(f64::NAN),
            )
    }

    // the added effect must itself earn the margins: the pair's own fit
    // without it (its base effect at the pair's parameters) is the
    // reference, so a joint polish of the base alone never names a pair
    pub(crate) fn partner_earns_its_place(&self, fr: &FitResult, f: &Finding) -> Result<bool> {
        let Some(last) = fr.cands.last() else {
            return Ok(true);
        };
        let opt = self.opt;
        let k_partner = params_of(last.kind).len() + last.located();
        let n_base = fr.effects.len() - 1;
        let st = self.ev.stats(&fr.effects[..n_base])?;
        let dbic_base = st.j_fit() - self.j0 + (fr.k - k_partner) as f64 * self.lnn;
        let m_base = st.m_held();
        Ok(f.dbic <= dbic_base - opt.min_dbic
            && f.m_after <= m_base * (1.0 - opt.min_rel)
            && m_base - f.m_after >= opt.min_abs)
    }
}

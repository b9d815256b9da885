//! `tcomp diagnose fit <runs…>`: the diagnosis without a machine file.
//! The nominal model is identified from the runs (`ident`), the gap is
//! located on its residual, and only the effects an identified nominal
//! cannot absorb are tested (`open_effects`); everything else is listed as
//! untestable with the reason.

use anyhow::Result;
use serde_json::{json, Value};

use super::ident::{ModelFit, Problem, Structure};
use super::series::{self, Dataset};
use super::stats::{ljung_box, phases, phases_from_temperatures, r4, where_json, ResidualView};
use super::{Diagnosis, Options};
use crate::runcsv::Run;

/// Effects an identified nominal absorbs (or the data cannot show), with why.
pub fn untestable(ds: &Dataset) -> Vec<(String, String)> {
    let mut v = vec![
        ("convection".to_string(), "a different convection level only changes the gains and time constants the nominal is identified with; without a machine file it is not a gap".to_string()),
        ("bending".to_string(), "displacement is identified as a linear map of the node rises, which contains any bending proportional to a temperature difference".to_string()),
        ("sensor_offset (constant over a run)".to_string(), "a constant offset is indistinguishable from the sensor's own rest level (its level is identified per run); steps inside a run are tested".to_string()),
    ];
    if ds.has_feed {
        v.push(("ballscrew".into(), "heat that follows feed_activity is an input of the nominal and is absorbed by its gains".into()));
    } else {
        v.push((
            "ballscrew".into(),
            "no feed_activity column: heat from axis travel has no observed driver".into(),
        ));
    }
    if ds.has_coolant {
        v.push(("coolant (on/off level)".into(), "coolant_on is an input of the nominal, so the mean cooling is absorbed; only a periodic chiller drive is tested".into()));
    }
    if !ds.has_rpm {
        v.push((
            "bearing_nonlinear / speed nonlinearity".into(),
            "no spindle_rpm column: the heat input is not observed, temperatures drive the nominal"
                .into(),
        ));
    }
    v
}

/// Residual evidence of "no effect": per-channel held-out RMS against the
/// noise level and a Ljung–Box whiteness test on the held-out residual.
pub fn no_effect_evidence(p: &Problem, fit: &ModelFit) -> Value {
    let mut ch = serde_json::Map::new();
    let mut worst_ratio = 0.0f64;
    let mut white = 0usize;
    let mut tested = 0usize;
    for (o, (out, f)) in p.outputs.iter().zip(&fit.outs).enumerate() {
        if f.n_held == 0 {
            continue;
        }
        let rms = (f.sse_held / f.n_held as f64).sqrt();
        let ratio = rms / out.noise;
        worst_ratio = worst_ratio.max(ratio);
        // held-out rows, runs concatenated, thinned to ≥ 2 min apart
        let mut held = Vec::new();
        for (r, run) in p.ds.runs.iter().enumerate() {
            for k in 0..run.rows() {
                if run.held[k] {
                    held.push(fit.outs[o].resid[r][k]);
                }
            }
        }
        let dt = p.ds.runs.first().map_or(60.0, |r| r.dt);
        let step = ((120.0 / dt).ceil() as usize).max(1);
        let lb = ljung_box(&held, 10, step);
        if let Some((_, _, pv)) = lb {
            tested += 1;
            if pv > 0.01 {
                white += 1;
            }
        }
        ch.insert(
            out.name.clone(),
            json!({
                "held_out_rms": r4(rms),
                "noise": r4(out.noise),
                "rms_over_noise": r4(ratio),
                "ljung_box_p": lb.map(|l| r4(l.2)),
            }),
        );
    }
    json!({
        "channels": ch,
        "worst_rms_over_noise": r4(worst_ratio),
        "white_channels": white,
        "tested_channels": tested,
        "rule": "residual at noise level: held-out RMS ≤ 2 × noise; white: Ljung–Box p > 0.01 over 10 lags of rows ≥ 2 min apart",
    })
}

/// Description of the identified nominal and its own held-out fit.
pub fn nominal_json(p: &Problem, st: &Structure, fit: &ModelFit) -> Value {
    let um = fit.gap_held(&p.outputs, true);
    let c = fit.gap_held(&p.outputs, false);
    let fit_rms = |disp: bool| {
        let (mut s, mut n) = (0.0, 0usize);
        for (f, o) in fit.outs.iter().zip(&p.outputs) {
            if o.is_disp == disp {
                s += f.sse_fit;
                n += f.n_fit;
            }
        }
        (n > 0).then(|| (s / n as f64).sqrt())
    };
    json!({
        "kind": "identified modal thermal network",
        "drive": if p.cross() { "temperatures (no spindle_rpm): each sensor from the principal components of the others" } else { "inputs: spindle heat, feed, coolant, ambient as present" },
        "time_constants_s": st.modes,
        "order": st.modes.len(),
        "speed_exponent": if p.ds.has_rpm { json!(st.exponent) } else { Value::Null },
        "coefficients": fit.k(),
        "bic": r4(fit.bic(&p.outputs)),
        "fit_rms_c": fit_rms(false).map(r4),
        "fit_rms_um": fit_rms(true).map(r4),
        "held_out_rms_c": c.map(|g| r4(g.0)),
        "held_out_rms_um": um.map(|g| r4(g.0)),
        "held_out_peak_um": um.map(|g| r4(g.1)),
        "split": format!("each run in {} time blocks, blocks {:?} held out", series::BLOCKS, series::HELD_BLOCKS),
    })
}

/// Where the nominal's gap lies, all rows of all runs.
pub fn where_of(p: &Problem, fit: &ModelFit) -> Value {
    let ds = p.ds;
    let ph: Vec<Vec<&'static str>> = ds
        .runs
        .iter()
        .map(|r| match &r.rpm {
            Some(rpm) => phases(rpm, r.dt),
            None => {
                let s: Vec<&[f64]> = r.sensors.iter().map(|s| s.values.as_slice()).collect();
                phases_from_temperatures(&s, r.dt)
            }
        })
        .collect();
    let mut views = Vec::new();
    for (r, run) in ds.runs.iter().enumerate() {
        for (o, out) in p.outputs.iter().enumerate() {
            views.push(ResidualView {
                name: &out.name,
                is_disp: out.is_disp,
                resid: &fit.outs[o].resid[r],
                phases: &ph[r],
                dt: run.dt,
            });
        }
    }
    where_json(&views)
}

/// Diagnose runs without a machine file.
pub fn diagnose_fit(runs: &[(String, Run)], opt: &Options) -> Result<Diagnosis> {
    let t0 = std::time::Instant::now();
    let ds = series::load(runs, opt.max_rows.min(1500))?;
    let p = Problem::new(&ds);
    let (st, fit) = p.identify();
    let where_ = where_of(&p, &fit);
    let mut notes = ds.notes.clone();
    notes.push(format!(
        "nominal identified on {} run(s), {} rows, fit and held-out blocks in every run",
        ds.runs.len(),
        ds.runs.iter().map(|r| r.rows()).sum::<usize>()
    ));
    Ok(Diagnosis {
        machine: "identified from the runs (no machine file)".into(),
        findings: Vec::new(),
        tried: Vec::new(),
        where_,
        nominal_m_held: fit.m_held_of(&p.outputs, &(0..p.outputs.len()).collect::<Vec<_>>()),
        nominal_gap_um: fit.gap_held(&p.outputs, true),
        nominal_gap_c: fit.gap_held(&p.outputs, false),
        notes,
        seconds: t0.elapsed().as_secs_f64(),
        sims: 0,
        untestable: untestable(&ds),
        missing: ds.missing.clone(),
        nominal: nominal_json(&p, &st, &fit),
        no_effect: no_effect_evidence(&p, &fit),
        ranking_rule: "effects are fitted jointly with the nominal on the fit blocks and scored on the held-out blocks".into(),
    })
}

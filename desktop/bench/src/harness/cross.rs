//! The cross-model column: `diagnose fit` on cases of the first simulator
//! (`tcomp_thermal::sim`), which the fit mode was never tuned on.

use anyhow::Result;
use serde_json::{json, Value};

use tcomp_numerics::rng::Rng;
use tcomp_thermal::diagnose::stats::r4;
use tcomp_thermal::diagnose::Options;
use tcomp_thermal::sim::{sim_run, Duty, Effect, Machine, SimOptions};

use super::draw::{lu, BenchConfig};
use super::tally::{FitTally, Visibility};

/// Kinds of the cross-model column (`run_cross_bench`): the sensor and
/// speed effects of the target set that the first simulator can
/// produce as they are meant (its machines have no chiller tank, so the
/// periodic drive is left to the truth model).
pub const CROSS_KINDS: [&str; 3] = ["sensor_offset", "sensor_lag", "bearing_nonlinear"];

/// An effect of the cross-model column on machine `m`, at the open-world
/// truth model's strengths: a step on one sensor in the second run, a lag
/// of one sensor, extra bearing heat steeper in speed than any textbook law.
fn cross_effect(g: &mut Rng, m: &Machine, kind: &str, hours: f64) -> Effect {
    let sign = if g.uniform() < 0.5 { -1.0 } else { 1.0 };
    let n = m.sensor_cols.len();
    let sensor = m.sensor_cols[((g.uniform() * n as f64) as usize).min(n - 1)].clone();
    match kind {
        "sensor_offset" => Effect::SensorOffset {
            sensor,
            offset_c: sign * lu(g, 0.3, 1.5),
            at_s: lu(g, 0.15, 0.85) * hours * 3600.0,
            run: None,
        },
        "sensor_lag" => Effect::SensorLag {
            tau_s: lu(g, 150.0, 900.0),
            sensor: Some(sensor),
        },
        _ => Effect::BearingNonlinear {
            k_w: lu(g, 40.0, 120.0),
            p: lu(g, 2.5, 3.2),
            node: None,
        },
    }
}

/// A light or heavy duty of the first simulator with the truth model's
/// duty generator (speeds in `lo..hi` of the machine's maximum; coolant
/// flows while the spindle runs).
fn band_duty(g: &mut Rng, m: &Machine, hours: f64, lo: f64, hi: f64) -> Duty {
    let steps = crate::truth::random_duty(g, hours, lo, hi);
    let scale = m.spec.n_max_rpm / crate::truth::N_MAX;
    let mut d = Duty {
        name: "band".into(),
        end_s: hours * 3600.0,
        ..Default::default()
    };
    for (t, rpm, feed) in steps {
        d.t.push(t);
        d.rpm.push(rpm * scale);
        d.feed.push(feed);
        d.coolant.push(if rpm > 0.0 { 1.0 } else { 0.0 });
        d.ambient.push(None);
    }
    d
}

/// One cross-model case: the machine (index into the machines given), the
/// effect kind (None = clean), the effects and the two runs.
pub struct CrossCase {
    pub machine: usize,
    pub kind: Option<&'static str>,
    pub effects: Vec<Effect>,
    pub runs: Vec<(String, tcomp_data::runcsv::Run)>,
    pub visibility: Visibility,
    pub redrawn: usize,
}

/// The cases `run_cross_bench` diagnoses (same seed, same cases).
pub fn cross_cases(machines: &[Machine], cfg: &BenchConfig) -> Result<Vec<CrossCase>> {
    let mut g = Rng::paired(cfg.seed ^ 0xc705);
    let n = cfg.cases.max(4);
    let n_clean = (n / 4).max(1);
    let mut plan: Vec<Option<&'static str>> = (0..n - n_clean)
        .map(|i| Some(CROSS_KINDS[i % CROSS_KINDS.len()]))
        .collect();
    plan.extend(std::iter::repeat_n(None, n_clean));
    let half = cfg.hours / 2.0;
    let mut cases = Vec::with_capacity(plan.len());
    for (ci, kind) in plan.into_iter().enumerate() {
        let machine = ci % machines.len();
        let m = &machines[machine];
        let mut redrawn = 0usize;
        loop {
            let effects: Vec<Effect> = kind
                .iter()
                .map(|k| cross_effect(&mut g, m, k, half))
                .collect();
            let mut visibility = Visibility::default();
            let mut runs = Vec::new();
            for (ri, &(lo, hi)) in [(0.15, 0.55), (0.5, 1.0)].iter().enumerate() {
                let duty = band_duty(&mut g, m, half, lo, hi);
                // a sensor fault happens once: in the second run only
                let eff: Vec<Effect> = effects
                    .iter()
                    .filter(|e| ri == 1 || !matches!(e, Effect::SensorOffset { .. }))
                    .cloned()
                    .collect();
                let so = |effects: Vec<Effect>| SimOptions {
                    effects,
                    seed: 7000 + 2 * ci as u64 + ri as u64,
                    hours: Some(half),
                    sample_period_s: Some(cfg.sample_period_s),
                    noise: true,
                };
                let mut run = sim_run(m, &duty, &so(eff.clone()))?;
                if !eff.is_empty() {
                    visibility.add(&run, &sim_run(m, &duty, &so(Vec::new()))?);
                }
                if let Some(c) = run.col_index("coolant_on") {
                    run.columns.remove(c);
                    run.data.remove(c);
                }
                runs.push((format!("cross{ci}-{ri}"), run));
            }
            if effects.is_empty() || visibility.visible() || redrawn >= 20 {
                cases.push(CrossCase {
                    machine,
                    kind,
                    effects,
                    runs,
                    visibility,
                    redrawn,
                });
                break;
            }
            redrawn += 1;
        }
    }
    Ok(cases)
}

/// Cross-model check of `diagnose fit`: blind cases from the project's
/// first simulator (`tcomp_thermal::sim`, lumped networks of other machines:
/// `examples/machines/turning-center-16.toml`, `five-axis-20.toml`), which the fit
/// mode was never tuned on. Two runs per case (light and heavy duty) as in
/// `run_open_bench`, written as measured data sets are (no `coolant_on`).
pub fn run_cross_bench(machines: &[Machine], cfg: &BenchConfig) -> Result<Value> {
    let cases = cross_cases(machines, cfg)?;
    let n_clean = cases.iter().filter(|c| c.kind.is_none()).count();
    let opt = Options {
        threads: cfg.threads,
        ..Options::default()
    };
    let mut tally = FitTally::default();
    let mut misses = Vec::new();
    let n_cases = cases.len();
    for (ci, case) in cases.into_iter().enumerate() {
        let CrossCase {
            machine,
            kind,
            effects,
            runs,
            visibility: vis,
            redrawn,
        } = case;
        let m = &machines[machine];
        let d = tally.diagnose(&runs, &opt, redrawn)?;
        let top = d.findings.first();
        let correct = match (kind, effects.first()) {
            (None, _) => top.is_none(),
            (Some(k), e) => top.is_some_and(|f| {
                let sensor = match e {
                    Some(Effect::SensorOffset { sensor, .. })
                    | Some(Effect::SensorLag {
                        sensor: Some(sensor),
                        ..
                    }) => Some(sensor.as_str()),
                    _ => None,
                };
                f.name == k && sensor.is_none_or(|s| f.params_json()["sensor"] == s)
            }),
        };
        if let Some(Effect::SensorLag {
            sensor: Some(sensor),
            tau_s,
        }) = effects.first()
        {
            tally.lag_reach.add(&d, sensor, *tau_s, correct);
        }
        tally.score(kind, correct, &d);
        let got: Vec<Value> = d
            .findings
            .iter()
            .map(|f| json!({"name": f.name, "params": f.params_json()}))
            .collect();
        if !correct {
            misses.push(json!({
                "case": ci,
                "machine": m.spec.name,
                "effect_rms_c": r4(vis.max_c),
                "effect_rms_um": r4(vis.max_um),
                "truth": effects.iter().map(|e| format!("{e:?}")).collect::<Vec<_>>(),
                "got": got,
            }));
        }
        if cfg.verbose {
            for f in &d.tried {
                eprintln!(
                    "      tried {:18} m {:.2} -> {:.2} dbic {:.1} {} {}",
                    f.name,
                    f.m_before,
                    f.m_after,
                    f.dbic,
                    f.params_json(),
                    f.evidence
                );
            }
            eprintln!(
                "cross {ci:3} {} effect rms {:.3} °C {:.3} µm truth {:?} got {} {} ({:.2} s)",
                m.spec.name,
                vis.max_c,
                vis.max_um,
                effects,
                Value::from(got),
                if correct {
                    "ok"
                } else if kind.is_some() {
                    "MISS"
                } else {
                    "FALSE ALARM"
                },
                tally.times.last().copied().unwrap_or(0.0)
            );
        }
    }
    Ok(tally.with_figures(json!({
        "mode": "diagnose fit (no machine file) on cases of the first simulator (tcomp_thermal::sim: turning-center-16, five-axis-20), two runs per case (light and heavy duty), no coolant_on column",
        "cases": n_cases,
        "clean_cases": n_clean,
        "hours_per_case": cfg.hours,
        "sample_period_s": cfg.sample_period_s,
        "misses": misses,
    })))
}

//! What `diagnose fit` cannot test, with why: the effects an identified
//! nominal absorbs by construction and those the runs cannot reach
//! (computed per case in `reach.rs` and `open_effects`).

use super::reach;
use crate::diagnose::effects::open_effects::{self, LAG_MIN_FIT_REL};
use crate::diagnose::ident::Problem;

/// Effects an identified nominal absorbs (or the data cannot show), with why.
pub fn untestable(
    p: &Problem,
    lag_reach: &[Option<f64>],
    speed_kept: Option<f64>,
    ambient_kept: Option<f64>,
) -> Vec<(String, String)> {
    let ds = p.ds;
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
    let speed = "bearing_nonlinear / speed nonlinearity".to_string();
    if !ds.has_rpm {
        v.push((
            speed,
            "no spindle_rpm column: the heat input is not observed, temperatures drive the nominal"
                .into(),
        ));
    } else if !open_effects::runs_of_different_speeds(p) {
        v.push((speed, "needs at least two runs whose mean speeds differ by 20 % of the maximum: within one run a steeper speed law cannot be told from other heat that comes with running".into()));
    } else if open_effects::speed_levels(p).len() < open_effects::MIN_SPEED_LEVELS {
        v.push((
            speed,
            format!(
                "needs at least {} spindle speeds each held for 5 % of the rows (found {}): the nominal's two speed terms (n and n^1.5 or n^2) pass through the heat of any law at two running speeds, so a steeper law leaves no gap",
                open_effects::MIN_SPEED_LEVELS,
                open_effects::speed_levels(p).len()
            ),
        ));
    } else if let Some(kept) = speed_kept.filter(|k| *k < reach::SPEED_MIN_KEPT) {
        v.push((speed, format!(
            "collinear with the nominal's own freedom on these runs: fitted on the fit rows, the nominal's speed terms (n and n^e through its modes, run levels, decays) leave at most {:.1} % (held-out RMS) of any steeper law's signature ((n/n_max)^p, p of {:?}, through any of its modes), below the {:.1} % the test needs; the runs' speeds do not spread enough to tell a steeper law from the nominal's own terms",
            kept * 100.0,
            open_effects::STEEP_EXPONENTS,
            reach::SPEED_MIN_KEPT * 100.0
        )));
    } else {
        // tested (`open_effects::speed_nonlinearity`): not listed
    }
    if let Some(kept) = ambient_kept.filter(|k| *k < reach::AMBIENT_MIN_KEPT) {
        v.push(("ambient_drift (beyond T_ambient)".into(), format!(
            "collinear with the nominal's own freedom on these runs: fitted on the fit rows, the nominal's columns (T_ambient and the other inputs through its modes with free gains, run levels, decays) leave at most {:.1} % (held-out RMS) of an air ramp beyond T_ambient through any of its modes, below the {:.1} % the test needs; on these runs a drift of the air reads as a different ambient gain",
            kept * 100.0,
            reach::AMBIENT_MIN_KEPT * 100.0
        )));
    }
    if ds.disps.is_empty() {
        v.push(("sensor_lag".into(), "no displacement column: a sensor's lag is only visible against its body, and an identified nominal absorbs any lag of a sensor's own reading".into()));
    }
    v.extend(lag_reach_untestable(p, lag_reach));
    v
}

/// The sensors whose lag the body-map test cannot see (`lag_reach`): one
/// entry for those it cannot test at any lag of the grid, one per shortest
/// lag it sees on the others (when above the grid's start).
fn lag_reach_untestable(p: &Problem, lag_reach: &[Option<f64>]) -> Vec<(String, String)> {
    let longest = open_effects::LAG_GRID[open_effects::LAG_GRID.len() - 1];
    let names = |pick: &dyn Fn(Option<f64>) -> bool| -> Vec<&str> {
        p.ds.sensors
            .iter()
            .zip(lag_reach)
            .filter(|(_, r)| pick(**r))
            .map(|(n, _)| n.as_str())
            .collect()
    };
    let why = |tau: f64| {
        format!(
        "put on these sensors' readings, a lag of {tau:.0} s would shrink the lagged body map's fit rows by less than the {:.0} % a claim needs: the displacements carry too little of them, so a lagging sensor is not told from a slower node without a machine file",
        LAG_MIN_FIT_REL * 100.0
    )
    };
    let mut v = Vec::new();
    let none = names(&|r| r.is_none());
    if !none.is_empty() {
        v.push((format!("sensor_lag on {}", none.join(", ")), why(longest)));
    }
    let mut shortest: Vec<f64> = lag_reach
        .iter()
        .flatten()
        .copied()
        .filter(|t| *t > open_effects::LAG_GRID[0])
        .collect();
    shortest.sort_by(f64::total_cmp);
    shortest.dedup();
    for t in shortest {
        let i = open_effects::LAG_GRID
            .iter()
            .position(|g| *g == t)
            .unwrap_or(1);
        let below = open_effects::LAG_GRID[i.saturating_sub(1)];
        v.push((
            format!(
                "sensor_lag shorter than {t:.0} s on {}",
                names(&|r| r == Some(t)).join(", ")
            ),
            why(below),
        ));
    }
    v
}

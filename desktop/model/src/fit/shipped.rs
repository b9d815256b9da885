//! What `export` ships per channel: the model the fit chose, the sensors it
//! reads, and every other temperature column of the training run with why
//! it is left out (beyond the board's channels, not picked, not in
//! `--features`, not `select`'s choice, not chosen by the forward selection,
//! or no model at all) — the answer to "why is my sensor not used?".

use serde::Serialize;

use super::model::ModelFile;
use super::plan::{Candidates, FeatureChoice, FitConfig};
use crate::select::Selection;
use tcomp_data::runcsv::Run;
use thermocomp_core::limits::MAX_SENSORS;

/// One channel of what `export` ships.
#[derive(Clone, Debug, Serialize)]
pub struct Shipped {
    pub channel: String,
    /// The chosen model (`mlr`, `ga-bpn`, `none`, …).
    pub model: String,
    /// The temperature columns its inputs read.
    pub sensors: Vec<String>,
    /// Every other temperature column of the training run, with why.
    pub left_out: Vec<LeftOut>,
}

/// A temperature column a channel's shipped model does not read.
#[derive(Clone, Debug, Serialize)]
pub struct LeftOut {
    pub sensor: String,
    pub why: String,
}

/// Per channel, the shipped model, its sensors and why every other
/// temperature column of the training run is not among them.
pub(super) fn shipped(
    first: &Run,
    cfg: &FitConfig,
    selection: Option<&Selection>,
    file: &ModelFile,
) -> Vec<Shipped> {
    let mut out = Vec::new();
    for (ch, model) in &file.chosen {
        let params = match model.as_str() {
            "none" => None,
            "mlr-static" => file.mlr_static.iter().find(|m| m.channel == *ch),
            "ridge" => file.ridge.iter().find(|m| m.channel == *ch),
            _ => file.mlr.iter().find(|m| m.channel == *ch),
        };
        let mut sensors: Vec<String> = Vec::new();
        for f in params.map_or(&[][..], |m| &m.features[..]) {
            for c in f.kind.columns() {
                if c != "spindle_rpm" && !sensors.iter().any(|s| s == c) {
                    sensors.push(c.to_string());
                }
            }
        }
        let left_out = first
            .temperature_columns()
            .iter()
            .enumerate()
            .filter(|(_, s)| !sensors.iter().any(|u| u == *s))
            .map(|(i, s)| LeftOut {
                sensor: s.to_string(),
                why: left_out_why(i, s, model, cfg, selection),
            })
            .collect();
        out.push(Shipped {
            channel: ch.clone(),
            model: model.clone(),
            sensors,
            left_out,
        });
    }
    out
}

/// Why the temperature column `s` (the run's `i`-th) is not read by a
/// channel whose shipped model is `model`.
fn left_out_why(
    i: usize,
    s: &str,
    model: &str,
    cfg: &FitConfig,
    selection: Option<&Selection>,
) -> String {
    if i >= MAX_SENSORS {
        return format!(
            "beyond the board's {MAX_SENSORS} channels (the board reads the run's first {MAX_SENSORS} T_ columns)"
        );
    }
    if cfg
        .sensors
        .as_ref()
        .is_some_and(|p| !p.iter().any(|x| x == s))
    {
        return "not among the picked sensors (--sensors, --sensors-from)".into();
    }
    if let FeatureChoice::List(kinds) = &cfg.features {
        if !kinds.iter().any(|(k, _)| k.columns().contains(&s)) {
            return "not in --features".into();
        }
    }
    if let Some(sel) = selection {
        if let Some(why) = sel.left_out.get(s) {
            return format!("select left it out: {why}");
        }
        if cfg.candidates == Candidates::Selected && !sel.chosen.iter().any(|c| c == s) {
            if let Some((g, best)) = sel
                .clusters
                .iter()
                .zip(&sel.chosen)
                .enumerate()
                .find(|(_, (members, _))| members.iter().any(|m| m == s))
                .map(|(g, (_, best))| (g, best))
            {
                let score = |n: &str| sel.scores.get(n).copied().unwrap_or(f64::NAN);
                return format!(
                    "not its group's best in select (group {}: {best}, score {:.3} against its {:.3})",
                    g + 1,
                    score(best),
                    score(s)
                );
            }
        }
    }
    match model {
        "none" => "the channel ships no compensation (no model beat 0 by the choice margin)".into(),
        "mlr-static" => "not an input of the chosen static MLR (unlagged rises of the selected sensors)".into(),
        _ if matches!(cfg.features, FeatureChoice::Auto) => format!(
            "a candidate the cross-validated forward selection did not pick for this channel (at most {} inputs: --max-inputs)",
            cfg.max_inputs
        ),
        _ => "not an input of the chosen model".into(),
    }
}

/// What `export` will ship per channel, and every sensor left out with why.
pub(super) fn print_shipped(shipped: &[Shipped]) {
    if shipped.is_empty() {
        return;
    }
    println!("what `export` ships (the cross-validated choice; `export --use` overrides it):");
    for c in shipped {
        let what = match c.model.as_str() {
            "none" => "no compensation (serves 0)",
            "mlr" => "lagged MLR",
            "mlr-static" => "static MLR",
            "ridge" => "ridge regression on the lagged MLR's inputs",
            "ga-bpn" => "GA-BPN network ensemble",
            "hybrid" => "lagged MLR + residual networks",
            "blend" => "blend of the MLR and the networks",
            other => other,
        };
        let reads = if c.sensors.is_empty() {
            "no sensor".to_string()
        } else {
            c.sensors.join(", ")
        };
        println!("  {}: {} ({what}), reads {reads}", c.channel, c.model);
        for l in &c.left_out {
            println!("    left out {}: {}", l.sensor, l.why);
        }
    }
    println!();
}

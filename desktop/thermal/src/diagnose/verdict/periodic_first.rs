//! Periodic first where a periodic driver is measured (issue 52 item 3).
//! With a machine file, a chiller's sawtooth on a measured coolant sensor
//! (or any measured node) leaves a line in that channel's residual; a
//! design value released outside its tolerance (a tank's capacity, its
//! loss to air) can follow the sawtooth's slow part — the level the
//! cycling holds the tank at — and explain more of the held-out gap than
//! the line alone, but never the line itself. The test, stated:
//!
//! 1. the periodic candidate is claimed (`periodic_claim`: the line is
//!    significant against the residual's own background, large enough,
//!    not a repeating duty, and its waveform takes a share of the held-out
//!    gap away);
//! 2. the line survives the parameter finding: in the residual of the
//!    released machine it is still significant (as many tests as the
//!    search) and at least `MIN_AMP_NOISE` noise units — the same test a
//!    selected effect must fail to have explained the line.
//!
//! Then the periodic driver is named first. The parameter finding stays, as
//! a note after it, only when it also reduces the residual away from the
//! line: the released residual with its own waveform at the line's period
//! taken out of the line's channels against the nominal's with its own,
//! by the noise gate's held-out test (z ≥ `Z_MIN`). Otherwise it is not
//! claimed (kept among the candidates tried, with the reason). A line the
//! release does explain is no driver of its own: it stays among the
//! candidates tried, not the findings.

use serde_json::json;

use super::gate::{held_out_z, Z_MIN};
use crate::diagnose::effects::periodic_claim::{self, Line};
use crate::diagnose::effects::Evaluator;
use crate::diagnose::runs::Prepared;
use crate::diagnose::types::{with_role, Finding};

type Residuals = Vec<Vec<Vec<f64>>>;

/// The ranking rule's sentence on a periodic driver against a parameter
/// finding.
pub fn rule() -> String {
    format!("; beside a parameter finding named first (a design value outside its tolerance), a claimed periodic line that survives it (still significant and ≥ {} noise units in the released machine's residual: the release does not explain the line) is named first as the periodic driver; the parameter finding stays after it only when, with each model's waveform at the line's period taken out of the line's channels, it still reduces the held-out gap by the same test (z ≥ {Z_MIN}): otherwise it only mimics the driver's slow part and is not claimed; a line the parameter finding explains is not claimed", periodic_claim::MIN_AMP_NOISE)
}

/// Merge the machine-file mode's periodic candidate into `findings`.
/// `release`: the held-out residuals of the parameter finding named first
/// (None: none named).
pub(crate) fn merge_periodic(
    ev: &Evaluator,
    ps: &[Prepared],
    res0: &[Vec<Vec<f64>>],
    release: Option<&Residuals>,
    findings: &mut Vec<Finding>,
    tried: &mut Vec<Finding>,
    only: &[String],
) {
    let first_is_release = findings
        .first()
        .is_some_and(|f| f.effects.is_empty() && f.name != "periodic");
    // the residual the selected explanation leaves (a release's, or its
    // effects' on the calibrated null)
    let effects_res = match findings.first() {
        Some(f) if !f.effects.is_empty() => ev.residuals(&f.effects).ok(),
        _ => None,
    };
    let selected: Option<&[Vec<Vec<f64>>]> = match (release, first_is_release) {
        (Some(rr), true) => Some(rr),
        _ => effects_res.as_deref(),
    };
    let cand = periodic_claim::machine_candidate(ev, res0, selected, only);
    match (cand, release) {
        (Some((f, line, true)), Some(rr)) if first_is_release => {
            let survives =
                periodic_claim::line_survives(&periodic_claim::scan_machine(ev, rr), &line);
            if survives {
                ahead_of_release(ev, ps, res0, rr, f, &line, findings, tried);
            } else {
                // the release explains the line: no driver of its own
                let why = "not claimed: the parameter finding named first explains this line (it does not survive it)";
                tried.push(with_role(&f, why));
            }
        }
        (cand, _) => {
            let sel = effects_res.as_deref();
            periodic_claim::machine(ev, cand, sel, findings, tried)
        }
    }
}

/// The periodic driver first; the release after it when it reduces the
/// held-out gap away from the line, else out of the findings.
#[allow(clippy::too_many_arguments)]
fn ahead_of_release(
    ev: &Evaluator,
    ps: &[Prepared],
    res0: &[Vec<Vec<f64>>],
    rr: &Residuals,
    mut f: Finding,
    line: &Line,
    findings: &mut Vec<Finding>,
    tried: &mut Vec<Finding>,
) {
    let names: Vec<String> = f
        .params
        .as_ref()
        .and_then(|p| p["channels"].as_array().cloned())
        .unwrap_or_default()
        .iter()
        .filter_map(|c| c["channel"].as_str().map(str::to_string))
        .collect();
    let away0 = periodic_claim::minus_line(ev, res0, line.period_s, &names);
    let away1 = periodic_claim::minus_line(ev, rr, line.period_s, &names);
    let z = held_out_z(ps, &away0, &away1);
    let keeps = z >= Z_MIN;
    if let Some(o) = f.evidence.as_object_mut() {
        o.insert("survives_selected_effect".into(), json!(true));
        o.insert(
            "ahead_of_parameter_finding".into(),
            json!({
                "parameter_finding": findings[0].name,
                "line_survives_it": true,
                "its_held_out_z_away_from_the_line": (z * 100.0).round() / 100.0,
                "kept_as_note": keeps,
            }),
        );
    }
    tried.push(f.clone());
    let rel = findings.remove(0);
    let period = line.period_s;
    findings.insert(0, with_role(&f, "selected"));
    if keeps {
        let why = format!("also present: a design value outside its tolerance that reduces the held-out gap away from the periodic line ({period:.0} s) too (z {z:.2} ≥ {Z_MIN})");
        findings.insert(1, with_role(&rel, &why));
    } else {
        let why = format!("not claimed: it leaves the periodic line ({period:.0} s) and, that line taken out, reduces the held-out gap no further (z {z:.2} < {Z_MIN}): it only mimics the periodic driver's slow part");
        tried.push(with_role(&rel, &why));
    }
}

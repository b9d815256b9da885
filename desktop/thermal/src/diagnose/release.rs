//! A calibration that must leave the tolerance is a finding: when the
//! calibrated design values of a group (all film coefficients, all links…)
//! or one design value sit on their tolerance bound and the data still pull
//! outwards, that group is released — one common extra factor on it,
//! searched over ×0.25…×4, the rest of the calibration's bounded freedom
//! kept — and judged like an effect (same BIC, held-out and noise-gate
//! margins). A release that earns them says where the gap lies: which
//! design value, its design and fitted value, and what that means.

use anyhow::Result;
use serde_json::json;

use super::calibrate;
use super::calibrate::{apply, design_value, Knob};
use super::effect_fit::Evaluator;
use super::freedom;
use super::freedom::Freedom;
use super::prep::Prepared;
use super::stats::r4;
use super::{gate, with_role, Finding, Judge};
use crate::sim::machine::tolerance::GROUPS;
use crate::sim::Machine;

/// Range of a released factor (on top of the calibration).
const RELEASE_LN: f64 = 1.386_294_361_119_890_6; // ln 4
/// Most single design values released.
const MAX_ELEMENTS: usize = 3;

/// A set of design values released together.
struct Release {
    key: String,
    group: &'static str,
    element: Option<String>,
    idx: Vec<usize>,
}

/// Groups and single values on a bound that the data push outwards.
fn releases(ks: &[Knob], fr: &Freedom, pull: &[f64]) -> Vec<Release> {
    let th = fr.theta();
    let pushing: Vec<usize> = (0..ks.len())
        .filter(|&i| {
            let (lo, hi) = fr.bounds(i);
            (th[i] >= hi - 1e-3 && pull[i] > 0.0) || (th[i] <= lo + 1e-3 && pull[i] < 0.0)
        })
        .collect();
    let mut out = Vec::new();
    for g in GROUPS {
        let members: Vec<usize> = (0..ks.len()).filter(|&i| ks[i].group == g).collect();
        if members.len() >= 2 && members.iter().any(|i| pushing.contains(i)) {
            out.push(Release {
                key: g.to_string(),
                group: g,
                element: None,
                idx: members,
            });
        }
    }
    let mut single = pushing.clone();
    single.sort_by(|&a, &b| pull[b].abs().total_cmp(&pull[a].abs()));
    for &i in single.iter().take(MAX_ELEMENTS) {
        let k = &ks[i];
        out.push(Release {
            key: match &k.element {
                Some(e) => format!("{}:{e}", k.group),
                None => k.group.to_string(),
            },
            group: k.group,
            element: k.element.clone(),
            idx: vec![i],
        });
    }
    out
}

/// What a factor on a group or value means physically.
fn meaning(group: &str, element: Option<&str>, f: f64) -> String {
    let more = f > 1.0;
    let of = element.map_or(String::new(), |e| format!(" ({e})"));
    match (group, element) {
        ("film", None) => format!(
            "convection {} than designed: every loss to air ×{f:.2}",
            if more { "stronger" } else { "weaker" }
        ),
        ("film", Some(_)) => format!(
            "loss to air{of} ×{f:.2}: {}",
            if more {
                "a draught or a missing cover"
            } else {
                "an enclosure or insulation"
            }
        ),
        ("link", Some(_)) if !more => format!("loose joint{of}: conductance ×{f:.2}"),
        ("link", _) => format!("conductance{of} ×{f:.2} against the design"),
        ("heat", Some(e)) if e.ends_with(":f0") => format!(
            "viscous bearing friction (f0) at {} ×{f:.2}: lubrication (oil quantity or viscosity) {} than designed",
            e.trim_end_matches(":f0"),
            if more { "heavier" } else { "lighter" }
        ),
        ("heat", _) => format!(
            "heat source{of} {} than designed: ×{f:.2}",
            if more { "stronger" } else { "weaker" }
        ),
        ("capacity", _) => format!("heat capacity{of} ×{f:.2}: mass misjudged"),
        ("jacket", _) => format!("coolant jacket{of} ×{f:.2}: flow or fouling"),
        _ => format!("displacement lever{of} ×{f:.2}"),
    }
}

/// Fit criterion, stats and residuals of one released machine.
type Judged = (f64, super::effect_fit::Stats, Vec<Vec<Vec<f64>>>);

/// The judged quantities of a machine (with the freedom): fit criterion,
/// stats and residuals.
fn eval(m: &Machine, ps: &[Prepared], fr: &Freedom) -> Result<Judged> {
    let ev = Evaluator::new(m, ps)?.with_freedom(Some(fr as &dyn super::effect_fit::Projection));
    let r = ev.residuals(&[])?;
    let st = ev.stats_of(&r);
    Ok((st.j_fit(), st, r))
}

/// The nominal the released factor acts on, and what the judge needs.
pub(crate) struct Null<'a> {
    pub design: &'a Machine,
    pub calibrated: &'a Machine,
    pub knobs: &'a [Knob],
    pub freedom: &'a Freedom,
    pub res0: &'a [Vec<Vec<f64>>],
    pub st0: &'a super::effect_fit::Stats,
    pub j0: f64,
    pub m0: f64,
    pub lnn: f64,
}

/// The released machine's residuals with the calibration's freedom, its
/// stats and fit criterion, and the freedom's own correction δ of every
/// knob (the released knobs move by it too: their fitted value is
/// θ + γ + δ, not θ + γ).
fn eval_with_correction(m: &Machine, ps: &[Prepared], fr: &Freedom) -> Result<(Judged, Vec<f64>)> {
    let ev = Evaluator::new(m, ps)?;
    let mut r = ev.residuals(&[])?;
    let delta = fr.correct(&mut r);
    let st = ev.stats_of(&r);
    Ok(((st.j_fit(), st, r), delta))
}

/// One release tried: the finding (not yet judged) and its held-out
/// residuals (to tell it from the other releases).
pub(crate) struct Tried {
    pub finding: Finding,
    pub res: Vec<Vec<Vec<f64>>>,
    /// The calibrated machine with this release applied.
    pub released: Machine,
    /// Whether the fitted value(s) left the tolerance (design-weighted:
    /// Σ fitted / Σ design outside 1 ± tol).
    pub outside: bool,
    /// Its tolerance group; whether it releases the whole group.
    pub group: &'static str,
    pub whole_group: bool,
}

/// Every release tried, as findings (not yet judged) and simulations used.
pub(crate) fn release_findings(n: &Null, ps: &[Prepared]) -> Result<(Vec<Tried>, usize)> {
    let pull = n.freedom.pull(ps, n.res0);
    let mut out = Vec::new();
    let mut sims = 0usize;
    for r in releases(n.knobs, n.freedom, &pull) {
        let sub: Vec<Knob> = r.idx.iter().map(|&i| n.knobs[i].clone()).collect();
        let at = |g: f64| apply(n.calibrated, &sub, &vec![g; sub.len()]);
        // coarse grid, then golden section around the best point
        let grid: Vec<f64> = (0..9)
            .map(|i| -RELEASE_LN + 2.0 * RELEASE_LN * i as f64 / 8.0)
            .collect();
        let mut vals = Vec::new();
        for &g in &grid {
            vals.push(eval(&at(g), ps, n.freedom).map_or(f64::INFINITY, |e| e.0));
            sims += 1;
        }
        let bi = (0..grid.len())
            .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
            .unwrap_or(4);
        let step = grid[1] - grid[0];
        let (mut a, mut b) = (grid[bi] - step, grid[bi] + step);
        let phi = 0.618_033_988_749_895;
        for _ in 0..8 {
            let (c, d) = (b - phi * (b - a), a + phi * (b - a));
            let fc = eval(&at(c), ps, n.freedom).map_or(f64::INFINITY, |e| e.0);
            let fd = eval(&at(d), ps, n.freedom).map_or(f64::INFINITY, |e| e.0);
            sims += 2;
            if fc < fd {
                b = d;
            } else {
                a = c;
            }
        }
        let gamma = 0.5 * (a + b);
        let ((j, st, res1), delta) = eval_with_correction(&at(gamma), ps, n.freedom)?;
        sims += 1;
        let design: f64 = sub.iter().map(|k| design_value(n.design, k)).sum();
        let th = n.freedom.theta();
        let fitted: f64 = r
            .idx
            .iter()
            .map(|&i| {
                let d = delta.get(i).copied().unwrap_or(0.0);
                design_value(n.design, &n.knobs[i]) * (th[i] + gamma + d).exp()
            })
            .sum();
        let factor = if design > 0.0 {
            fitted / design
        } else {
            f64::NAN
        };
        let tol = sub.iter().map(|k| k.tol).fold(0.0, f64::max);
        // a release that ends inside the tolerance (a group ×0.87, or γ
        // pointing back inwards) is no value that had to leave it
        let outside = factor < 1.0 - tol || factor > 1.0 + tol;
        let k_params = 1 + usize::from(r.element.is_some());
        let dbic = j - n.j0 + k_params as f64 * n.lnn;
        let z = super::gate::held_out_z(ps, n.res0, &res1);
        let name = match (r.group, &r.element) {
            ("film", None) => "convection".to_string(),
            _ => format!("parameter:{}", r.key),
        };
        let what = meaning(r.group, r.element.as_deref(), factor);
        let finding = Finding {
            name,
            effects: Vec::new(),
            dbic,
            m_before: n.m0,
            m_after: st.m_held(),
            gap_um: n.st0.gap_held(true).zip(st.gap_held(true)),
            gap_c: n.st0.gap_held(false).zip(st.gap_held(false)),
            evidence: json!({
                "kind": "design value outside its tolerance",
                "delta_bic": (dbic * 10.0).round() / 10.0,
                "held_out_norm_gap_before": r4(n.m0.sqrt()),
                "held_out_norm_gap_after": r4(st.m_held().sqrt()),
                "held_out_z": r4(z),
                "gap_before_c": n.st0.gap_held(false).map(|g| r4(g.0)),
                "gap_after_c": st.gap_held(false).map(|g| r4(g.0)),
            }),
            params: Some(json!({
                "parameter": r.key,
                "values": sub.len(),
                "design": r4(design),
                "fitted": r4(fitted),
                "factor": r4(factor),
                "tolerance": r4(tol),
                "meaning": what,
            })),
        };
        if std::env::var_os("TCOMP_DIAG_RELEASES").is_some() {
            eprintln!(
                "      release {:28} factor {:.3} outside {} m {:.2} -> {:.2} dbic {:.1} z {:.2}",
                r.key,
                factor,
                outside,
                n.m0,
                st.m_held(),
                dbic,
                z
            );
        }
        out.push(Tried {
            finding,
            res: res1,
            released: at(gamma),
            outside,
            group: r.group,
            whole_group: r.element.is_none() && r.idx.len() > 1,
        });
    }
    Ok((out, sims))
}

/// The calibrated null: the design file, its knobs and the freedom.
pub(super) struct CalNull<'a> {
    pub(super) design: &'a Machine,
    pub(super) knobs: &'a [calibrate::Knob],
    pub(super) freedom: &'a freedom::Freedom,
}

/// Parameter findings that earn the margins, merged into the ranking: one
/// that leaves less held-out gap than the selected effect goes first. A
/// release is a finding only when its fitted value really left the
/// tolerance and it can be told from every other release that earns the
/// margins: the best must beat each of them on the held-out blocks by the
/// noise gate's own test (z ≥ `gate::Z_MIN`); when it cannot, the data say
/// some design value is off but not which (collinear values), and the
/// release is listed untestable instead. Only the best release is named:
/// the others explain the same gap worse. Beside a selected effect it must
/// also beat that effect by the same test.
pub(super) fn merge_releases(
    judge: &Judge,
    cal: &CalNull,
    m: &Machine,
    ps: &[Prepared],
    findings: &mut Vec<Finding>,
    untestable: &mut Vec<(String, String)>,
) -> Result<usize> {
    let null = Null {
        design: cal.design,
        calibrated: m,
        knobs: cal.knobs,
        freedom: cal.freedom,
        res0: judge.res0,
        st0: &judge.st0,
        j0: judge.j0,
        m0: judge.m0,
        lnn: judge.lnn,
    };
    let (rel, mut sims) = release_findings(&null, ps)?;
    let mut ok: Vec<Tried> = rel
        .into_iter()
        .filter(|t| t.outside && judge.supported(&t.finding, judge.m0))
        .collect();
    ok.sort_by(|a, b| a.finding.m_after.total_cmp(&b.finding.m_after));
    let Some(best) = ok.first() else {
        return Ok(sims);
    };
    // rivals: the releases the best cannot be told from
    let rivals: Vec<&Tried> = ok[1..]
        .iter()
        .filter(|t| !(gate::held_out_z(ps, &t.res, &best.res) >= gate::Z_MIN))
        .collect();
    // rivals within the best's own group still say which group: the
    // group's release is named (not one of its members)
    let mut best = best;
    if rivals.iter().all(|t| t.group == best.group) {
        if let Some(g) = rivals.iter().find(|t| t.whole_group) {
            best = g;
        }
    }
    let undecided = rivals
        .iter()
        .any(|t| t.group != best.group || !best.whole_group);
    if undecided {
        let names: Vec<&str> = std::iter::once(ok[0].finding.name.as_str())
            .chain(rivals.iter().map(|t| t.finding.name.as_str()))
            .collect();
        untestable.push((
            "design value outside its tolerance".into(),
            format!(
                "the runs need a design value outside its tolerance but cannot tell which: {} explain the held-out gap alike (z < {} between them)",
                names.join(", "),
                gate::Z_MIN
            ),
        ));
        return Ok(sims);
    }
    // beside a selected effect the finding must explain the held-out gap
    // significantly better than that effect (the same test): otherwise it
    // only re-explains the effect's gap (a lagging sensor read as a larger
    // capacity) and is not named
    if let Some(top) = findings.first() {
        let res_top = judge.ev.residuals(&top.effects)?;
        sims += 1;
        if !(gate::held_out_z(ps, &res_top, &best.res) >= gate::Z_MIN) {
            return Ok(sims);
        }
    }
    // an effect beside the finding must still add to the released null
    // (its parameters as fitted against the calibrated one): otherwise it
    // only absorbed the local misfit the release explains
    if findings.iter().all(|f| f.effects.is_empty()) {
        findings.insert(0, with_role(&best.finding, "selected"));
        return Ok(sims);
    }
    let ev_rel = Evaluator::new(&best.released, ps)?.with_freedom(Some(cal.freedom));
    sims += ps.len();
    let mut kept = Vec::new();
    for f in findings.drain(..) {
        if f.effects.is_empty() {
            kept.push(f);
            continue;
        }
        let res_both = ev_rel.residuals(&f.effects)?;
        sims += 1;
        if gate::held_out_z(ps, &best.res, &res_both) >= gate::Z_MIN {
            kept.push(f);
        }
    }
    *findings = kept;
    findings.insert(0, with_role(&best.finding, "selected"));
    Ok(sims)
}

//! `tcomp geometry identify --method poly`: the polynomial model of the 21
//! errors from the line files of one temperature state, its stated
//! adequacy test (refused unless --accept-inadequate), the σ's of its
//! values from the class that is not told the shape
//! (`tcomp_geometry::shape_free`: the generic Legendre-16 posterior, whose
//! spread along what no line sees is its prior's; σ = √((value − that
//! posterior's mean)² + (its misfit inflation × its σ)²) — the polynomial
//! model's own posterior assumes its degrees and cannot cover a plan's
//! null directions, issue 49 item 2), and the report: as JSON (the errors JSON with the fit's
//! figures beside it) or in words. `geometry.rs` parses the arguments.

use anyhow::Result;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::geometry_adequacy::{inadequate_warning, print_verdict, refuse_inadequate};
use super::geometry_smooth::{read_one_state, recovery_json, recovery_text, stroke_from};
use tcomp_geometry::adequacy::{Adequacy, StatedNoise};
use tcomp_geometry::errors::Term;
use tcomp_geometry::identify::{
    identify, leave_one_line_out, line_adequacy, Degrees, Identification, LeaveOneLineOut, LineObs,
};
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::Averaged;
use tcomp_geometry::shape_free::ShapeFree;
use tcomp_geometry::study::{recovery, volumetric_residual, ErrorsJson};

/// `identify --method poly` as given.
pub struct PolyRequest<'a> {
    pub files: &'a [PathBuf],
    pub degrees: Degrees,
    /// `--stroke X,Y,Z` as given.
    pub stroke: Option<&'a str>,
    pub points: usize,
    pub truth: Option<&'a Path>,
    pub partial: bool,
    pub noise_um: Option<f64>,
    pub accept_inadequate: bool,
    pub json: bool,
}

pub fn identify_poly_cmd(r: &PolyRequest) -> Result<()> {
    let (st, avg) = read_one_state(r.files, " (or use fit-thermal)")?;
    let obs: Vec<LineObs> = avg.iter().map(|a| a.obs.clone()).collect();
    let stroke = stroke_from(r.stroke, &obs)?;
    let id = identify(&st, &obs, r.degrees, stroke)?;
    tcomp_geometry::guard::refuse_unobservable(&id, obs.len(), r.partial)?;
    let stated = assess(&st, &avg, &obs, &id, stroke, r)?;
    refuse_inadequate(
        &stated.adequacy,
        r.accept_inadequate,
        &format!("the polynomial model of these {} lines", obs.len()),
        "measure more lines: `tcomp geometry plan`",
    )?;
    let loo = leave_one_line_out(&st, &obs, &id)?;
    let truth = match r.truth {
        Some(p) => Some(ErrorsJson::read(p)?.to_errors()?),
        None => None,
    };
    let report = Report {
        recovery: truth.as_ref().map(|t| recovery(&id.errors, t, stroke)),
        volumetric: truth
            .as_ref()
            .map(|t| volumetric_residual(&st, &id.errors, t, stroke)),
        reversal: avg
            .iter()
            .filter_map(|a| a.reversal_um.map(|r| (a.obs.id.clone(), r)))
            .collect(),
        st,
        stroke,
        points: r.points,
        degrees: r.degrees,
        obs,
        id,
        stated,
        loo,
    };
    if r.json {
        println!("{}", report.json()?);
    } else {
        report.print();
    }
    if let Some(w) = inadequate_warning(&report.stated.adequacy, "model") {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// The stated adequacy test's verdict and the σ's it gives.
struct Stated {
    adequacy: Adequacy,
    /// The error functions with their shape-free σ's; the model marked
    /// adequate or not.
    errors: ErrorsJson,
    /// σ of EC0Y, EB0Z, EA0Z [µrad], inflated the same way.
    squareness_sigma: Vec<f64>,
}

/// The stated adequacy test of the fit (σ per reading of a run at the
/// stated noise; a line whose two runs were averaged has σ/√2), and the
/// error functions tabulated at `r.points` positions with its σ's.
fn assess(
    st: &Structure,
    avg: &[Averaged],
    obs: &[LineObs],
    id: &Identification,
    stroke: [f64; 3],
    r: &PolyRequest,
) -> Result<Stated> {
    let noise = StatedNoise::new(r.noise_um)?;
    let line_sigma: Vec<f64> = avg
        .iter()
        .map(|l| match l.reversal_um {
            Some(_) => noise.um / std::f64::consts::SQRT_2,
            None => noise.um,
        })
        .collect();
    let (mut adq, _) = line_adequacy(st, obs, id, &line_sigma, noise)?;
    // The σ's come from the class that is not told the shape (module doc).
    let sf = ShapeFree::fit(st, obs, stroke, &line_sigma, noise)?;
    adq.sigma_inflation = sf.inflation;
    let mut ej = ErrorsJson::from_errors(&id.errors, st, stroke, r.points);
    ej.unobservable_terms = id.unobservable_terms.clone();
    for t in Term::all() {
        if let Some(tj) = ej.errors.get_mut(&t.name()) {
            tj.sigma = tj
                .positions_mm
                .iter()
                .map(|q| sf.term_sigma(&id.errors, t, *q))
                .collect();
        }
    }
    let squareness_sigma: Vec<f64> = (0..3).map(|i| sf.squareness_sigma(&id.errors, i)).collect();
    ej.adequate = Some(adq.adequate);
    ej.adequacy = Some(adq.clone());
    Ok(Stated {
        adequacy: adq,
        errors: ej,
        squareness_sigma,
    })
}

/// Everything `identify --method poly` reports.
struct Report {
    st: Structure,
    stroke: [f64; 3],
    points: usize,
    degrees: Degrees,
    obs: Vec<LineObs>,
    id: Identification,
    stated: Stated,
    loo: LeaveOneLineOut,
    /// With --truth: per term (max, RMS, true peak) of the recovery error,
    /// and the held-out grid's tool-point RMS before and after.
    recovery: Option<BTreeMap<String, (f64, f64, f64)>>,
    volumetric: Option<(f64, f64)>,
    /// Forward − backward per line with both runs [µm].
    reversal: BTreeMap<String, f64>,
}

impl Report {
    /// `--json`: the errors JSON with the fit's figures beside it.
    fn json(&self) -> Result<serde_json::Value> {
        let (id, sq) = (&self.id, &self.stated.squareness_sigma);
        let mut v = serde_json::to_value(&self.stated.errors)?;
        let o = v
            .as_object_mut()
            .ok_or_else(|| anyhow::anyhow!("internal: errors JSON is not an object"))?;
        o.insert("degrees".into(), serde_json::to_value(self.degrees)?);
        o.insert("lines".into(), serde_json::json!(self.obs.len()));
        o.insert("readings".into(), serde_json::json!(id.readings));
        o.insert("unknowns".into(), serde_json::json!(id.basis.columns.len()));
        o.insert("rank".into(), serde_json::json!(id.rank));
        o.insert(
            "condition_number".into(),
            condition_json(id.condition_number),
        );
        o.insert(
            "singular_values".into(),
            serde_json::json!(id.singular_values),
        );
        o.insert(
            "unobservable".into(),
            serde_json::to_value(&id.unobservable)?,
        );
        o.insert(
            "residual_rms_um".into(),
            serde_json::json!(id.residual_rms_um),
        );
        o.insert("reversal_um".into(), serde_json::json!(self.reversal));
        o.insert(
            "leave_one_line_out".into(),
            serde_json::to_value(&self.loo)?,
        );
        o.insert(
            "sigma_class".into(),
            serde_json::json!("shape-free: the generic posterior (Legendre degree 16 per error), sqrt((value - its mean)^2 + (adequacy.sigma_inflation x its sigma)^2)"),
        );
        o.insert(
            "squareness_sigma_urad".into(),
            serde_json::json!({"EC0Y": sq[0], "EB0Z": sq[1], "EA0Z": sq[2]}),
        );
        if let Some(r) = &self.recovery {
            o.insert("recovery".into(), recovery_json(r));
        }
        if let Some((b, af)) = self.volumetric {
            o.insert(
                "volumetric_rms_um".into(),
                serde_json::json!({"before": b, "after": af, "reduction_pct": 100.0 * (1.0 - af / b)}),
            );
        }
        Ok(v)
    }

    /// The report in words: the fit, the held-out lines, the adequacy
    /// verdict, then the error functions.
    fn print(&self) {
        print_identification(&self.id, &self.obs, self.stroke, &self.st, self.points);
        print_loo(&self.loo);
        print_verdict(&self.stated.adequacy);
        println!(
            "σ's printed are those of a model not told the shape (Legendre degree 16 per error, evidence-chosen prior, its misfit inflation × {:.2}), about these values: what no line sees keeps its prior's spread",
            self.stated.adequacy.sigma_inflation
        );
        if !self.id.unobservable_terms.is_empty() {
            println!(
                "unobservable (not determined by these lines, values meaningless): {}",
                self.id.unobservable_terms.join(", ")
            );
        }
        self.print_errors();
    }

    /// Each error function tabulated with its largest σ (and recovery),
    /// the squareness, the reversal, the held-out grid.
    fn print_errors(&self) {
        for t in Term::all() {
            let tj = &self.stated.errors.errors[&t.name()];
            let vals: Vec<String> = tj.values.iter().map(|v| format!("{v:7.2}")).collect();
            let rec_s = recovery_text(self.recovery.as_ref(), t);
            let smax = tj.sigma.iter().copied().fold(0.0, f64::max);
            println!(
                "  {} [{:4}] {}   σ ≤ {smax:.2}{rec_s}",
                t.name(),
                tj.unit,
                vals.join(" ")
            );
        }
        let (s, sq) = (self.id.errors.squareness, &self.stated.squareness_sigma);
        println!(
            "  squareness [urad]: EC0Y {:.2} ± {:.2}, EB0Z {:.2} ± {:.2}, EA0Z {:.2} ± {:.2}",
            s.c0y, sq[0], s.b0z, sq[1], s.a0z, sq[2]
        );
        if !self.reversal.is_empty() {
            let r: Vec<String> = self
                .reversal
                .iter()
                .map(|(k, v)| format!("{k} {v:.2}"))
                .collect();
            println!(
                "  reversal (forward − backward, µm along the line): {}",
                r.join(", ")
            );
        }
        if let Some((b, af)) = self.volumetric {
            println!(
                "  held-out grid: tool-point error RMS {b:.2} µm before, {af:.2} µm after ({:.1} % less)",
                100.0 * (1.0 - af / b)
            );
        }
    }
}

fn print_loo(loo: &LeaveOneLineOut) {
    println!(
        "leave-one-line-out prediction RMS {:.3} µm beside reading noise {:.3} µm (from the readings' 4th differences; the residual implies {:.3} µm); {} direction(s) only the left-out line sees taken from it",
        loo.rms_um, loo.noise_um, loo.residual_noise_um, loo.null_directions
    );
    if let Some(w) = &loo.warning {
        println!("WARNING: {w}");
    }
}

fn print_identification(
    id: &Identification,
    obs: &[LineObs],
    stroke: [f64; 3],
    st: &Structure,
    points: usize,
) {
    println!(
        "{} lines ({} readings), structure {st}, strokes {:.0}×{:.0}×{:.0} mm",
        obs.len(),
        id.readings,
        stroke[0],
        stroke[1],
        stroke[2]
    );
    let d = id.basis.degrees;
    println!(
        "model: degree {} (positioning, pitch, yaw), {} (straightness), {} (roll): {} unknowns",
        d.main,
        d.straightness,
        d.roll,
        id.basis.columns.len()
    );
    println!(
        "rank {} of {}; condition number {}; residual RMS {:.3} µm",
        id.rank,
        id.basis.columns.len(),
        condition_text(id.condition_number),
        id.residual_rms_um
    );
    if id.unobservable.is_empty() {
        println!("every unknown is observable from these lines");
    } else {
        println!(
            "NOT observable from these lines ({} combinations, left at zero):",
            id.unobservable.len()
        );
        for u in &id.unobservable {
            println!("  {}", combination_text(&u.combination));
        }
    }
    println!("error functions at {points} positions per axis:");
}

/// A condition number as printed: one decimal, or "infinite" when the lines
/// leave some combination of the unknowns unseen.
pub fn condition_text(c: f64) -> String {
    if c.is_finite() {
        format!("{c:.1}")
    } else {
        "infinite".into()
    }
}

/// A condition number in JSON: the number, or null when infinite.
pub fn condition_json(c: f64) -> serde_json::Value {
    if c.is_finite() {
        serde_json::json!(c)
    } else {
        serde_json::Value::Null
    }
}

/// A combination the lines cannot see, as `+0.71·EXX -0.71·EYY`.
pub fn combination_text(combination: &[(String, f64)]) -> String {
    let c: Vec<String> = combination
        .iter()
        .map(|(n, w)| format!("{w:+.2}·{n}"))
        .collect();
    c.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unseen_combination_reads_infinite_in_words_and_null_in_json() {
        assert_eq!(condition_text(381.21), "381.2");
        assert_eq!(condition_text(f64::INFINITY), "infinite");
        assert_eq!(condition_json(381.25), serde_json::json!(381.25));
        assert_eq!(condition_json(f64::INFINITY), serde_json::Value::Null);
        let c = [("EXX".to_string(), 0.6), ("EYY".to_string(), -0.8)];
        assert_eq!(combination_text(&c), "+0.60·EXX -0.80·EYY");
    }
}

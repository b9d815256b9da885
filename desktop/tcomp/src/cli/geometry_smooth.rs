//! `tcomp geometry identify --method smooth` (issue 29): the identification
//! of `smooth.rs` from line files, with its report (effective number of
//! parameters, noise found, leave-one-line-out error beside the fit
//! residual, per-line scale) and the same refusal as the polynomial model
//! when errors are not determined (`--partial` writes them marked). Also
//! what both identify methods read and report alike: the strokes, the line
//! files of one temperature state, the recovery against `--truth`.

use anyhow::{bail, Result};
use std::collections::BTreeMap;

use std::path::{Path, PathBuf};

use super::geometry_table::parse_triple;
use tcomp_geometry::dense::identify_dense;
use tcomp_geometry::errors::Term;
use tcomp_geometry::identify::LineObs;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::{average_runs, Averaged, LineFile};
use tcomp_geometry::smooth::{
    identify_smooth, SmoothFit, DEFAULT_DEGREE, DETERMINED_UM, DETERMINED_URAD,
};
use tcomp_geometry::study::{recovery, ErrorsJson};

/// What `identify --method smooth` reads of the `identify` flags.
pub struct SmoothRequest<'a> {
    /// `--method dense` with its nodes per error (values per node) rather
    /// than `smooth` (Legendre).
    pub dense: Option<usize>,
    pub files: &'a [PathBuf],
    /// `--stroke X,Y,Z` as given.
    pub stroke: Option<&'a str>,
    pub points: usize,
    pub truth: Option<&'a Path>,
    pub partial: bool,
    pub json: bool,
}

/// The axis strokes: `--stroke` as given, or the range the lines cover.
pub fn stroke_from(stroke: Option<&str>, obs: &[LineObs]) -> Result<[f64; 3]> {
    let stroke = match stroke {
        Some(s) => parse_triple(s, "--stroke")?,
        None => {
            let mut m = [0.0f64; 3];
            for p in obs.iter().flat_map(|l| &l.points) {
                for k in 0..3 {
                    m[k] = m[k].max(p.pos_mm[k].abs());
                }
            }
            m
        }
    };
    if stroke.iter().any(|x| !(*x > 0.0)) {
        bail!("the lines do not move every axis; give --stroke X,Y,Z");
    }
    Ok(stroke)
}

/// The line files, forward/backward runs averaged, of one temperature
/// state; `hint` ends the refusal of several states.
pub fn read_one_state(paths: &[PathBuf], hint: &str) -> Result<(Structure, Vec<Averaged>)> {
    let files: Vec<LineFile> = paths
        .iter()
        .map(|p| LineFile::read(p))
        .collect::<Result<_>>()?;
    let st = tcomp_geometry::guard::common_structure(&files, paths)?;
    let avg = average_runs(&files)?;
    let states: std::collections::BTreeSet<_> =
        avg.iter().map(|a| a.temperature_state.clone()).collect();
    if states.len() > 1 {
        bail!(
            "the files come from {} temperature states; identify one state at a time{hint}",
            states.len()
        );
    }
    Ok((st, avg))
}

/// Per term (max, RMS, true peak) of the recovery error, as JSON.
pub fn recovery_json(r: &BTreeMap<String, (f64, f64, f64)>) -> serde_json::Value {
    let m: BTreeMap<_, _> = r
        .iter()
        .map(|(k, (mx, rms, pk))| {
            (
                k.clone(),
                serde_json::json!({"max": mx, "rms": rms, "true_peak": pk}),
            )
        })
        .collect();
    serde_json::json!(m)
}

/// A term's recovery error in words (empty without `--truth`).
pub fn recovery_text(r: Option<&BTreeMap<String, (f64, f64, f64)>>, t: Term) -> String {
    r.map(|r| {
        let (mx, rms, _) = r[&t.name()];
        format!("   recovery max {mx:.2} rms {rms:.2}")
    })
    .unwrap_or_default()
}

pub fn identify_smooth_cmd(a: &SmoothRequest) -> Result<()> {
    let (st, avg) = read_one_state(a.files, "")?;
    let obs: Vec<LineObs> = avg.iter().map(|a| a.obs.clone()).collect();
    let stroke = stroke_from(a.stroke, &obs)?;
    let fit = match a.dense {
        Some(nodes) => identify_dense(&st, &obs, nodes, stroke)?,
        None => identify_smooth(&st, &obs, DEFAULT_DEGREE, stroke)?,
    };
    if !fit.unobservable_terms.is_empty() && !a.partial {
        bail!(
            "{} lines do not determine {} (posterior standard deviation above {DETERMINED_UM} µm / {DETERMINED_URAD} µrad); measure more lines, or give --partial to write the model with these marked unobservable",
            obs.len(),
            fit.unobservable_terms.join(", ")
        );
    }
    let mut ej = ErrorsJson::from_errors(&fit.errors, &st, stroke, a.points);
    ej.unobservable_terms = fit.unobservable_terms.clone();
    let truth = match a.truth {
        Some(p) => Some(ErrorsJson::read(p)?.to_errors()?),
        None => None,
    };
    let rec = truth.as_ref().map(|t| recovery(&fit.errors, t, stroke));
    if a.json {
        let mut v = serde_json::to_value(&ej)?;
        let o = v
            .as_object_mut()
            .ok_or_else(|| anyhow::anyhow!("internal: errors JSON is not an object"))?;
        o.insert(
            "method".into(),
            serde_json::json!(if a.dense.is_some() { "dense" } else { "smooth" }),
        );
        o.insert("lines".into(), serde_json::json!(obs.len()));
        o.insert("identification".into(), serde_json::to_value(&fit)?);
        if let Some(r) = &rec {
            o.insert("recovery".into(), recovery_json(r));
        }
        println!("{v}");
        if let Some(w) = &fit.warning {
            eprintln!("warning: {w}");
        }
        return Ok(());
    }
    print_fit(&fit, stroke);
    for t in Term::all() {
        let tj = &ej.errors[&t.name()];
        let vals: Vec<String> = tj.values.iter().map(|v| format!("{v:7.2}")).collect();
        let rec_s = recovery_text(rec.as_ref(), t);
        println!("  {} [{:4}] {}{rec_s}", t.name(), tj.unit, vals.join(" "));
    }
    let s = fit.errors.squareness;
    println!(
        "  squareness [urad]: EC0Y {:.2}, EB0Z {:.2}, EA0Z {:.2}",
        s.c0y, s.b0z, s.a0z
    );
    Ok(())
}

fn print_fit(f: &SmoothFit, stroke: [f64; 3]) {
    println!(
        "{} lines ({} readings), strokes {:.0}×{:.0}×{:.0} mm; no shape assumed: {} per error, {} unknowns, {:.1} effective parameters",
        f.lines, f.readings, stroke[0], stroke[1], stroke[2], f.basis, f.unknowns, f.effective_parameters
    );
    let h = &f.hyper;
    println!(
        "prior chosen by the evidence: noise {:.3} µm, size {:.2} µm positioning, {:.2} µm straightness, {:.2} µrad angles{}",
        h.noise_um,
        h.positioning_um,
        h.straightness_um,
        h.angular_urad,
        match (h.decay, h.length_scale_strokes) {
            (Some(p), _) => format!(", order decay {p:.2}"),
            (None, Some(l)) => format!(", length scale {l:.3} strokes"),
            (None, None) => String::new(),
        }
    );
    println!(
        "residual RMS {:.3} µm; leave-one-line-out prediction RMS {:.3} µm",
        f.residual_rms_um, f.loo_rms_um
    );
    if let Some(w) = &f.warning {
        println!("WARNING: {w}");
    }
    let sc: Vec<String> = f
        .line_scale_ppm
        .iter()
        .map(|(l, v)| format!("{l} {v:+.2}"))
        .collect();
    println!(
        "laser scale per line [ppm] (prior 1 ppm): {}",
        sc.join(", ")
    );
    if !f.unobservable_terms.is_empty() {
        println!(
            "unobservable (not determined by these lines, values are the prior's): {}",
            f.unobservable_terms.join(", ")
        );
    }
}

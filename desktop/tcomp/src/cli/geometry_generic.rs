//! `tcomp geometry identify --method generic` (issue 49): the generic
//! identifier of `tcomp_geometry::generic` from line files — the default
//! when the lines determine the machine (at least `generic::MIN_LINES`
//! lines and no null direction of the shape-free class). Its report and
//! `--json` carry what the polynomial model's do in the same fields (per
//! error `sigma` at its positions, `squareness_sigma_urad`,
//! `unobservable_terms`, `unobservable`, `adequate`, `adequacy`), with the
//! fit's own figures under `identification`.

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

use super::geometry_adequacy::{inadequate_warning, print_adequacy, refuse_inadequate};
use super::geometry_smooth::{read_one_state, recovery_json, recovery_text, stroke_from};
use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::errors::Term;
use tcomp_geometry::generic::{
    identify_generic, null_combinations, Generic, MIN_LINES, UNDETERMINED_RATIO,
};
use tcomp_geometry::identify::{LineKind, LineObs};
use tcomp_geometry::study::{recovery, ErrorsJson};

/// `identify --method generic` as given.
pub struct GenericRequest<'a> {
    pub files: &'a [PathBuf],
    pub stroke: Option<&'a str>,
    pub points: usize,
    pub truth: Option<&'a Path>,
    pub partial: bool,
    pub noise_um: Option<f64>,
    pub accept_inadequate: bool,
    pub json: bool,
}

/// What `identify` does without `--method`: `generic` when the lines
/// determine the machine, else `poly` (its refusal then names the
/// combinations no line sees, returned here in words, with the number of
/// lines).
pub fn default_method(
    files: &[PathBuf],
    stroke: Option<&str>,
) -> (&'static str, Vec<String>, usize) {
    let Ok((st, avg)) = read_one_state(files, "") else {
        return ("poly", Vec::new(), 0);
    };
    let obs: Vec<LineObs> = avg.into_iter().map(|a| a.obs).collect();
    let Ok(stroke) = stroke_from(stroke, &obs) else {
        return ("poly", Vec::new(), obs.len());
    };
    let nulls: Vec<String> = null_combinations(&st, &obs, stroke)
        .into_iter()
        .map(|(w, _)| w)
        .collect();
    if obs.len() >= MIN_LINES && nulls.is_empty() {
        ("generic", nulls, obs.len())
    } else {
        ("poly", nulls, obs.len())
    }
}

/// The combinations no line sees, in one clause (first three named).
pub fn nulls_clause(lines: usize, nulls: &[String]) -> String {
    let shown: Vec<&str> = nulls.iter().take(3).map(String::as_str).collect();
    format!(
        "these {lines} lines leave {} combinations of the errors that no line sees when no shape is assumed (e.g. {}{})",
        nulls.len(),
        shown.join("; "),
        if nulls.len() > 3 { "; …" } else { "" }
    )
}

pub fn identify_generic_cmd(r: &GenericRequest) -> Result<()> {
    let (st, avg) = read_one_state(r.files, "")?;
    let obs: Vec<LineObs> = avg.iter().map(|a| a.obs.clone()).collect();
    let stroke = stroke_from(r.stroke, &obs)?;
    let nulls = null_combinations(&st, &obs, stroke);
    if !nulls.is_empty() && !r.partial {
        let words: Vec<String> = nulls.iter().map(|n| n.0.clone()).collect();
        bail!(
            "{}; measure more lines: `tcomp geometry plan --plan rich`, or give --partial",
            nulls_clause(obs.len(), &words)
        );
    }
    let g = identify_generic(&st, &obs, stroke)?;
    let noise = StatedNoise::new(r.noise_um)?;
    let line_sigma: Vec<f64> = avg
        .iter()
        .map(|l| match l.reversal_um {
            Some(_) => noise.um / std::f64::consts::SQRT_2,
            None => noise.um,
        })
        .collect();
    let adq = g.adequacy(&line_sigma, noise);
    if !g.fit.unobservable_terms.is_empty() && !r.partial {
        bail!(
            "{} lines do not determine {} (posterior σ above {UNDETERMINED_RATIO} of the prior's); measure more lines: `tcomp geometry plan --plan rich`, or give --partial to write the model with these marked unobservable",
            obs.len(),
            g.fit.unobservable_terms.join(", ")
        );
    }
    refuse_inadequate(
        &adq,
        r.accept_inadequate,
        &format!("the generic model of these {} lines", obs.len()),
        "measure more lines: `tcomp geometry plan`",
    )?;
    let f = adq.sigma_inflation;
    let mut ej = ErrorsJson::from_errors(&g.fit.errors, &st, stroke, r.points);
    ej.unobservable_terms = g.fit.unobservable_terms.clone();
    for t in Term::all() {
        if let Some(tj) = ej.errors.get_mut(&t.name()) {
            tj.sigma = tj.positions_mm.iter().map(|q| f * g.sigma(t, *q)).collect();
        }
    }
    let sq: Vec<f64> = (0..3).map(|i| f * g.squareness_sigma(i)).collect();
    ej.adequate = Some(adq.adequate);
    ej.adequacy = Some(adq.clone());
    let rec = match r.truth {
        Some(p) => Some(recovery(
            &g.fit.errors,
            &ErrorsJson::read(p)?.to_errors()?,
            stroke,
        )),
        None => None,
    };
    let reversal: std::collections::BTreeMap<String, f64> = avg
        .iter()
        .filter_map(|a| a.reversal_um.map(|v| (a.obs.id.clone(), v)))
        .collect();
    if r.json {
        let mut v = serde_json::to_value(&ej)?;
        let o = v
            .as_object_mut()
            .ok_or_else(|| anyhow::anyhow!("internal: errors JSON is not an object"))?;
        let unseen: Vec<_> = nulls
            .iter()
            .map(|(w, t)| serde_json::json!({"words": w, "terms": t}))
            .collect();
        o.insert("method".into(), serde_json::json!("generic"));
        o.insert("lines".into(), serde_json::json!(obs.len()));
        o.insert("readings".into(), serde_json::json!(g.fit.readings));
        o.insert("unknowns".into(), serde_json::json!(g.fit.unknowns));
        o.insert("unobservable".into(), serde_json::json!(unseen));
        o.insert(
            "residual_rms_um".into(),
            serde_json::json!(g.fit.residual_rms_um),
        );
        o.insert("reversal_um".into(), serde_json::json!(reversal));
        o.insert(
            "leave_one_line_out".into(),
            serde_json::json!({"rms_um": g.fit.loo_rms_um, "per_line_um": g.loo_per_line()}),
        );
        o.insert(
            "squareness_sigma_urad".into(),
            serde_json::json!({"EC0Y": sq[0], "EB0Z": sq[1], "EA0Z": sq[2]}),
        );
        o.insert(
            "posterior_over_prior_sigma".into(),
            serde_json::json!(g.ratio),
        );
        o.insert(
            "scale_prior_ppm".into(),
            serde_json::json!(g.scale_prior_ppm),
        );
        o.insert("identification".into(), serde_json::to_value(&g.fit)?);
        if let Some(rc) = &rec {
            o.insert("recovery".into(), recovery_json(rc));
        }
        println!("{v}");
    } else {
        print_generic(&g, &obs, stroke);
        print_adequacy(&adq);
        for t in Term::all() {
            let tj = &ej.errors[&t.name()];
            let vals: Vec<String> = tj.values.iter().map(|v| format!("{v:7.2}")).collect();
            let smax = tj.sigma.iter().copied().fold(0.0, f64::max);
            let rec_s = recovery_text(rec.as_ref(), t);
            println!(
                "  {} [{:4}] {}   σ ≤ {smax:.2}{rec_s}",
                t.name(),
                tj.unit,
                vals.join(" ")
            );
        }
        let s = g.fit.errors.squareness;
        println!(
            "  squareness [urad]: EC0Y {:.2} ± {:.2}, EB0Z {:.2} ± {:.2}, EA0Z {:.2} ± {:.2}",
            s.c0y, sq[0], s.b0z, sq[1], s.a0z, sq[2]
        );
    }
    if let Some(w) = inadequate_warning(&adq, "model") {
        eprintln!("warning: {w}");
    }
    Ok(())
}

fn print_generic(g: &Generic, obs: &[LineObs], stroke: [f64; 3]) {
    let f = &g.fit;
    println!(
        "{} lines ({} readings), strokes {:.0}×{:.0}×{:.0} mm; generic model, no shape assumed: {} per error, {} unknowns, {:.1} effective parameters",
        f.lines, f.readings, stroke[0], stroke[1], stroke[2], f.basis, f.unknowns, f.effective_parameters
    );
    let h = &f.hyper;
    println!(
        "prior chosen by the evidence: noise {:.3} µm, size {:.2} µm positioning, {:.2} µm straightness, {:.2} µrad angles, order decay {:.2}, laser scale {:.2} ppm per line",
        h.noise_um,
        h.positioning_um,
        h.straightness_um,
        h.angular_urad,
        h.decay.unwrap_or(0.0),
        g.scale_prior_ppm
    );
    println!(
        "residual RMS {:.3} µm; leave-one-line-out prediction RMS {:.3} µm",
        f.residual_rms_um, f.loo_rms_um
    );
    // A straightness line's column is its optic's slope [µrad], not a scale.
    let optic = |id: &str| (obs.iter()).any(|o| o.id == id && o.kind == LineKind::Straightness);
    let sc: Vec<String> = (f.line_scale_ppm.iter())
        .filter(|(l, _)| !optic(l))
        .map(|(l, v)| format!("{l} {v:+.2}"))
        .collect();
    println!("laser scale per line [ppm]: {}", sc.join(", "));
    let sl: Vec<String> = (f.line_scale_ppm.iter())
        .filter(|(l, _)| optic(l))
        .map(|(l, v)| format!("{l} {v:+.1}"))
        .collect();
    if !sl.is_empty() {
        println!(
            "straightness optic slope per line [µrad]: {}",
            sl.join(", ")
        );
    }
    if !f.unobservable_terms.is_empty() {
        println!(
            "undetermined (posterior σ above {UNDETERMINED_RATIO} of the prior's; values are mostly the prior's): {}",
            f.unobservable_terms.join(", ")
        );
    }
    println!("error functions with their posterior σ (× the misfit inflation):");
}

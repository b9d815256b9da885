//! The linear axes as `tcomp geometry identify-rotary` takes them: none, an
//! errors JSON (known input), or line files — fitted together with the
//! R-test files, by the generic identifier when the lines determine the
//! machine (`identify`'s rule: at least `generic::MIN_LINES` lines and no
//! null direction of the shape-free class; `rotary::joint_generic`), else
//! by the polynomial model (`rotary::joint`, the 14-line plan).

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

use super::geometry_adequacy::{inadequate_warning, refuse_inadequate};
use tcomp_geometry::adequacy::StatedNoise;
use tcomp_geometry::errors::GeometricErrors;
use tcomp_geometry::generic::{identify_generic, null_combinations, Generic, MIN_LINES};
use tcomp_geometry::identify::{identify, Degrees, Identification, LineObs};
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::lines::{average_runs, LineFile};
use tcomp_geometry::rotary::identify::{identify_rotary, RotaryIdentification, RotaryOptions};
use tcomp_geometry::rotary::joint::{identify_rotary_joint, LinearPrior};
use tcomp_geometry::rotary::joint_generic::{identify_rotary_joint_generic, GenericPrior};
use tcomp_geometry::rotary::Linear;
use tcomp_geometry::rtest::RTestFile;
use tcomp_geometry::study::ErrorsJson;

/// The linear axes as the rotary fit takes them.
pub enum LinearIn {
    None,
    /// An errors JSON: known input.
    Known(Structure, Box<GeometricErrors>),
    /// Line files: the polynomial identification and the averaged lines.
    Lines(Structure, Box<Identification>, Vec<LineObs>, [f64; 3]),
    /// Line files that determine the machine: the generic identification.
    Generic(Structure, Box<Generic>, Vec<LineObs>, [f64; 3]),
}

impl LinearIn {
    /// Line files were given.
    pub fn has_lines(&self) -> bool {
        matches!(self, LinearIn::Lines(..) | LinearIn::Generic(..))
    }
}

/// The linear axes' errors from an errors JSON or line files; the generic
/// model of line files is held to `identify`'s adequacy test at `noise`
/// (refused unless `accept_inadequate`).
pub fn linear_input(
    paths: &[PathBuf],
    accept_inadequate: bool,
    noise: StatedNoise,
) -> Result<LinearIn> {
    match paths {
        [] => Ok(LinearIn::None),
        [p] if p.extension().is_some_and(|e| e == "json") => {
            let ej = ErrorsJson::read(p)?;
            if let Some(w) = tcomp_geometry::adequacy::check_model_file(
                ej.adequate,
                p,
                accept_inadequate,
                ej.adequacy.as_ref().map(|a| a.failure.as_str()),
            )? {
                eprintln!("warning: {w}");
            }
            if !ej.unobservable_terms.is_empty() {
                bail!(
                    "{}: the linear model has unobservable terms ({}); it cannot be known input",
                    p.display(),
                    ej.unobservable_terms.join(", ")
                );
            }
            let st = Structure::parse(&ej.structure).with_context(|| p.display().to_string())?;
            Ok(LinearIn::Known(st, Box::new(ej.to_errors()?)))
        }
        _ => {
            let files: Vec<LineFile> = paths
                .iter()
                .map(|p| LineFile::read(p))
                .collect::<Result<_>>()?;
            let st = tcomp_geometry::guard::common_structure(&files, paths)?;
            let avg = average_runs(&files)?;
            let sigma: Vec<f64> = (avg.iter())
                .map(|a| match a.reversal_um {
                    Some(_) => noise.um / std::f64::consts::SQRT_2,
                    None => noise.um,
                })
                .collect();
            let obs: Vec<LineObs> = avg.into_iter().map(|a| a.obs).collect();
            let stroke = super::geometry_smooth::stroke_from(None, &obs)?;
            if obs.len() >= MIN_LINES && null_combinations(&st, &obs, stroke).is_empty() {
                let g = identify_generic(&st, &obs, stroke)?;
                let adq = g.adequacy(&sigma, noise);
                let what = format!("the generic linear model of these {} lines", obs.len());
                refuse_inadequate(&adq, accept_inadequate, &what, "measure the lines again")?;
                if let Some(w) = inadequate_warning(&adq, "generic linear model") {
                    eprintln!("warning: {w}");
                }
                return Ok(LinearIn::Generic(st, Box::new(g), obs, stroke));
            }
            let id = identify(&st, &obs, Degrees::default(), stroke)?;
            tcomp_geometry::guard::refuse_unobservable(&id, obs.len(), false)?;
            Ok(LinearIn::Lines(st, Box::new(id), obs, stroke))
        }
    }
}

/// The rotary fit with the linear axes as `lin` gives them (`fixed`: line
/// files' model as known input); the corrected linear model is written to
/// `linear_out` when given (joint fits only).
pub fn fit_rotary(
    files: &[RTestFile],
    lin: &LinearIn,
    o: &RotaryOptions,
    fixed: bool,
    linear_out: Option<&PathBuf>,
) -> Result<RotaryIdentification> {
    let known = |st: &Structure, e: &GeometricErrors| {
        let l = Linear {
            structure: st,
            errors: e,
        };
        identify_rotary(files, Some(l), o)
    };
    let write = |corrected: &GeometricErrors, st: &Structure, stroke: [f64; 3]| match linear_out {
        Some(p) => {
            let ej = ErrorsJson::from_errors(corrected, st, stroke, 11);
            let text = serde_json::to_string_pretty(&serde_json::to_value(&ej)?)?;
            std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))
        }
        None => Ok(()),
    };
    match lin {
        LinearIn::None => identify_rotary(files, None, o),
        LinearIn::Known(st, e) => known(st, e),
        LinearIn::Lines(st, idl, ..) if fixed => known(st, &idl.errors),
        LinearIn::Generic(st, g, ..) if fixed => known(st, &g.fit.errors),
        LinearIn::Lines(st, idl, obs, stroke) => {
            let prior = LinearPrior {
                structure: st,
                identification: idl,
                lines: obs,
            };
            let (id, corrected) = identify_rotary_joint(files, &prior, o)?;
            write(&corrected, st, *stroke)?;
            Ok(id)
        }
        LinearIn::Generic(st, g, obs, stroke) => {
            let prior = GenericPrior {
                structure: st,
                generic: g,
                lines: obs,
            };
            let (id, corrected) = identify_rotary_joint_generic(files, &prior, o)?;
            write(&corrected, st, *stroke)?;
            Ok(id)
        }
    }
}

//! What the geometry commands and benchmarks share: the errors file
//! (`ErrorsJson`, written by `tcomp geometry simulate|identify --json`, read
//! by `check`, `tooltip`, `table` and `tcomp export --geometry`) and the
//! figures of a simulated identification (`recovery`, `volumetric_residual`).

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

use crate::errors::{GeometricErrors, Poly, Squareness, Term};
use crate::identify::to_reference_convention;
use crate::kinematics::{tool_tip_error_exact, Structure};

/// Errors as JSON: per term the polynomial and a table; squareness apart.
#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct TermJson {
    pub positions_mm: Vec<f64>,
    pub values: Vec<f64>,
    pub unit: String,
    pub poly: Poly,
    /// Posterior standard deviation at `positions_mm` (identify), inflated
    /// by the measured misfit (`adequacy.sigma_inflation`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sigma: Vec<f64>,
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct ErrorsJson {
    pub structure: String,
    pub stroke_mm: [f64; 3],
    pub errors: BTreeMap<String, TermJson>,
    pub squareness_urad: Squareness,
    /// Errors the lines did not determine (`identify --partial`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unobservable_terms: Vec<String>,
    /// The adequacy verdict of the identification (issue 49); absent in
    /// files from before the test (then: unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequate: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adequacy: Option<crate::adequacy::Adequacy>,
}

impl ErrorsJson {
    pub fn from_errors(
        e: &GeometricErrors,
        st: &Structure,
        stroke: [f64; 3],
        points: usize,
    ) -> Self {
        let n = points.max(2);
        let errors = Term::all()
            .map(|t| {
                let l = stroke[t.axis.index()];
                let positions_mm: Vec<f64> =
                    (0..n).map(|i| l * i as f64 / (n - 1) as f64).collect();
                let values = positions_mm.iter().map(|q| e.value(t, *q)).collect();
                let poly = e.get(t).clone();
                (
                    t.name(),
                    TermJson {
                        positions_mm,
                        values,
                        unit: t.component.unit().to_string(),
                        poly,
                        sigma: Vec::new(),
                    },
                )
            })
            .collect();
        ErrorsJson {
            structure: st.to_string(),
            stroke_mm: stroke,
            errors,
            squareness_urad: e.squareness,
            unobservable_terms: Vec::new(),
            adequate: None,
            adequacy: None,
        }
    }

    pub fn to_errors(&self) -> Result<GeometricErrors> {
        let mut e = GeometricErrors::zero();
        for (name, tj) in &self.errors {
            let t = crate::errors::parse_term(name)?;
            if !(tj.poly.scale_mm > 0.0) {
                bail!("{name}: poly.scale_mm must be positive");
            }
            e.set(t, tj.poly.clone());
        }
        e.squareness = self.squareness_urad;
        Ok(e)
    }

    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }
}

/// Max and RMS difference of identified minus true over the stroke, per term.
pub fn recovery(
    id: &GeometricErrors,
    truth: &GeometricErrors,
    stroke: [f64; 3],
) -> BTreeMap<String, (f64, f64, f64)> {
    let conv = to_reference_convention(truth, stroke);
    let mut out = BTreeMap::new();
    for t in Term::all() {
        let l = stroke[t.axis.index()];
        let (mut mx, mut ss, mut peak) = (0.0f64, 0.0, 0.0f64);
        let n = 101;
        for i in 0..n {
            let q = l * i as f64 / (n - 1) as f64;
            let d = id.value(t, q) - conv.value(t, q);
            mx = mx.max(d.abs());
            ss += d * d;
            peak = peak.max(conv.value(t, q).abs());
        }
        out.insert(t.name(), (mx, (ss / n as f64).sqrt(), peak));
    }
    out
}

/// RMS tool-point error over a held-out grid before and after compensation
/// with the identified errors [µm] (exact kinematics for the truth).
pub fn volumetric_residual(
    st: &Structure,
    id: &GeometricErrors,
    truth: &GeometricErrors,
    stroke: [f64; 3],
) -> (f64, f64) {
    let conv = to_reference_convention(truth, stroke);
    let (mut before, mut after, mut n) = (0.0, 0.0, 0);
    // A 6×6×6 grid off the plan's 3×3×3 grid, two tools.
    for i in 0..6 {
        for j in 0..6 {
            for k in 0..6 {
                let f = |m: usize, l: f64| l * (0.05 + 0.18 * m as f64);
                let pos = [f(i, stroke[0]), f(j, stroke[1]), f(k, stroke[2])];
                for tool in [[0.0, 0.0, 120.0], [40.0, -60.0, 180.0]] {
                    let t = tool_tip_error_exact(st, &conv, pos, tool);
                    let p = tool_tip_error_exact(st, id, pos, tool);
                    before += t.norm_squared();
                    after += (t - p).norm_squared();
                    n += 1;
                }
            }
        }
    }
    ((before / n as f64).sqrt(), (after / n as f64).sqrt())
}

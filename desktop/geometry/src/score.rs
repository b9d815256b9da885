//! Scoring an identified model against a machine that is not a polynomial
//! (issue 29): the truth as tabulated functions (`errors.<name>.positions_mm`
//! / `values`, the shape `desktop/tcomp/tests/data/geometry_rich_gen.py` writes; the
//! `poly` of each term is not needed), compared in the ISO end-point
//! reference convention (docs/geometry.md), and predictions of held-out
//! lines (line files in random directions) against their readings.
//! The command is `tcomp geometry score` (crate `tcomp`).

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::errors::{GeometricErrors, Term, SQUARENESS_NAMES};
use super::kinematics::{tool_tip_error_exact, Structure};
use super::lines::LineFile;

/// A machine's errors as tables (any shape), linear interpolation.
#[derive(Clone, Debug)]
pub struct TabulatedTruth {
    pub stroke_mm: [f64; 3],
    /// Per term: positions [mm] and values [µm or µrad].
    pub funcs: BTreeMap<String, (Vec<f64>, Vec<f64>)>,
    /// EC0Y, EB0Z, EA0Z [µrad] as given (not yet in the reference convention).
    pub squareness_urad: [f64; 3],
}

impl TabulatedTruth {
    pub fn read(path: &Path) -> Result<TabulatedTruth> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let p = path.display();
        let nums = |x: &serde_json::Value, what: &str| -> Result<Vec<f64>> {
            x.as_array()
                .ok_or_else(|| anyhow::anyhow!("{p}: {what} is not an array"))?
                .iter()
                .map(|n| {
                    n.as_f64()
                        .ok_or_else(|| anyhow::anyhow!("{p}: {what}: not a number"))
                })
                .collect()
        };
        let stroke = nums(&v["stroke_mm"], "stroke_mm")?;
        if stroke.len() != 3 {
            bail!("{p}: stroke_mm needs three numbers");
        }
        let mut funcs = BTreeMap::new();
        for t in Term::all() {
            let e = &v["errors"][t.name()];
            let q = nums(&e["positions_mm"], &format!("{}.positions_mm", t.name()))?;
            let y = nums(&e["values"], &format!("{}.values", t.name()))?;
            if q.len() != y.len() || q.len() < 2 {
                bail!("{p}: {}: positions and values differ in length", t.name());
            }
            funcs.insert(t.name(), (q, y));
        }
        let mut sq = [0.0; 3];
        for (i, n) in SQUARENESS_NAMES.iter().enumerate() {
            sq[i] = v["squareness_urad"][n]
                .as_f64()
                .ok_or_else(|| anyhow::anyhow!("{p}: squareness_urad.{n} missing"))?;
        }
        Ok(TabulatedTruth {
            stroke_mm: [stroke[0], stroke[1], stroke[2]],
            funcs,
            squareness_urad: sq,
        })
    }

    /// The term's value at q [mm] (linear interpolation, clamped).
    pub fn value(&self, t: Term, q: f64) -> f64 {
        let (x, y) = &self.funcs[&t.name()];
        let i = x.partition_point(|v| *v < q).clamp(1, x.len() - 1);
        let f = ((q - x[i - 1]) / (x[i] - x[i - 1])).clamp(0.0, 1.0);
        y[i - 1] + f * (y[i] - y[i - 1])
    }

    /// In the reference convention: straightness minus its end-point line.
    pub fn value_ref(&self, t: Term, q: f64) -> f64 {
        let l = self.stroke_mm[t.axis.index()];
        if t.is_straightness() {
            self.value(t, q) - self.value(t, l) * q / l
        } else {
            self.value(t, q)
        }
    }

    /// Squareness in the reference convention (as `to_reference_convention`).
    pub fn squareness_ref(&self) -> [f64; 3] {
        let slope = |n: &str| {
            let t = Term::parse(n).expect("term name");
            let l = self.stroke_mm[t.axis.index()];
            self.value(t, l) / l * 1e3
        };
        let s = self.squareness_urad;
        [
            s[0] - slope("EXY") - slope("EYX"),
            s[1] + slope("EXZ") + slope("EZX"),
            s[2] - slope("EYZ") - slope("EZY"),
        ]
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Score {
    /// Per term: max and RMS over the stroke of identified − true [µm, µrad].
    pub terms: BTreeMap<String, (f64, f64)>,
    pub worst_rms_translational_um: f64,
    pub worst_rms_angular_urad: f64,
    pub worst_max_translational_um: f64,
    pub worst_max_angular_urad: f64,
    /// Identified − true squareness [µrad], reference convention.
    pub squareness_error_urad: [f64; 3],
    /// Held-out lines: RMS of the readings (each line's zero removed) and of
    /// readings − prediction [µm]; reduction in %.
    pub heldout: Option<HeldOut>,
}

#[derive(Clone, Debug, Serialize)]
pub struct HeldOut {
    pub lines: usize,
    pub before_um: f64,
    pub after_um: f64,
    pub reduction_pct: f64,
}

pub fn score(
    st: &Structure,
    model: &GeometricErrors,
    truth: &TabulatedTruth,
    heldout: &[LineFile],
) -> Score {
    let mut terms = BTreeMap::new();
    let (mut wt, mut wa, mut mt, mut ma) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for t in Term::all() {
        let l = truth.stroke_mm[t.axis.index()];
        let n = 101;
        let (mut mx, mut ss) = (0.0f64, 0.0);
        for i in 0..n {
            let q = l * i as f64 / (n - 1) as f64;
            let d = model.value(t, q) - truth.value_ref(t, q);
            mx = mx.max(d.abs());
            ss += d * d;
        }
        let rms = (ss / n as f64).sqrt();
        if t.component.is_angular() {
            wa = wa.max(rms);
            ma = ma.max(mx);
        } else {
            wt = wt.max(rms);
            mt = mt.max(mx);
        }
        terms.insert(t.name(), (mx, rms));
    }
    let sr = truth.squareness_ref();
    let sq = [0, 1, 2].map(|i| model.squareness.get(i) - sr[i]);
    let heldout = (!heldout.is_empty()).then(|| heldout_score(st, model, heldout));
    Score {
        terms,
        worst_rms_translational_um: wt,
        worst_rms_angular_urad: wa,
        worst_max_translational_um: mt,
        worst_max_angular_urad: ma,
        squareness_error_urad: sq,
        heldout,
    }
}

/// Predicted readings of each held-out line (exact kinematics of the model,
/// along the line's direction, zero at its first target) against its file.
pub fn heldout_score(st: &Structure, model: &GeometricErrors, lines: &[LineFile]) -> HeldOut {
    let (mut before, mut after, mut n) = (0.0, 0.0, 0usize);
    for f in lines {
        let d = nalgebra::Vector3::from(f.spec.direction);
        let tool = f.spec.tool_offset_mm;
        let pred: Vec<f64> = f
            .pos_mm
            .iter()
            .map(|p| d.dot(&tool_tip_error_exact(st, model, *p, tool)))
            .collect();
        let m = f.disp_um.len() as f64;
        let mb = f.disp_um.iter().sum::<f64>() / m;
        let r: Vec<f64> = f.disp_um.iter().zip(&pred).map(|(y, p)| y - p).collect();
        let mr = r.iter().sum::<f64>() / m;
        before += f.disp_um.iter().map(|y| (y - mb).powi(2)).sum::<f64>();
        after += r.iter().map(|v| (v - mr).powi(2)).sum::<f64>();
        n += f.disp_um.len();
    }
    let (b, a) = (
        (before / n.max(1) as f64).sqrt(),
        (after / n.max(1) as f64).sqrt(),
    );
    HeldOut {
        lines: lines.len(),
        before_um: b,
        after_um: a,
        reduction_pct: 100.0 * (1.0 - a / b),
    }
}

/// The `*.csv` line files of a directory, sorted.
pub fn read_dir_lines(dir: &Path) -> Result<Vec<LineFile>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    paths.sort();
    paths.iter().map(|p| LineFile::read(p)).collect()
}

//! The fit's model types: inputs (`FeatureKind`, `FeatureSpec`), the fitted
//! parameters and the model file `tcomp fit --out` writes, the `Model` trait
//! and the combined models (blend, hybrid, network ensemble).

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::net;

/// What an input measures (before the optional lag).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum FeatureKind {
    /// `T_i(t) − T_i(t_ref)`, `t_ref` = the board's reference row: the first
    /// row of the run at which the sensors are valid (column name).
    SensorRise(String),
    /// `T_a − T_b` (column names).
    SensorDiff(String, String),
    /// Spindle speed, rpm.
    Spindle,
}

/// One network / MLR input: kind, optional first-order lag, training range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureSpec {
    pub kind: FeatureKind,
    /// First-order lag time constant in seconds (`None`: no lag).
    pub tau_s: Option<f64>,
    /// Training range: inputs are clamped to it and mapped to [−1, 1].
    pub min: f64,
    pub max: f64,
}

/// The n_in–n_hidden–1 network of one displacement channel:
/// `h_j = sigmoid(b1_j + Σ_i W1[j][i]·xn_i)`, `y_um = b2 + Σ_j w2_j·h_j`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetParams {
    pub features: Vec<FeatureSpec>,
    /// `w1[j][i]`: hidden unit j, input i.
    pub w1: Vec<Vec<f64>>,
    pub b1: Vec<f64>,
    pub w2: Vec<f64>,
    pub b2: f64,
    /// Displacement column this network predicts (e.g. `dch3_um`).
    pub channel: String,
}

/// Multiple linear regression of one channel: `y_um = c0 + Σ c_i·xn_i`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlrParams {
    pub features: Vec<FeatureSpec>,
    pub c0: f64,
    pub coef: Vec<f64>,
    pub channel: String,
}

/// What `fit --out` writes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Lagged MLR per channel (model name `mlr`).
    pub mlr: Vec<MlrParams>,
    /// Ensemble members per channel (model name `ga-bpn`): the channel's
    /// prediction is the mean of its members.
    pub nets: Vec<NetParams>,
    /// Static MLR on the selected sensors per channel (model name `mlr-static`).
    #[serde(default)]
    pub mlr_static: Vec<MlrParams>,
    /// The model blocked cross-validation on the training rows chose per
    /// channel (`mlr-static`, `mlr`, `hybrid` or `ga-bpn`); what `export`
    /// ships by default.
    #[serde(default)]
    pub chosen: std::collections::BTreeMap<String, String>,
    /// Residual networks per channel (model name `hybrid`): the channel's
    /// hybrid prediction is its lagged MLR (`mlr`) plus the mean of these
    /// members, trained on the MLR's training residual. The board sums a
    /// table and networks of the same direction, so it ships as both.
    #[serde(default)]
    pub hybrid_nets: Vec<NetParams>,
    /// Per channel, the blend's weight `w` on the lagged MLR (model name
    /// `blend`: `w·mlr + (1−w)·ga-bpn`, the same inputs), chosen on the
    /// out-of-fold predictions of the blocked cross-validation.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub blend: std::collections::BTreeMap<String, f64>,
    /// Per channel, models without each of its sensors (degraded mode, issue 15).
    #[serde(default)]
    pub fallbacks: Vec<FallbackParams>,
    /// Ridge regression per channel on the lagged MLR's inputs (model name
    /// `ridge`), its penalty chosen by forward-chaining time-blocked CV on
    /// the training rows: a table like the MLR's, with its own coefficients.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ridge: Vec<MlrParams>,
    /// Per channel, the envelope policy's evidence (issue 50 item 3,
    /// [`super::envelope`]): what `export` writes in the image's policy section.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub envelope: std::collections::BTreeMap<String, EnvelopeEvidence>,
    /// Per channel, the time constant (s) of the low-pass on the served
    /// correction that the forward folds chose ([`super::output_lag`]);
    /// channels without one are absent.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub output_lag_s: std::collections::BTreeMap<String, f64>,
}

/// Model names, simplest first (the order ties are broken in): `none` (no
/// compensation: the board serves 0 about the run's reference) is the
/// simplest of all, so a model must beat it by more than the margin to ship;
/// the ridge has the MLR's form plus one fitted parameter (its penalty), so
/// it comes after the MLR: it ships when it beats the MLR by more than the
/// margin, or when the MLR's coefficients are unstable across the folds and
/// the ridge is within noise of it (`stability`); the hybrid is
/// anchored on the lagged MLR (its network only corrects the residual), so it
/// is taken as simpler than the free network; the blend carries both the
/// lagged MLR's table and the networks, so it comes last: it is chosen only
/// when it beats each of its parts by more than the margin.
pub const MODEL_NAMES: [&str; 7] = [
    "none",
    "mlr-static",
    "mlr",
    "ridge",
    "hybrid",
    "ga-bpn",
    "blend",
];

/// `w·mlr + (1−w)·ensemble` on the same inputs (model name `blend`). The
/// board ships it as the MLR's table with every term scaled by `w` and the
/// networks with their output layers scaled by `(1−w)/k`: one direction's
/// table and networks, which it sums.
pub struct Blend<'a> {
    pub mlr: &'a MlrParams,
    pub nets: NetEnsemble<'a>,
    pub w: f64,
}

impl<'a> Blend<'a> {
    /// The blend of `channel` in a fit file (None without its parts).
    pub fn of(file: &'a ModelFile, channel: &str) -> Option<Self> {
        let mlr = file.mlr.iter().find(|m| m.channel == channel)?;
        let nets = NetEnsemble::of(&file.nets, channel)?;
        let w = *file.blend.get(channel)?;
        Some(Blend { mlr, nets, w })
    }
}

impl Model for Blend<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.mlr.features
    }
    fn channel(&self) -> &str {
        &self.mlr.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.w * self.mlr.predict_norm(xn) + (1.0 - self.w) * self.nets.predict_norm(xn)
    }
}

/// The weight `w ∈ [0, 1]` minimising `Σ (y − w·a − (1−w)·b)²` over the
/// given `(y, a, b)` rows (least squares in one unknown, clamped); 1 (all
/// `a`) when `a` and `b` never differ.
pub fn blend_weight<'a>(rows: impl Iterator<Item = (&'a f64, &'a f64, &'a f64)>) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (y, a, b) in rows {
        let d = a - b;
        num += (y - b) * d;
        den += d * d;
    }
    if den > 0.0 && num.is_finite() {
        (num / den).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Lagged MLR plus a network ensemble on its residual, same inputs.
pub struct Hybrid<'a> {
    pub mlr: &'a MlrParams,
    pub residual: NetEnsemble<'a>,
}

impl<'a> Hybrid<'a> {
    /// The hybrid of `channel` in a fit file (None without its parts).
    pub fn of(file: &'a ModelFile, channel: &str) -> Option<Self> {
        let mlr = file.mlr.iter().find(|m| m.channel == channel)?;
        let residual = NetEnsemble::of(&file.hybrid_nets, channel)?;
        Some(Hybrid { mlr, residual })
    }
}

impl Model for Hybrid<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.mlr.features
    }
    fn channel(&self) -> &str {
        &self.mlr.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.mlr.predict_norm(xn) + self.residual.predict_norm(xn)
    }
}

/// The networks of one channel, averaged: the ensemble that goes on the board.
pub struct NetEnsemble<'a> {
    pub members: Vec<&'a NetParams>,
}

impl<'a> NetEnsemble<'a> {
    /// The members fitted for `channel` (None if there are none).
    pub fn of(nets: &'a [NetParams], channel: &str) -> Option<Self> {
        let members: Vec<&NetParams> = nets.iter().filter(|n| n.channel == channel).collect();
        (!members.is_empty()).then_some(NetEnsemble { members })
    }
}

impl Model for NetEnsemble<'_> {
    fn features(&self) -> &[FeatureSpec] {
        &self.members[0].features
    }
    fn channel(&self) -> &str {
        &self.members[0].channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        let k = self.members.len() as f64;
        self.members.iter().map(|m| m.predict_norm(xn)).sum::<f64>() / k
    }
}

impl FeatureKind {
    pub fn columns(&self) -> Vec<&str> {
        match self {
            FeatureKind::SensorRise(a) => vec![a],
            FeatureKind::SensorDiff(a, b) => vec![a, b],
            FeatureKind::Spindle => vec!["spindle_rpm"],
        }
    }
}

/// Short name: `rise(T_t3)`, `T_t3-T_t5`, `rpm`, with `@<tau>s` for a lag.
pub fn feature_name(kind: &FeatureKind, tau_s: Option<f64>) -> String {
    let base = match kind {
        FeatureKind::SensorRise(a) => a.clone(),
        FeatureKind::SensorDiff(a, b) => format!("{a}-{b}"),
        FeatureKind::Spindle => "rpm".to_string(),
    };
    match tau_s {
        Some(t) => format!("{base}@{t}"),
        None => base,
    }
}

/// Parse `T_t3`, `T_t3@3600`, `T_t3-T_t5@1800`, `rpm@600` (lag in seconds;
/// `@0` means no lag).
pub fn parse_feature(s: &str) -> Result<(FeatureKind, Option<f64>)> {
    let s = s.trim();
    let (base, tau) = match s.split_once('@') {
        Some((b, t)) => {
            let v: f64 =
                t.trim().trim_end_matches('s').parse().with_context(|| {
                    format!("feature `{s}`: lag `{t}` is not a number of seconds")
                })?;
            if !(v >= 0.0 && v.is_finite()) {
                bail!("feature `{s}`: lag must be ≥ 0 s");
            }
            (b.trim(), if v > 0.0 { Some(v) } else { None })
        }
        None => (s, None),
    };
    let kind = if base == "rpm" || base == "spindle_rpm" || base == "spindle" {
        FeatureKind::Spindle
    } else if let Some((a, b)) = base.split_once('-') {
        FeatureKind::SensorDiff(a.trim().to_string(), b.trim().to_string())
    } else if base.is_empty() {
        bail!("empty feature name");
    } else {
        FeatureKind::SensorRise(base.to_string())
    };
    Ok((kind, tau))
}

impl FeatureSpec {
    pub fn name(&self) -> String {
        feature_name(&self.kind, self.tau_s)
    }
    /// Clamp to [min, max] and map to [−1, 1].
    #[inline]
    pub fn normalize(&self, x: f64) -> f64 {
        let span = self.max - self.min;
        if span <= 0.0 {
            return 0.0;
        }
        2.0 * (x.clamp(self.min, self.max) - self.min) / span - 1.0
    }
}

/// A fitted model of one channel: MLR or network.
pub trait Model {
    fn features(&self) -> &[FeatureSpec];
    fn channel(&self) -> &str;
    /// Prediction in µm from normalized inputs.
    fn predict_norm(&self, xn: &[f64]) -> f64;
    /// Prediction in µm from raw (un-normalized) inputs.
    fn predict_raw(&self, x: &[f64]) -> f64 {
        let xn: Vec<f64> = self
            .features()
            .iter()
            .zip(x)
            .map(|(f, &v)| f.normalize(v))
            .collect();
        self.predict_norm(&xn)
    }
}

impl Model for MlrParams {
    fn features(&self) -> &[FeatureSpec] {
        &self.features
    }
    fn channel(&self) -> &str {
        &self.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        self.c0 + self.coef.iter().zip(xn).map(|(c, x)| c * x).sum::<f64>()
    }
}

impl Model for NetParams {
    fn features(&self) -> &[FeatureSpec] {
        &self.features
    }
    fn channel(&self) -> &str {
        &self.channel
    }
    fn predict_norm(&self, xn: &[f64]) -> f64 {
        let mut y = self.b2;
        for j in 0..self.b1.len() {
            let z = self.b1[j] + self.w1[j].iter().zip(xn).map(|(w, x)| w * x).sum::<f64>();
            y += self.w2[j] * net::sigmoid(z);
        }
        y
    }
}

/// One fallback model as `fit --out` writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FallbackParams {
    pub channel: String,
    /// Sensor columns it does without (one, or a pair).
    pub excluded: Vec<String>,
    /// `mlr-static` or `mlr`, chosen by blocked cross-validation.
    pub model: String,
    pub params: MlrParams,
    /// Blocked-CV RMS of the chosen model on the training rows (µm): the
    /// board's priority among fallbacks whose sensors are valid (lowest first).
    #[serde(default)]
    pub cv_rms_um: Option<f64>,
}

/// One channel's evidence, as `tcomp fit --out` stores it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvelopeEvidence {
    /// `hold`, `fallback` or `extrapolate`.
    pub policy: String,
    /// The folds' rows beyond decided it against the physical prior
    /// (`false`: the prior, [`super::envelope`]).
    #[serde(default)]
    pub by_evidence: bool,
    /// Margin judged, raw units (1/16 °C, rpm).
    pub margin_raw: u16,
    /// Forward folds examined, and those with validation rows beyond.
    pub folds: usize,
    pub folds_beyond: usize,
    /// Validation rows of those folds, and the ones beyond the margin.
    pub rows: usize,
    pub rows_beyond: usize,
    /// On the rows beyond: MAE holding the inputs at the edge, and serving
    /// the board's fallback choice (µm).
    pub hold_mae_um: Option<f64>,
    pub fallback_mae_um: Option<f64>,
    /// On the same rows: MAE with a linear chosen model continued past the
    /// edge (None: the model is not linear, or no row beyond).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extrapolate_mae_um: Option<f64>,
    /// Rows beyond where some fallback could serve.
    pub rows_with_fallback: usize,
}

impl EnvelopeEvidence {
    /// One line: which policy and why.
    pub fn why(&self) -> String {
        let k = self.margin_raw;
        let how = if self.by_evidence {
            "by the folds' evidence beyond their noise"
        } else if self.policy == "extrapolate" {
            "the prior for a linear model whose coefficients held across the folds, no policy lower beyond the noise"
        } else {
            "the prior (the model is not linear or its coefficients moved across the folds), no policy lower beyond the noise"
        };
        let text = match (self.hold_mae_um, self.fallback_mae_um) {
            (Some(h), Some(f)) => format!(
                "{}: on the {} of {} training rows of {} forward fold(s) beyond the earlier blocks' range by > {k}/16 K, holding at the edge {h:.2} µm MAE, the fallback {f:.2} µm ({} rows had one){}",
                self.policy,
                self.rows_beyond,
                self.rows,
                self.folds_beyond,
                self.rows_with_fallback,
                self.extrapolate_mae_um
                    .map_or(String::new(), |e| format!(", continuing the linear model {e:.2} µm"))
            ),
            _ => format!(
                "{}: no training row of the {} forward fold(s) leaves the earlier blocks' range by > {k}/16 K",
                self.policy, self.folds
            ),
        };
        format!("{text}; {how}")
    }
}

//! The envelope policy's evidence (issue 50 item 3): per channel, whether
//! the board should serve from the fallback without an input that has left
//! its training range (`fallback`), hold that input at the range's edge
//! (`hold`, the rule before the policy existed), or let a linear model
//! continue beyond the range (`extrapolate`, up to
//! [`EXTRAPOLATE_WIDTHS`] training widths past each edge, as the board).
//!
//! The evidence comes from the training rows alone, forward in time: the
//! training rows are cut into the fit's time blocks, and each of the later
//! forward-chaining folds ([`super::ridge::forward_folds`]: fit on the
//! blocks before, validate on the next) refits the channel's chosen inputs
//! and each of its fallbacks (least squares on the fold's fit rows, their
//! ranges the fold's envelope). On the validation rows whose inputs leave
//! the fit rows' range by more than [`DEFAULT_MARGIN_RAW`], it compares the
//! absolute error of holding those inputs at the edge with the board's
//! fallback choice there (the first fallback in the board's priority order
//! that reads none of the sensors beyond; none: held as well) and, for a
//! linear chosen model (`mlr`, `mlr-static`, `ridge`: the board extrapolates
//! only tables of degree 1), with the refitted model continued past the
//! edge. The physical prior decides unless the folds say otherwise beyond
//! their noise ([`decisive`]: one witness per fold, all agreeing):
//! a linear model whose coefficients held across the CV folds continues,
//! anything else is held. Why a third policy, and why the prior: thermal expansion is linear
//! in temperature, so a linear model held at the edge freezes its
//! correction while the machine keeps moving (a blind world measured the
//! hold as most of the loss beyond the envelope); what the hold guards
//! against (a collinear pair of inputs amplifying a small excursion) shows
//! in these folds as a larger extrapolation error, and then `hold` wins. The chosen model is refitted as a linear model on its own inputs
//! (exact for `mlr` and `mlr-static`; for `ridge`, networks and blends a
//! linear stand-in on the same inputs: the folds judge extrapolation, not
//! the fit; a `ridge` is refitted as a ridge with its chosen penalty).

use std::collections::BTreeMap;

use anyhow::Result;
use tcomp_data::runcsv::Run;

use super::greedy::blocked_folds;
use super::mlr::fit_mlr;
use super::model::{
    EnvelopeEvidence, FallbackParams, FeatureKind, FeatureSpec, MlrParams, Model, ModelFile,
};
use super::ridge::{all_blocks, fit_ridge, forward_folds};
use super::samples::{ranged_specs, SeriesCache};
use super::split::Segment;

/// Training widths past each edge a linear model continues on the board
/// before it is held (the core's bound; the fit judges the same function).
pub const EXTRAPOLATE_WIDTHS: f64 = thermocomp_core::limits::EXTRAPOLATE_WIDTHS as f64;

/// The margin the fit judges and `tcomp export` writes, raw units of each
/// input: 8/16 °C = 0.5 K for temperatures (8 rpm for the spindle speed).
pub const DEFAULT_MARGIN_RAW: u16 = 8;
/// Time blocks the training rows are cut into (the fit's default).
const BLOCKS: usize = 5;

/// The chosen model's inputs for `ch` (none for `none`).
fn chosen_features<'a>(file: &'a ModelFile, ch: &str) -> Option<&'a [FeatureSpec]> {
    let pick = |v: &'a [MlrParams]| v.iter().find(|m| m.channel == ch);
    let feats = match file.chosen.get(ch).map(String::as_str) {
        Some("none") => return None,
        Some("mlr-static") => &pick(&file.mlr_static)?.features,
        Some("ridge") => &pick(&file.ridge)?.features,
        Some("ga-bpn") => &file.nets.iter().find(|n| n.channel == ch)?.features,
        _ => &pick(&file.mlr)?.features,
    };
    Some(feats)
}

/// The channel's fallbacks in the board's priority order (lowest CV RMS
/// first, singles before pairs: `export`'s order).
fn fallbacks_of<'a>(file: &'a ModelFile, ch: &str) -> Vec<&'a FallbackParams> {
    let mut v: Vec<&FallbackParams> = file.fallbacks.iter().filter(|f| f.channel == ch).collect();
    v.sort_by(|a, b| {
        let key = |f: &FallbackParams| (f.cv_rms_um.unwrap_or(f64::INFINITY), f.excluded.len());
        let (ka, kb) = (key(a), key(b));
        ka.0.total_cmp(&kb.0).then(ka.1.cmp(&kb.1))
    });
    v
}

type Kind = (FeatureKind, Option<f64>);

fn kind_of(f: &FeatureSpec) -> Kind {
    (f.kind.clone(), f.tau_s)
}

/// The margin in an input's unit (°C or rpm).
fn margin_in(kind: &FeatureKind, margin_raw: u16) -> f64 {
    match kind {
        FeatureKind::Spindle => f64::from(margin_raw),
        _ => f64::from(margin_raw) / 16.0,
    }
}

/// Evidence per fitted channel. `runs` are the fit's runs (errors as
/// rises, as the fit read them), `train` its training segments.
/// `chosen`: per channel, what the choice knew of the chosen model (its
/// coefficients' stability across the CV folds, a ridge's penalty).
pub fn evidence(
    runs: &[Run],
    train: &[Segment],
    file: &ModelFile,
    margin_raw: u16,
    chosen: &BTreeMap<String, ChosenInfo>,
) -> Result<BTreeMap<String, EnvelopeEvidence>> {
    let blocks = all_blocks(&blocked_folds(runs, train, BLOCKS));
    let folds = forward_folds(&blocks);
    let mut out = BTreeMap::new();
    for ch in file.chosen.keys() {
        let Some(main) = chosen_features(file, ch) else {
            continue;
        };
        let linear = matches!(
            file.chosen.get(ch).map(String::as_str),
            Some("mlr" | "mlr-static" | "ridge")
        );
        let fbs = fallbacks_of(file, ch);
        let mut kinds: Vec<Kind> = main.iter().map(kind_of).collect();
        for f in fbs.iter().flat_map(|f| &f.params.features) {
            if !kinds.contains(&kind_of(f)) {
                kinds.push(kind_of(f));
            }
        }
        let cache = SeriesCache::new(runs, kinds.clone())?;
        let idx_of = |fs: &[FeatureSpec]| -> Vec<usize> {
            fs.iter()
                .filter_map(|f| kinds.iter().position(|k| *k == kind_of(f)))
                .collect()
        };
        let main_idx = idx_of(main);
        let fb_idx: Vec<Vec<usize>> = fbs.iter().map(|f| idx_of(&f.params.features)).collect();
        let mut ev = Tally {
            linear,
            stable: chosen.get(ch).is_some_and(|c| c.stable),
            ridge_penalty: chosen.get(ch).and_then(|c| c.ridge_penalty),
            ..Tally::default()
        };
        for (fit, val) in &folds {
            ev.fold(
                &cache,
                runs,
                (fit, val),
                ch,
                (&main_idx, &fb_idx),
                margin_raw,
            )?;
        }
        out.insert(ch.clone(), ev.finish(folds.len(), margin_raw));
    }
    Ok(out)
}

#[derive(Default)]
struct Tally {
    folds_beyond: usize,
    rows: usize,
    rows_beyond: usize,
    rows_with_fallback: usize,
    /// Per row beyond, in fold and time order: the absolute error holding,
    /// serving the fallback choice, and continuing the model.
    hold: Vec<f64>,
    fallback: Vec<f64>,
    extrapolate: Vec<f64>,
    /// Per row beyond, its fold (index among the folds with rows beyond)
    /// and time (s), for [`decisive`].
    fold_of: Vec<usize>,
    time_s: Vec<f64>,
    /// The chosen model is linear (the board may extrapolate it) and its
    /// coefficients held across the folds.
    linear: bool,
    stable: bool,
    /// The chosen ridge's penalty: the folds refit the main model with it.
    ridge_penalty: Option<f64>,
}

/// What the choice knew of a channel's chosen model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChosenInfo {
    /// Its coefficients held across the CV folds ([`super::stability`]).
    pub stable: bool,
    /// For `ridge`, its penalty (the folds refit the ridge itself, not a
    /// least-squares stand-in).
    pub ridge_penalty: Option<f64>,
}

/// A fold's rows beyond must span this long to be a witness (the lag
/// rule's anchor window, one hour): minutes of rows are one observation.
const WITNESS_S: f64 = super::lags::ANCHOR_S;
/// Witness folds needed before the evidence may decide.
const MIN_WITNESSES: usize = 2;

/// Whether errors `a` are lower than `b` (paired rows beyond, `fold` and
/// `time` per row) beyond the noise. Each fold is one witness (its rows
/// share one refitted model, so they are not independent): its mean of
/// `b − a`. At least [`MIN_WITNESSES`] folds whose rows span
/// [`WITNESS_S`], every one of them lower, and their mean beyond `NOISE_Z`
/// standard errors (the per-input lag rule's level).
fn decisive(a: &[f64], b: &[f64], (fold, time): (&[usize], &[f64])) -> bool {
    let k = fold.last().map_or(0, |&l| l + 1);
    let mut means = Vec::new();
    for f in 0..k {
        let rows: Vec<usize> = (0..fold.len()).filter(|&i| fold[i] == f).collect();
        let span = |r: &[usize]| -> f64 {
            let ts = r.iter().map(|&i| time[i]);
            ts.clone().fold(f64::MIN, f64::max) - ts.fold(f64::MAX, f64::min)
        };
        if rows.is_empty() || span(&rows) < WITNESS_S {
            continue;
        }
        means.push(rows.iter().map(|&i| b[i] - a[i]).sum::<f64>() / rows.len() as f64);
    }
    let n = means.len();
    if n < MIN_WITNESSES || means.iter().any(|&d| d <= 0.0) {
        return false;
    }
    let m = means.iter().sum::<f64>() / n as f64;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64;
    m > super::lags::NOISE_Z * (var / n as f64).sqrt()
}

/// A linear model's prediction with its inputs clamped to
/// [min − W·span, max + W·span] instead of [min, max] (the board's
/// `extrapolate` policy, W = [`EXTRAPOLATE_WIDTHS`]).
fn predict_extrapolated(m: &MlrParams, x: &[f64]) -> f64 {
    let terms = m.features.iter().zip(x).zip(&m.coef).map(|((f, &v), c)| {
        let span = f.max - f.min;
        if span <= 0.0 {
            return 0.0;
        }
        let w = EXTRAPOLATE_WIDTHS * span;
        c * (2.0 * (v.clamp(f.min - w, f.max + w) - f.min) / span - 1.0)
    });
    m.c0 + terms.sum::<f64>()
}

impl Tally {
    /// One forward fold: refit on `fit`, score the rows of `val` beyond.
    fn fold(
        &mut self,
        cache: &SeriesCache,
        runs: &[Run],
        (fit, val): (&[Segment], &[Segment]),
        ch: &str,
        (main_idx, fb_idx): (&[usize], &[Vec<usize>]),
        margin_raw: u16,
    ) -> Result<()> {
        let refit = |idx: &[usize], penalty: Option<f64>| -> Result<Option<MlrParams>> {
            let tr = cache.samples(runs, fit, idx, ch)?;
            if tr.y.len() < 2 * idx.len() + 2 {
                return Ok(None);
            }
            let kinds: Vec<Kind> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
            let specs = ranged_specs(&kinds, &tr);
            match penalty {
                Some(l) => fit_ridge(specs, &tr, l, ch).map(Some),
                None => fit_mlr(specs, &tr, ch).map(Some),
            }
        };
        let Some(main) = refit(main_idx, self.ridge_penalty)? else {
            return Ok(());
        };
        let fbs: Vec<Option<MlrParams>> = fb_idx
            .iter()
            .map(|i| refit(i, None))
            .collect::<Result<_>>()?;
        let va = cache.samples(runs, val, main_idx, ch)?;
        let mut any = false;
        for (x, (&y, &(run, r))) in va.x.iter().zip(va.y.iter().zip(&va.rows)) {
            self.rows += 1;
            let beyond: Vec<&FeatureSpec> = main
                .features
                .iter()
                .zip(x)
                .filter(|(f, &v)| {
                    let m = margin_in(&f.kind, margin_raw);
                    v < f.min - m || v > f.max + m
                })
                .map(|(f, _)| f)
                .collect();
            if beyond.is_empty() {
                continue;
            }
            any = true;
            self.rows_beyond += 1;
            self.fold_of.push(self.folds_beyond);
            self.time_s.push(runs[run].time_at(r));
            let hold = (y - main.predict_raw(x)).abs();
            self.hold.push(hold);
            self.extrapolate
                .push((y - predict_extrapolated(&main, x)).abs());
            // As the board: the sensors beyond count as faulted; a spindle
            // input beyond rules out that input itself.
            let affected = |f: &FeatureSpec| {
                beyond.iter().any(|b| {
                    (b.kind == FeatureKind::Spindle && kind_of(b) == kind_of(f))
                        || b.kind
                            .columns()
                            .iter()
                            .any(|c| *c != "spindle_rpm" && f.kind.columns().contains(c))
                })
            };
            let served = fbs.iter().zip(fb_idx).find_map(|(m, idx)| {
                let m = m.as_ref()?;
                if m.features.iter().any(affected) {
                    return None;
                }
                let xf: Option<Vec<f64>> = idx
                    .iter()
                    .map(|&i| Some(cache.series[i][run][r]).filter(|v| v.is_finite()))
                    .collect();
                Some((y - m.predict_raw(&xf?)).abs())
            });
            if served.is_some() {
                self.rows_with_fallback += 1;
            }
            self.fallback.push(served.unwrap_or(hold));
        }
        self.folds_beyond += usize::from(any);
        Ok(())
    }

    /// The policy: the physical prior (a linear model whose coefficients
    /// held across the folds continues past the edge, as thermal expansion
    /// does; anything else is held), unless the folds' rows beyond show
    /// another policy lower than the prior's beyond their noise
    /// ([`decisive`]): thin or noisy evidence does not decide.
    fn finish(self, folds: usize, margin_raw: u16) -> EnvelopeEvidence {
        let n = self.hold.len() as f64;
        let mae = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / n);
        let (hold, fallback) = (mae(&self.hold), mae(&self.fallback));
        let extrapolate = mae(&self.extrapolate).filter(|_| self.linear);
        let prior = if self.linear && self.stable {
            "extrapolate"
        } else {
            "hold"
        };
        let errors = |p: &str| match p {
            "extrapolate" => &self.extrapolate,
            "fallback" => &self.fallback,
            _ => &self.hold,
        };
        let candidates = [
            ("hold", hold),
            ("fallback", fallback),
            ("extrapolate", extrapolate),
        ];
        let best = candidates
            .iter()
            .filter_map(|&(p, m)| Some((p, m?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let (policy, by_evidence) = match best {
            Some((p, _))
                if p != prior
                    && decisive(errors(p), errors(prior), (&self.fold_of, &self.time_s)) =>
            {
                (p, true)
            }
            _ => (prior, false),
        };
        EnvelopeEvidence {
            policy: policy.into(),
            by_evidence,
            margin_raw,
            folds,
            folds_beyond: self.folds_beyond,
            rows: self.rows,
            rows_beyond: self.rows_beyond,
            hold_mae_um: hold,
            fallback_mae_um: fallback,
            extrapolate_mae_um: extrapolate,
            rows_with_fallback: self.rows_with_fallback,
        }
    }
}

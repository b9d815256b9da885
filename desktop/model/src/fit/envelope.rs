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
//! edge. The policy with the lowest error wins; `hold` on a tie or when no
//! fold leaves the range (the conservative rule: nothing past the range
//! without evidence for it). Why a third policy: thermal expansion is linear
//! in temperature, so a linear model held at the edge freezes its
//! correction while the machine keeps moving (a blind world measured the
//! hold as most of the loss beyond the envelope); what the hold guards
//! against (a collinear pair of inputs amplifying a small excursion) shows
//! in these folds as a larger extrapolation error, and then `hold` wins. The chosen model is refitted as a linear model on its own inputs
//! (exact for `mlr` and `mlr-static`; for `ridge`, networks and blends a
//! linear stand-in on the same inputs: the folds judge extrapolation, not
//! the fit).

use std::collections::BTreeMap;

use anyhow::Result;
use tcomp_data::runcsv::Run;

use super::greedy::blocked_folds;
use super::mlr::fit_mlr;
use super::model::{
    EnvelopeEvidence, FallbackParams, FeatureKind, FeatureSpec, MlrParams, Model, ModelFile,
};
use super::ridge::{all_blocks, forward_folds};
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
pub fn evidence(
    runs: &[Run],
    train: &[Segment],
    file: &ModelFile,
    margin_raw: u16,
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
    hold: f64,
    fallback: f64,
    /// The chosen model is linear (the board may extrapolate it).
    linear: bool,
    extrapolate: f64,
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
        let refit = |idx: &[usize]| -> Result<Option<MlrParams>> {
            let tr = cache.samples(runs, fit, idx, ch)?;
            if tr.y.len() < 2 * idx.len() + 2 {
                return Ok(None);
            }
            let kinds: Vec<Kind> = idx.iter().map(|&i| cache.kinds[i].clone()).collect();
            fit_mlr(ranged_specs(&kinds, &tr), &tr, ch).map(Some)
        };
        let Some(main) = refit(main_idx)? else {
            return Ok(());
        };
        let fbs: Vec<Option<MlrParams>> = fb_idx.iter().map(|i| refit(i)).collect::<Result<_>>()?;
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
            let hold = (y - main.predict_raw(x)).abs();
            self.hold += hold;
            self.extrapolate += (y - predict_extrapolated(&main, x)).abs();
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
            self.fallback += served.unwrap_or(hold);
        }
        self.folds_beyond += usize::from(any);
        Ok(())
    }

    fn finish(self, folds: usize, margin_raw: u16) -> EnvelopeEvidence {
        let n = self.rows_beyond as f64;
        let mae = |s: f64| (self.rows_beyond > 0).then(|| s / n);
        let (hold, fallback) = (mae(self.hold), mae(self.fallback));
        let extrapolate = mae(self.extrapolate).filter(|_| self.linear);
        let mut policy = "hold";
        if let Some(h) = hold {
            let f = fallback.unwrap_or(f64::INFINITY);
            let e = extrapolate.unwrap_or(f64::INFINITY);
            if f < h && f <= e {
                policy = "fallback";
            } else if e < h && e < f {
                policy = "extrapolate";
            }
        }
        EnvelopeEvidence {
            policy: policy.into(),
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

//! `tcomp replay --reference-every 1h` / `--reference-at T` (issue 28): the
//! board's served correction with probe references at a gauge and operator
//! re-zeros, by the math core's own update rule
//! ([`thermocomp_core::reference`]), bit-exact with the board.
//!
//! The board's loop per sample: the compensator steps (the replay rows,
//! [`crate::replay`]); when a reference is due, the probe reading at the
//! gauge is compared with the compensator's served correction at that
//! moment and the direction's [`ReferenceState`] is updated; when a re-zero
//! is due the state takes it; the served value is
//! [`ReferenceState::serve`]. The terms never feed back into the
//! compensator (they are added after it), so running the core's update over
//! the replay rows in time order is the board's loop exactly.
//!
//! **When the board asks** (`--reference-when-asked`, issue 51): the
//! schedule is the board's own rule ([`thermocomp_core::ask`], the very
//! code): per direction, an [`AskState`] looks at every row's time and the
//! run's `spindle_rpm` (what the PLC writes; a run without the column
//! gives the interval rule only); a request raised at a row is probed by
//! the simulated PLC at the next row with a measured value (latency: one
//! sample, the PLC polls between two cycles); only an accepted reference
//! clears it, so after a refused one the next row probes again. Each
//! direction is replayed as if it were the probe's direction (holding
//! register 40), with its own request state.
//!
//! Simulated readings: the run's measured error channel at that row (as a
//! rise from the run's start, the model's frame) plus seeded Gaussian noise,
//! rounded to 0.1 µm; a share of them corrupted by a fixed offset (a chip on
//! the gauge). The noise of each reference does not depend on the outlier
//! draw, so a corrupted run differs from the clean one only in the
//! corrupted readings.

use anyhow::{anyhow, bail, Result};
use thermocomp_core::ask::{AskParams, AskReason, AskState};
use thermocomp_core::reference::{ReferenceOutcome, ReferenceParams, ReferenceState};
use thermocomp_core::Model;

use crate::reference_args::parse_time_ms;
pub use crate::reference_args::{
    ask_params, parse_duration_s, parse_outliers, parse_params, ReferenceArgs,
};
use crate::replay::ReplayRow;
use tcomp_data::runcsv::Run;
use tcomp_numerics::rng::Rng;

/// One direction's figures over the scored block.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ChannelReference {
    pub column: String,
    pub rows: usize,
    /// With references (and re-zeros): residual = measured − served.
    pub mae_um: f64,
    pub rms_um: f64,
    pub peak_um: f64,
    /// The model alone (re-zeros applied, no references).
    pub mae_without_um: f64,
    pub rms_without_um: f64,
    /// The measured error itself (about the last re-zero, if any): no compensation.
    pub raw_mae_um: f64,
    pub raw_rms_um: f64,
    /// References taken over the whole run, in the scored block, accepted, refused.
    pub references: usize,
    pub references_in_block: usize,
    pub accepted: usize,
    pub refused: usize,
    /// Corrupted references, and how many of them were refused.
    pub corrupted: usize,
    pub corrupted_refused: usize,
    /// Clean references refused by the gate.
    pub clean_refused: usize,
    /// When the board asks: the requests it raised, by reason (a refused
    /// reference leaves a request raised: one request, several readings).
    pub asked_speed_change: usize,
    pub asked_interval: usize,
    /// Every reference taken, in time order (`references` of them).
    pub taken: Vec<TakenReference>,
    /// RMS with references ≤ RMS of the model alone.
    pub never_worse_than_model: bool,
    /// RMS with references ≤ RMS of the raw error.
    pub never_worse_than_raw: bool,
    /// The final state as the board would store it (hex).
    pub final_state: String,
    /// Fingerprint of every served integer (FNV-1a), for bit-exactness checks.
    pub served_hash: String,
}

/// One reference taken (the `taken` list of `--json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct TakenReference {
    /// The row's time (s) and index.
    pub time_s: f64,
    pub row: usize,
    /// The gate accepted it.
    pub accepted: bool,
    /// A simulated chip on the gauge.
    pub corrupted: bool,
    /// When the board asks: why (`speed_change`, `interval`) and when it
    /// raised the request (s).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub asked_s: Option<f64>,
}

/// `--reference-when-asked` in `--json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct WhenAskedJson {
    pub settle_s: u16,
    pub max_interval_s: u16,
    pub speed_step_rpm: u16,
    /// Rows from the request to the probe: the next sample.
    pub latency_rows: usize,
    /// The run has `spindle_rpm` (else: the interval rule only).
    pub spindle_rpm: bool,
}

/// What `--json` reports under `"references"`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ReferenceReport {
    pub every_s: Option<f64>,
    /// The clock schedule's shift (`--reference-phase`), s.
    pub phase_s: f64,
    pub after_change_s: Option<f64>,
    /// The board's asking rule, when it asks (`--reference-when-asked`).
    pub when_asked: Option<WhenAskedJson>,
    pub noise_um: f64,
    pub outliers: Option<(f64, f64)>,
    pub seed: u64,
    pub rezero_ms: Vec<u64>,
    pub params: ParamsJson,
    pub channels: Vec<ChannelReference>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct ParamsJson {
    pub sigma_ref_um: f64,
    pub sigma_bias_um: f64,
    pub tau_bias_h: f64,
    pub sigma_rate_um_h: f64,
    pub tau_rate_h: f64,
    pub gate_k: f64,
    pub gate_abs_um: f64,
    pub max_step_um: f64,
    pub max_bias_um: f64,
    pub max_rate_um_h: f64,
}

impl From<&ReferenceParams> for ParamsJson {
    fn from(p: &ReferenceParams) -> Self {
        let um = |v: u32| f64::from(v) / 1000.0;
        ParamsJson {
            sigma_ref_um: um(p.sigma_ref_nm),
            sigma_bias_um: um(p.sigma_bias_nm),
            tau_bias_h: f64::from(p.tau_bias_s) / 3600.0,
            sigma_rate_um_h: um(p.sigma_rate_nm_h),
            tau_rate_h: f64::from(p.tau_rate_s) / 3600.0,
            gate_k: f64::from(p.gate_k_x10) / 10.0,
            gate_abs_um: um(p.gate_abs_nm),
            max_step_um: um(p.max_step_nm),
            max_bias_um: um(p.max_bias_nm),
            max_rate_um_h: um(p.max_rate_nm_h),
        }
    }
}

/// One simulated reference of one direction.
#[derive(Debug, Clone, Copy)]
pub struct SimReference {
    pub row: usize,
    pub reading: i32,
    pub corrupted: bool,
}

/// Times (s) at which a reference is due: phase + k·every (k ≥ 0, after
/// the run's first time) from the run's first time — phase 0: k·every,
/// k ≥ 1 — and, with `after_change`, that long after every change of
/// `spindle_rpm`; sorted, duplicates once.
pub fn due_times(
    run: &Run,
    every_s: Option<f64>,
    phase_s: f64,
    after_change_s: Option<f64>,
) -> Vec<f64> {
    let time = run.time_s();
    let (Some(&t0), Some(&t_end)) = (time.first(), time.last()) else {
        return vec![];
    };
    let mut due = vec![];
    if let Some(e) = every_s {
        let mut k = 0u64;
        while t0 + phase_s + e * k as f64 <= t_end {
            let t = t0 + phase_s + e * k as f64;
            if t > t0 {
                due.push(t);
            }
            k += 1;
        }
    }
    if let (Some(d), Some(rpm)) = (after_change_s, run.col("spindle_rpm")) {
        for (i, w) in rpm.windows(2).enumerate() {
            if let [Some(a), Some(b)] = w {
                if a != b && time[i + 1] + d <= t_end {
                    due.push(time[i + 1] + d);
                }
            }
        }
    }
    due.sort_by(f64::total_cmp);
    due.dedup();
    due
}

/// The simulated references per direction at the `due` times (s), on the
/// first row at or after each that has a measured value.
pub fn simulate_references(
    run: &Run,
    model: &Model,
    due: &[f64],
    noise_um: f64,
    outliers: Option<(f64, f64)>,
    seed: u64,
) -> Vec<Vec<SimReference>> {
    let time = run.time_s();
    let mut noise = Rng::new(seed);
    let mut corrupt = Rng::new(seed ^ 0x9E37_79B9_7F4A_7C15);
    let mut out = vec![vec![]; model.directions.len()];
    let mut row = 0usize;
    for &due in due {
        while row < time.len() && time[row] < due {
            row += 1;
        }
        if row >= time.len() {
            break;
        }
        for (d, refs) in out.iter_mut().enumerate() {
            // Draw for every direction and instant, used or not: the
            // sequence does not depend on which channels a run has.
            let n = noise.normal() * noise_um;
            let (share, off) = outliers.unwrap_or((0.0, 0.0));
            let bad = corrupt.uniform() < share;
            let column = format!("d{}_um", model.direction_name(d));
            let Some(Some(m)) = run.col(&column).and_then(|c| c.get(row)) else {
                continue;
            };
            // Two due times on one row: one reference.
            if refs.last().is_some_and(|r: &SimReference| r.row == row) {
                continue;
            }
            let v = m + n + if bad { off } else { 0.0 };
            refs.push(SimReference {
                row,
                reading: (v * 10.0)
                    .round()
                    .clamp(f64::from(i32::MIN), f64::from(i32::MAX))
                    as i32,
                corrupted: bad,
            });
        }
    }
    out
}

/// A reference the board asked for: the reading, why it was asked and
/// when (ms, the run's clock).
#[derive(Debug, Clone, Copy)]
pub struct AskedReference {
    pub sim: SimReference,
    pub reason: AskReason,
    pub asked_ms: u64,
}

/// The references of direction `d` when the board asks
/// ([`thermocomp_core::ask`]): the rule looks at every row (time, the
/// run's `spindle_rpm`); the simulated PLC probes at the next row with a
/// measured value (one sample of latency); the reference rule decides
/// ([`ReferenceState::reference`], as in [`serve_direction`], re-zeros
/// included) and only an accepted reading clears the request. Returns the
/// readings and the number of requests raised per reason (speed change,
/// interval). Noise and corruption: streams of their own per direction
/// from `seed` (direction 0 draws as the clock schedule's first direction).
#[allow(clippy::too_many_arguments)]
pub fn simulate_when_asked(
    run: &Run,
    rows: &[ReplayRow],
    model: &Model,
    d: usize,
    ask: &AskParams,
    params: &ReferenceParams,
    reading: (f64, Option<(f64, f64)>, u64),
    rezero_rows: &[usize],
) -> (Vec<AskedReference>, [usize; 2]) {
    let (noise_um, outliers, seed) = reading;
    let mut out = vec![];
    let mut asked = [0usize; 2];
    let column = format!("d{}_um", model.direction_name(d));
    let (Some(measured), Some(first)) = (run.col(&column), rows.first()) else {
        return (out, asked);
    };
    let rpm = run.col("spindle_rpm");
    let mix = (d as u64).wrapping_mul(0xA24B_AED4_963E_E407);
    let mut noise = Rng::new(seed ^ mix);
    let mut corrupt = Rng::new(seed ^ 0x9E37_79B9_7F4A_7C15 ^ mix);
    let (share, off) = outliers.unwrap_or((0.0, 0.0));
    let mut state = AskState::new(first.time_ms);
    let mut st = ReferenceState::new(params);
    let mut asked_ms = first.time_ms;
    for (i, r) in rows.iter().enumerate() {
        let m = r.out.corrections[d];
        // The PLC saw the request between the last cycle and this one.
        if state.wanted() != AskReason::None {
            if let Some(Some(y)) = measured.get(i) {
                let bad = corrupt.uniform() < share;
                let v = y + noise.normal() * noise_um + if bad { off } else { 0.0 };
                let reading = (v * 10.0)
                    .round()
                    .clamp(f64::from(i32::MIN), f64::from(i32::MAX))
                    as i32;
                let o = st.reference(params, r.time_ms, m, reading);
                out.push(AskedReference {
                    sim: SimReference {
                        row: i,
                        reading,
                        corrupted: bad,
                    },
                    reason: state.wanted(),
                    asked_ms,
                });
                if matches!(o, ReferenceOutcome::Accepted { .. }) {
                    state.referenced(ask, r.time_ms);
                }
            }
        }
        if rezero_rows.contains(&i) {
            st.rezero(params, r.time_ms, m);
        }
        let speed = rpm
            .and_then(|c| c.get(i).copied().flatten())
            .filter(|v| v.is_finite())
            .map(|v| v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32);
        if state.step(ask, r.time_ms, speed) {
            asked_ms = r.time_ms;
            match state.wanted() {
                AskReason::SpeedChange => asked[0] += 1,
                AskReason::Interval => asked[1] += 1,
                AskReason::None => {}
            }
        }
    }
    (out, asked)
}

/// The board's loop for one direction: served correction per row (0.1 µm)
/// with the given references and re-zero rows, and the final state.
pub fn serve_direction(
    rows: &[ReplayRow],
    d: usize,
    max_correction: i32,
    params: &ReferenceParams,
    refs: &[SimReference],
    rezero_rows: &[usize],
) -> (Vec<i32>, ReferenceState, Vec<ReferenceOutcome>) {
    let mut st = ReferenceState::new(params);
    let mut served = Vec::with_capacity(rows.len());
    let mut outcomes = vec![];
    let mut next = 0usize;
    for (i, r) in rows.iter().enumerate() {
        let m = r.out.corrections[d];
        while next < refs.len() && refs[next].row == i {
            outcomes.push(st.reference(params, r.time_ms, m, refs[next].reading));
            next += 1;
        }
        if rezero_rows.contains(&i) {
            st.rezero(params, r.time_ms, m);
        }
        served.push(st.serve(params, r.time_ms, m, max_correction));
    }
    (served, st, outcomes)
}

fn fnv(v: &[i32]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for x in v {
        for b in x.to_le_bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
    h
}

fn stats(v: &[f64]) -> (f64, f64, f64) {
    let n = v.len().max(1) as f64;
    (
        v.iter().map(|x| x.abs()).sum::<f64>() / n,
        (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        v.iter().fold(0.0f64, |a, x| a.max(x.abs())),
    )
}

/// Replay references and re-zeros over the compensator's rows and score
/// rows `[from, to)`.
pub fn score(
    run: &Run,
    rows: &[ReplayRow],
    model: &Model,
    args: &ReferenceArgs,
    from: usize,
    to: usize,
) -> Result<ReferenceReport> {
    let params = parse_params(args)?;
    let outliers = args.outliers.as_deref().map(parse_outliers).transpose()?;
    let every_s = args.every.as_deref().map(parse_duration_s).transpose()?;
    if !(args.noise_um >= 0.0 && args.noise_um.is_finite()) {
        bail!("--reference-noise-um must be 0 or more");
    }
    let time = run.time_s();
    let mut rezero_ms = args
        .rezero_at
        .iter()
        .map(|s| parse_time_ms(s, &time))
        .collect::<Result<Vec<_>>>()?;
    rezero_ms.sort_unstable();
    let rezero_rows: Vec<usize> = rezero_ms
        .iter()
        .filter_map(|&t| rows.iter().position(|r| r.time_ms >= t))
        .collect();
    let after_s = args
        .after_change
        .as_deref()
        .map(parse_duration_s)
        .transpose()?;
    if after_s.is_some() && run.col("spindle_rpm").is_none() {
        bail!("--reference-after-change: the run has no spindle_rpm column");
    }
    let phase_s = match args.phase.as_deref().map(str::trim) {
        None | Some("0") => 0.0,
        Some(p) => {
            let Some(e) = every_s else {
                bail!("--reference-phase needs --reference-every (the clock schedule it shifts)");
            };
            let v = parse_duration_s(p).map_err(|e| anyhow!("--reference-phase {e}"))?;
            if v >= e {
                bail!("--reference-phase {p}: must be below the interval --reference-every ({e:.0} s)");
            }
            v
        }
    };
    if args.when_asked.is_some() && (every_s.is_some() || after_s.is_some()) {
        bail!("--reference-when-asked: the board's schedule, not with --reference-every or --reference-after-change");
    }
    let dirs = model.directions.len();
    // Per direction: the readings; when the board asks, why and when each
    // was asked, and the requests raised per reason.
    let (refs, why, asked) = match &args.when_asked {
        None => {
            let due = due_times(run, every_s, phase_s, after_s);
            let refs = simulate_references(run, model, &due, args.noise_um, outliers, args.seed);
            (refs, vec![vec![]; dirs], vec![[0usize; 2]; dirs])
        }
        Some(ask) => {
            let mut refs = Vec::with_capacity(dirs);
            let mut why = Vec::with_capacity(dirs);
            let mut asked = Vec::with_capacity(dirs);
            for d in 0..dirs {
                let (r, a) = simulate_when_asked(
                    run,
                    rows,
                    model,
                    d,
                    ask,
                    &params,
                    (args.noise_um, outliers, args.seed),
                    &rezero_rows,
                );
                refs.push(r.iter().map(|r| r.sim).collect::<Vec<_>>());
                why.push(r.iter().map(|r| (r.reason, r.asked_ms)).collect::<Vec<_>>());
                asked.push(a);
            }
            (refs, why, asked)
        }
    };
    let mut channels = vec![];
    let mut dump: Vec<DumpColumn> = vec![];
    let scoring = Scoring {
        rows,
        params: &params,
        rezero_rows: &rezero_rows,
        block: (from, to),
    };
    for (d, dir) in model.directions.iter().enumerate() {
        let column = format!("d{}_um", model.direction_name(d));
        let Some(measured) = run.col(&column) else {
            continue;
        };
        let dumped = args.dump.is_some().then_some(&mut dump);
        let planned = (&refs[d][..], &why[d][..], asked[d]);
        if let Some(c) = scoring.channel(d, dir.max_correction, column, measured, planned, dumped) {
            channels.push(c);
        }
    }
    if let Some(path) = &args.dump {
        write_dump(path, run, rows, model, &dump)?;
    }
    Ok(ReferenceReport {
        every_s,
        phase_s,
        after_change_s: after_s,
        when_asked: args.when_asked.map(|a| WhenAskedJson {
            settle_s: a.settle_s,
            max_interval_s: a.max_interval_s,
            speed_step_rpm: a.speed_step_rpm,
            latency_rows: 1,
            spindle_rpm: run.col("spindle_rpm").is_some(),
        }),
        noise_um: args.noise_um,
        outliers,
        seed: args.seed,
        rezero_ms,
        params: ParamsJson::from(&params),
        channels,
    })
}

/// What scoring a direction needs beside its own readings: the replay rows,
/// the rule's parameters, the re-zero rows and the scored block.
struct Scoring<'a> {
    rows: &'a [ReplayRow],
    params: &'a ReferenceParams,
    rezero_rows: &'a [usize],
    block: (usize, usize),
}

impl Scoring<'_> {
    /// Direction `d`'s figures against its measured `column`, with its
    /// readings, why each was asked and the requests per reason (`planned`);
    /// its served values go to `dump` when asked. `None`: no measured row
    /// in the block.
    fn channel(
        &self,
        d: usize,
        max_correction: i32,
        column: String,
        measured: &[Option<f64>],
        planned: (&[SimReference], &[(AskReason, u64)], [usize; 2]),
        dump: Option<&mut Vec<DumpColumn>>,
    ) -> Option<ChannelReference> {
        let (rows, params, rezero_rows) = (self.rows, self.params, self.rezero_rows);
        let (from, to) = self.block;
        let (refs, why, asked) = planned;
        let (with, st, outcomes) =
            serve_direction(rows, d, max_correction, params, refs, rezero_rows);
        let (without, _, _) = serve_direction(rows, d, max_correction, params, &[], rezero_rows);
        // The measured error in the operator's frame: about the last re-zero.
        let mut zero = 0.0;
        let (mut r_with, mut r_without, mut raw) = (vec![], vec![], vec![]);
        for (i, m) in measured.iter().enumerate().take(rows.len()) {
            if rezero_rows.contains(&i) {
                zero = m.unwrap_or(zero);
            }
            let Some(m) = m else { continue };
            if i < from || i >= to {
                continue;
            }
            let e = m - zero;
            raw.push(e);
            r_with.push(e - f64::from(with[i]) / 10.0);
            r_without.push(e - f64::from(without[i]) / 10.0);
        }
        let accepted_flags: Vec<bool> = outcomes
            .iter()
            .map(|o| matches!(o, ReferenceOutcome::Accepted { .. }))
            .collect();
        if let Some(dump) = dump {
            dump.push(DumpColumn {
                column: column.clone(),
                served: with.clone(),
                refs: refs
                    .iter()
                    .zip(&accepted_flags)
                    .map(|(r, &a)| (r.row, r.reading, a))
                    .collect(),
            });
        }
        if raw.is_empty() {
            return None;
        }
        let (mae, rms, peak) = stats(&r_with);
        let (mae0, rms0, _) = stats(&r_without);
        let (raw_mae, raw_rms, _) = stats(&raw);
        let refused_flags: Vec<bool> = accepted_flags.iter().map(|a| !a).collect();
        let taken = refs
            .iter()
            .zip(&accepted_flags)
            .enumerate()
            .map(|(k, (r, &accepted))| {
                let why = why.get(k);
                TakenReference {
                    time_s: rows[r.row].time_ms as f64 / 1000.0,
                    row: r.row,
                    accepted,
                    corrupted: r.corrupted,
                    reason: why.map(|(w, _)| match w {
                        AskReason::SpeedChange => "speed_change",
                        AskReason::Interval => "interval",
                        AskReason::None => "none",
                    }),
                    asked_s: why.map(|(_, t)| *t as f64 / 1000.0),
                }
            })
            .collect();
        let corrupted = refs.iter().filter(|r| r.corrupted).count();
        let corrupted_refused = refs
            .iter()
            .zip(&refused_flags)
            .filter(|(r, &f)| r.corrupted && f)
            .count();
        let clean_refused = refs
            .iter()
            .zip(&refused_flags)
            .filter(|(r, &f)| !r.corrupted && f)
            .count();
        Some(ChannelReference {
            column,
            rows: raw.len(),
            mae_um: mae,
            rms_um: rms,
            peak_um: peak,
            mae_without_um: mae0,
            rms_without_um: rms0,
            raw_mae_um: raw_mae,
            raw_rms_um: raw_rms,
            references: refs.len(),
            references_in_block: refs.iter().filter(|r| r.row >= from && r.row < to).count(),
            accepted: usize::from(st.accepted),
            refused: usize::from(st.refused),
            corrupted,
            corrupted_refused,
            clean_refused,
            asked_speed_change: asked[0],
            asked_interval: asked[1],
            taken,
            never_worse_than_model: rms <= rms0,
            never_worse_than_raw: rms <= raw_rms,
            final_state: st.to_bytes().iter().map(|b| format!("{b:02x}")).collect(),
            served_hash: format!("{:016x}", fnv(&with)),
        })
    }
}

/// One direction of `--reference-dump`: served values, and the references
/// (row, reading in 0.1 µm, accepted).
struct DumpColumn {
    column: String,
    served: Vec<i32>,
    refs: Vec<(usize, i32, bool)>,
}

/// Per direction: measured, model, served (µm), and at the rows of a
/// reference the reading (µm) and whether it was accepted (1/0).
fn write_dump(
    path: &std::path::Path,
    run: &Run,
    rows: &[ReplayRow],
    model: &Model,
    served: &[DumpColumn],
) -> Result<()> {
    use std::fmt::Write as _;
    let mut text = String::from("time_s");
    for DumpColumn { column: c, .. } in served {
        let _ = write!(
            text,
            ",{c}_measured,{c}_model,{c}_served,{c}_reference,{c}_accepted"
        );
    }
    text.push('\n');
    let cols: Vec<(usize, &[Option<f64>])> = served
        .iter()
        .filter_map(|s| {
            let d = (0..model.directions.len())
                .find(|&d| format!("d{}_um", model.direction_name(d)) == s.column)?;
            Some((d, run.col(&s.column)?))
        })
        .collect();
    let mut next = vec![0usize; served.len()];
    for (i, r) in rows.iter().enumerate() {
        let _ = write!(text, "{}", r.time_ms as f64 / 1000.0);
        for (k, ((d, m), s)) in cols.iter().zip(served).enumerate() {
            let m = m
                .get(i)
                .copied()
                .flatten()
                .map_or(String::new(), |v| format!("{v}"));
            let _ = write!(
                text,
                ",{m},{},{}",
                f64::from(r.out.corrections[*d]) / 10.0,
                f64::from(s.served[i]) / 10.0
            );
            match s.refs.get(next[k]) {
                Some(&(row, reading, accepted)) if row == i => {
                    next[k] += 1;
                    let _ = write!(
                        text,
                        ",{},{}",
                        f64::from(reading) / 10.0,
                        u8::from(accepted)
                    );
                }
                _ => text.push_str(",,"),
            }
        }
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|e| anyhow!("writing {}: {e}", path.display()))
}

impl ReferenceReport {
    /// The text form of `tcomp replay`.
    pub fn print(&self) {
        match self.every_s {
            Some(e) => println!(
                "  references every {:.0} s from {:.0} s (probe noise σ {} µm{}, seed {}); re-zeros at {:?} ms",
                e,
                if self.phase_s > 0.0 { self.phase_s } else { e },
                self.noise_um,
                self.outliers
                    .map(|(s, o)| format!(", {:.1} % corrupted by {o:+} µm", s * 100.0))
                    .unwrap_or_default(),
                self.seed,
                self.rezero_ms
            ),
            None => match &self.when_asked {
                Some(a) => {
                    let part = |s: u16, what: &str| {
                        if s == 0 {
                            format!("never {what}")
                        } else if s.is_multiple_of(60) {
                            format!("{} min {what}", s / 60)
                        } else {
                            format!("{s} s {what}")
                        }
                    };
                    println!(
                        "  references when the board asks: {} of ≥ {} rpm, {} (the PLC probes at the next sample; probe noise σ {} µm{}, seed {}); re-zeros at {:?} ms",
                        part(a.settle_s, "after a spindle-speed change"),
                        a.speed_step_rpm,
                        part(a.max_interval_s, "since the last accepted reference at most"),
                        self.noise_um,
                        self.outliers
                            .map(|(s, o)| format!(", {:.1} % corrupted by {o:+} µm", s * 100.0))
                            .unwrap_or_default(),
                        self.seed,
                        self.rezero_ms
                    );
                    if !a.spindle_rpm {
                        println!("  the run has no spindle_rpm column: the board asks by the interval rule only");
                    }
                }
                None => println!("  no references; re-zeros at {:?} ms", self.rezero_ms),
            },
        }
        if let Some(a) = self.after_change_s {
            println!("  and a reference {a:.0} s after every change of spindle speed");
        }
        for c in &self.channels {
            println!(
                "  {}: with references MAE {:.2} µm, RMS {:.2} µm (peak {:.2}); model alone MAE {:.2}, RMS {:.2}; raw MAE {:.2}, RMS {:.2}",
                c.column, c.mae_um, c.rms_um, c.peak_um, c.mae_without_um, c.rms_without_um, c.raw_mae_um, c.raw_rms_um
            );
            println!(
                "  {}: {} references ({} in the block), {} accepted, {} refused ({} of {} corrupted refused, {} clean refused)",
                c.column, c.references, c.references_in_block, c.accepted, c.refused, c.corrupted_refused, c.corrupted, c.clean_refused
            );
            if self.when_asked.is_some() {
                println!(
                    "  {}: the board asked {} times ({} after a speed change, {} at the interval)",
                    c.column,
                    c.asked_speed_change + c.asked_interval,
                    c.asked_speed_change,
                    c.asked_interval
                );
            }
        }
    }
}

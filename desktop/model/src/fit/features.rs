//! Training features by the board's own pipeline: each run is turned into
//! the integers the board's trace parser hands the compensator (time in ms,
//! temperatures in 1/16 °C, whole rpm; an empty spindle cell is 0 rpm, as
//! the bench board reads it) and fed through
//! [`thermocomp_core::features::FeatureState`] — the code
//! `Compensator::step` runs. The fixed-point features (Q8 of 1/16 °C or
//! rpm) are converted to f64 °C / rpm for training, so the fitted model sees
//! exactly the numbers the board will compute: the reference row (the first
//! row at which the feature's sensors are valid), the 1/16 °C rounding, the
//! gap rule (a row where a sensor the feature reads is empty yields no
//! feature: the board serves no new correction there) and the lag decay per
//! whole model step.

use anyhow::{bail, Context, Result};
use thermocomp_core::features::FeatureState;
use thermocomp_core::image::{InputKind, InputSpec, Model, SensorRef};
use thermocomp_core::limits::{MAX_INPUTS, MAX_SENSORS};

use super::model::{feature_name, FeatureKind, FeatureSpec, ModelFile};
use super::split::Segment;
use tcomp_data::runcsv::Run;

/// The model step of every image `tcomp export` writes (ms): the lag filters'
/// discretisation, the same in training and on the board.
pub const STEP_MS: u32 = 1000;

/// The temperature columns the board reads, in its channel order: the run's
/// `T_…` columns in file order, the first [`MAX_SENSORS`] of them.
pub fn board_channels(run: &Run) -> Vec<String> {
    run.temperature_columns()
        .iter()
        .take(MAX_SENSORS)
        .map(|s| s.to_string())
        .collect()
}

/// A run as the board's inputs see it (integers, board channel order).
pub struct BoardRows {
    pub time_ms: Vec<u64>,
    /// `temps[channel][row]` in 1/16 °C; `None` where the cell is empty or
    /// outside what a DS18B20 reports (i16).
    pub temps: Vec<Vec<Option<i32>>>,
    pub spindle_rpm: Vec<i32>,
    /// Temperature column names in board channel order.
    pub channels: Vec<String>,
}

impl BoardRows {
    /// What the trace parser (`thermocomp_protocol::trace`) makes of the run: decimal
    /// values rounded half away from zero to 1 ms, 1/16 °C and 1 rpm.
    pub fn new(run: &Run) -> Result<BoardRows> {
        let time_ms = run
            .time_s()
            .iter()
            .map(|t| {
                if t.is_finite() && *t >= 0.0 {
                    Ok((t * 1000.0).round() as u64)
                } else {
                    bail!("time_s {t} is not a time the board can replay")
                }
            })
            .collect::<Result<Vec<_>>>()?;
        let channels = board_channels(run);
        let temps = channels
            .iter()
            .map(|c| {
                run.col(c)
                    .unwrap_or(&[])
                    .iter()
                    .map(|v| {
                        v.map(|v| (v * 16.0).round())
                            .filter(|v| *v >= f64::from(i16::MIN) && *v <= f64::from(i16::MAX))
                            .map(|v| v as i32)
                    })
                    .collect()
            })
            .collect();
        let spindle_rpm = match run.col("spindle_rpm") {
            Some(c) => c
                .iter()
                .map(|v| v.map_or(0, |v| v.round().clamp(-1e9, 1e9) as i32))
                .collect(),
            None => vec![0; time_ms.len()],
        };
        Ok(BoardRows {
            time_ms,
            temps,
            spindle_rpm,
            channels,
        })
    }

    fn channel(&self, name: &str) -> Result<u8> {
        let ch = self.channels.iter().position(|c| c == name).with_context(|| {
            format!(
                "no temperature column `{name}` among the board's {MAX_SENSORS} channels (columns: {})",
                self.channels.join(",")
            )
        })?;
        Ok(ch as u8)
    }
}

/// Per feature, the f64 unit of one Q8 step: 1/16 °C · 1/256 for
/// temperatures (features in °C), 1/256 for rpm.
fn unit(kind: &FeatureKind) -> f64 {
    match kind {
        FeatureKind::Spindle => 1.0 / 256.0,
        _ => 1.0 / (256.0 * 16.0),
    }
}

/// The board's feature series over a run: `out[feature][row]` in °C (rises,
/// differences) or rpm, NaN on rows where the board computes no feature (a
/// sensor the feature reads is empty). Features reading the same sensors
/// share one pipeline (same reference row and gaps, as on the board).
pub fn board_series(run: &Run, kinds: &[(FeatureKind, Option<f64>)]) -> Result<Vec<Vec<f64>>> {
    let rows = BoardRows::new(run)?;
    board_series_of(&rows, kinds)
}

/// [`board_series`] on a run already converted.
pub fn board_series_of(
    rows: &BoardRows,
    kinds: &[(FeatureKind, Option<f64>)],
) -> Result<Vec<Vec<f64>>> {
    let mut out = vec![Vec::new(); kinds.len()];
    // Group by the sensors read: each group is one pipeline of ≤ MAX_INPUTS inputs.
    let mut groups: Vec<(Vec<String>, Vec<usize>)> = Vec::new();
    for (i, (k, _)) in kinds.iter().enumerate() {
        let mut cols: Vec<String> = k
            .columns()
            .into_iter()
            .filter(|c| *c != "spindle_rpm")
            .map(str::to_string)
            .collect();
        cols.sort();
        match groups
            .iter_mut()
            .find(|(c, m)| *c == cols && m.len() < MAX_INPUTS)
        {
            Some((_, m)) => m.push(i),
            None => groups.push((cols, vec![i])),
        }
    }
    for (_, members) in groups {
        let sub: Vec<_> = members.iter().map(|&i| kinds[i].clone()).collect();
        for (&i, c) in members.iter().zip(pipeline(rows, &sub)?) {
            out[i] = c;
        }
    }
    Ok(out)
}

/// All `kinds` in one pipeline, as one board image computes them: one
/// reference row and one gap rule for every input (a row where any sensor
/// is empty yields nothing). At most [`MAX_INPUTS`] inputs.
pub fn pipeline(rows: &BoardRows, kinds: &[(FeatureKind, Option<f64>)]) -> Result<Vec<Vec<f64>>> {
    let n = rows.time_ms.len();
    let mut model = Model::empty(0, STEP_MS);
    let mut channels: Vec<u8> = Vec::new();
    let mut sensor = |name: &str, model: &mut Model| -> Result<u8> {
        let ch = rows.channel(name)?;
        if let Some(i) = channels.iter().position(|c| *c == ch) {
            return Ok(i as u8);
        }
        model
            .sensors
            .push(SensorRef {
                rom: [0; 8],
                channel: ch,
                ref_temp: 0,
            })
            .map_err(|_| anyhow::anyhow!("more than {MAX_SENSORS} sensors"))?;
        channels.push(ch);
        Ok((channels.len() - 1) as u8)
    };
    for (k, tau) in kinds {
        let kind = match k {
            FeatureKind::SensorRise(a) => InputKind::SensorRise {
                a: sensor(a, &mut model)?,
            },
            FeatureKind::SensorDiff(a, b) => InputKind::SensorDiff {
                a: sensor(a, &mut model)?,
                b: sensor(b, &mut model)?,
            },
            FeatureKind::Spindle => InputKind::Spindle,
        };
        let lag = match tau {
            Some(t) if *t > 0.0 => Some(
                thermocomp_core::float::lag(*t, STEP_MS)
                    .map_err(|e| anyhow::anyhow!("feature {}: {e}", feature_name(k, *tau)))?,
            ),
            _ => None,
        };
        model
            .inputs
            .push(InputSpec {
                kind,
                lag,
                min: 0,
                max: 0,
            })
            .map_err(|_| anyhow::anyhow!("more than {MAX_INPUTS} inputs in one pipeline"))?;
    }
    let units: Vec<f64> = kinds.iter().map(|(k, _)| unit(k)).collect();
    let mut cols = vec![Vec::with_capacity(n); kinds.len()];
    let mut state = FeatureState::new();
    let mut temps = vec![None; channels.len()];
    for r in 0..n {
        for (t, &ch) in temps.iter_mut().zip(&channels) {
            *t = rows.temps[usize::from(ch)][r];
        }
        match state.step(&model, rows.time_ms[r], &temps, rows.spindle_rpm[r]) {
            Some(f) => {
                for ((c, &v), u) in cols.iter_mut().zip(f).zip(&units) {
                    c.push(f64::from(v) * u);
                }
            }
            None => cols.iter_mut().for_each(|c| c.push(f64::NAN)),
        }
    }
    Ok(cols)
}

/// Rows of `segs` where the exported image's features (every input of every
/// channel's chosen model in one pipeline) differ from the per-sensor
/// features each channel was trained on. Only sensor gaps cause it: the
/// board skips a whole step when any of the image's sensors is empty, and
/// its filters then catch up over the skipped steps. `None` when the image
/// would hold more inputs than one pipeline (export refuses it anyway).
pub fn image_gap_rows(
    runs: &[Run],
    segs: &[Segment],
    kinds: &[(FeatureKind, Option<f64>)],
) -> Result<Option<usize>> {
    if kinds.is_empty() || kinds.len() > MAX_INPUTS {
        return Ok(None);
    }
    let mut differ = 0usize;
    for (ri, run) in runs.iter().enumerate() {
        if !segs.iter().any(|s| s.run == ri) {
            continue;
        }
        let rows = BoardRows::new(run)?;
        let joint = pipeline(&rows, kinds)?;
        let own = board_series_of(&rows, kinds)?;
        for s in segs.iter().filter(|s| s.run == ri) {
            differ += (s.start..s.end)
                .filter(|&r| {
                    joint
                        .iter()
                        .zip(&own)
                        .any(|(j, o)| j[r].to_bits() != o[r].to_bits())
                })
                .count();
        }
    }
    Ok(Some(differ))
}

/// The distinct inputs of the models `file.chosen` names (what `export`
/// puts on the board by default), in first-use order.
pub fn chosen_kinds(file: &ModelFile) -> Vec<(FeatureKind, Option<f64>)> {
    fn inputs<'a, M: super::model::Model>(
        models: &'a [M],
        ch: &'a str,
    ) -> impl Iterator<Item = &'a FeatureSpec> + 'a {
        models
            .iter()
            .filter(move |m| m.channel() == ch)
            .flat_map(|m| m.features())
    }
    let mut out: Vec<(FeatureKind, Option<f64>)> = Vec::new();
    for (ch, name) in &file.chosen {
        let specs: Vec<&FeatureSpec> = match name.as_str() {
            "mlr" => inputs(&file.mlr, ch).collect(),
            "mlr-static" => inputs(&file.mlr_static, ch).collect(),
            "ridge" => inputs(&file.ridge, ch).collect(),
            "ga-bpn" => inputs(&file.nets, ch).collect(),
            "none" => vec![],
            // Any other model (e.g. a table plus networks): every input the channel has.
            _ => inputs(&file.mlr, ch)
                .chain(inputs(&file.nets, ch))
                .collect(),
        };
        for f in specs {
            let k = (f.kind.clone(), f.tau_s.filter(|t| *t > 0.0));
            if !out.contains(&k) {
                out.push(k);
            }
        }
    }
    out
}

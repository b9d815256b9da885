//! From `tcomp fit --out` parameters to the board's float model: which
//! fitted model each channel ships (the fit's choice or `--use`), its
//! tables and networks with the normalisation folded in, the fallbacks in
//! the board's priority order, all within the image's limits; and the
//! sensors named by ROM code when the run recorded them.

use anyhow::Result;
use thermocomp_core::float::{
    FloatDirection, FloatFallback, FloatInput, FloatModel, FloatNet, FloatTable, FloatTerm,
};
use thermocomp_core::image::{InputKind, SensorRef};
use thermocomp_core::limits::{
    MAX_DIRECTIONS, MAX_FALLBACKS, MAX_FALLBACK_TERMS, MAX_INPUTS, MAX_NETS, MAX_NET_INPUTS,
    MAX_SENSORS, MAX_TABLES, MAX_TERMS,
};

use crate::fit::{FallbackParams, FeatureKind, FeatureSpec, ModelFile, NetParams};

/// Which fitted model of a channel goes on the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Choice {
    /// The GA-BPN ensemble (`ga-bpn`, alias `net`).
    Net,
    /// The lagged MLR (`mlr`).
    Mlr,
    /// The static MLR on the selected sensors (`mlr-static`).
    MlrStatic,
    /// Ridge regression on the lagged MLR's inputs (`ridge`): a table like
    /// the MLR's, with its own (shrunk) coefficients.
    Ridge,
    /// The lagged MLR plus its residual networks (`hybrid`): a table and
    /// networks of the same direction, which the board sums.
    Hybrid,
    /// `w·mlr + (1−w)·ga-bpn` (`blend`, `w` from the fit): the lagged MLR's
    /// table scaled by `w` and the networks' output layers by `(1−w)/k`.
    Blend,
    /// No compensation (`none`): the direction is served as 0 about the
    /// run's reference; the fit chose it when no model beat it in CV.
    None,
}

impl Choice {
    pub fn parse(s: &str) -> Result<Choice> {
        Ok(match s.trim() {
            "net" | "ga-bpn" => Choice::Net,
            "mlr" => Choice::Mlr,
            "mlr-static" => Choice::MlrStatic,
            "ridge" => Choice::Ridge,
            "hybrid" => Choice::Hybrid,
            "blend" => Choice::Blend,
            "none" => Choice::None,
            other => {
                anyhow::bail!(
                    "unknown model `{other}` (ga-bpn, blend, hybrid, mlr, mlr-static, ridge or none)"
                )
            }
        })
    }
}

/// Board limits and identity for an exported model.
#[derive(Debug, Clone)]
pub struct ExportOptions {
    pub model_version: u32,
    pub max_correction_um: f64,
    pub max_rate_um_per_s: f64,
    pub warmup_s: u32,
    /// Per channel (e.g. `dch5_um`) overrides of the fit's choice.
    pub choices: Vec<(String, Choice)>,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            model_version: 1,
            max_correction_um: 200.0,
            max_rate_um_per_s: 1.0,
            warmup_s: 1800,
            choices: vec![],
        }
    }
}

/// The model a channel ships: the `--use` override, else the fit's
/// cross-validated choice, else (an old fit file without one) the lagged MLR.
pub fn choice_for(file: &ModelFile, opts: &ExportOptions, ch: &str) -> Result<Choice> {
    if let Some((_, c)) = opts.choices.iter().find(|(c, _)| c == ch) {
        return Ok(*c);
    }
    match file.chosen.get(ch) {
        Some(name) => Choice::parse(name),
        None => Ok(Choice::Mlr),
    }
}

/// Build the board's float model from `tcomp fit --out` parameters.
///
/// Temperatures become 1/16 °C, the training envelope is widened to whole
/// raw units (the image stores integers) and the normalisation change is
/// folded into the first-layer weights and biases (MLR: into its terms), so
/// the float model computes exactly what the fitted one did inside the
/// original envelope. `temperature_columns` is the board's channel order
/// (the run's `T_…` columns, as the bench maps them).
pub fn float_model_from_fit(
    file: &ModelFile,
    temperature_columns: &[String],
    opts: &ExportOptions,
) -> Result<FloatModel> {
    let channels = fitted_channels(file);
    if channels.len() > MAX_DIRECTIONS {
        anyhow::bail!(
            "the model has {} channels; the board serves at most {MAX_DIRECTIONS} directions (MAX_DIRECTIONS)",
            channels.len()
        );
    }
    let mut b = FloatModelBuilder {
        model: empty_float_model(opts),
        temperature_columns,
    };
    for ch in &channels {
        b.add_direction(file, opts, ch)?;
    }
    if b.model.tables.is_empty() && b.model.nets.is_empty() {
        anyhow::bail!(
            "no channel has a model to ship: the fit chose `none` (no model beat no compensation in its cross-validation) for {}; `--use CHANNEL=mlr` ships one anyway",
            channels.join(", ")
        );
    }
    b.add_fallbacks(file, &channels);
    Ok(b.model)
}

/// Name the model's sensors by the ROM codes the run recorded for their
/// columns (`# rom.T_<name>:`, [`tcomp_data::runcsv::Run::sensor_roms`]), so the
/// board reads each from the physical sensor it was trained on, whatever
/// channel that sensor has. Each sensor's `channel` (its run column) stays.
/// A run with ROM codes for some of the model's sensors but not all is
/// refused (a model half by ROM, half by channel would be trusted more than
/// it deserves); a run without any leaves the model by channel. Returns how
/// many sensors are named by ROM.
pub fn name_sensors_by_rom(
    model: &mut FloatModel,
    temperature_columns: &[String],
    roms: &std::collections::BTreeMap<String, [u8; 8]>,
) -> Result<usize> {
    let column = |ch: u8| temperature_columns.get(usize::from(ch));
    let missing: Vec<&str> = model
        .sensors
        .iter()
        .filter_map(|s| column(s.channel))
        .filter(|c| !roms.contains_key(*c))
        .map(String::as_str)
        .collect();
    if missing.len() == model.sensors.len() {
        return Ok(0);
    }
    if !missing.is_empty() {
        anyhow::bail!(
            "the run records ROM codes for some of the model's sensors but not for {}: record the run again with every sensor on the bus (tcomp record) or remove the rom.* lines",
            missing.join(", ")
        );
    }
    for s in &mut model.sensors {
        if let Some(rom) = column(s.channel).and_then(|c| roms.get(c)) {
            s.rom = *rom;
        }
    }
    Ok(model.sensors.len())
}

/// Every channel with a fitted model, sorted: the board's directions.
fn fitted_channels(file: &ModelFile) -> Vec<String> {
    let mut channels: Vec<String> = file
        .nets
        .iter()
        .map(|n| n.channel.clone())
        .chain(file.mlr.iter().map(|m| m.channel.clone()))
        .chain(file.mlr_static.iter().map(|m| m.channel.clone()))
        .chain(file.ridge.iter().map(|m| m.channel.clone()))
        .collect();
    channels.sort();
    channels.dedup();
    channels
}

fn empty_float_model(opts: &ExportOptions) -> FloatModel {
    FloatModel {
        model_version: opts.model_version,
        step_ms: crate::fit::features::STEP_MS,
        warmup_s: opts.warmup_s,
        fixed_reference: false,
        sensors: vec![],
        directions: vec![],
        axes: vec![],
        inputs: vec![],
        nets: vec![],
        tables: vec![],
        fallbacks: vec![],
    }
}

/// The blend's shares of channel `ch`: the table's `w`, the networks' `1 − w`
/// (both 1 for every other choice).
fn blend_shares(file: &ModelFile, ch: &str, choice: Choice) -> Result<(f64, f64)> {
    if choice != Choice::Blend {
        return Ok((1.0, 1.0));
    }
    let w = *file.blend.get(ch).ok_or_else(|| {
        anyhow::anyhow!("no blend weight for channel {ch} in the fit file (fit with --blend)")
    })?;
    anyhow::ensure!(
        (0.0..=1.0).contains(&w),
        "channel {ch}: blend weight {w} is outside [0, 1]"
    );
    Ok((w, 1.0 - w))
}

/// Fallbacks in the board's priority order: per channel the lowest
/// cross-validated RMS first (singles before pairs at equal CV; no CV
/// figure: last).
fn fallbacks_by_priority(file: &ModelFile) -> Vec<&FallbackParams> {
    let mut ordered: Vec<&FallbackParams> = file.fallbacks.iter().collect();
    ordered.sort_by(|a, b| {
        let key = |f: &FallbackParams| (f.cv_rms_um.unwrap_or(f64::INFINITY), f.excluded.len());
        let (ka, kb) = (key(a), key(b));
        ka.0.total_cmp(&kb.0).then(ka.1.cmp(&kb.1))
    });
    ordered
}

/// The float model under construction, with the board's channel order.
struct FloatModelBuilder<'a> {
    model: FloatModel,
    temperature_columns: &'a [String],
}

impl FloatModelBuilder<'_> {
    /// The model's sensor index of temperature column `name` (added if new).
    fn sensor_of(&mut self, name: &str) -> Result<u8> {
        let ch = self
            .temperature_columns
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| {
                anyhow::anyhow!("sensor column {name} is not in the run's temperature columns")
            })?;
        if ch >= MAX_SENSORS {
            anyhow::bail!(
                "sensor {name} is board channel {ch}; the board reads channels 0..={} (MAX_SENSORS = {MAX_SENSORS})",
                MAX_SENSORS - 1
            );
        }
        let model = &mut self.model;
        if let Some(i) = model
            .sensors
            .iter()
            .position(|s| usize::from(s.channel) == ch)
        {
            return Ok(i as u8);
        }
        model.sensors.push(SensorRef {
            rom: [0; 8],
            channel: ch as u8,
            ref_temp: 0,
        });
        Ok((model.sensors.len() - 1) as u8)
    }

    /// One model input per distinct (kind, lag); returns its index and the
    /// fold (a, c) of the normalisation change.
    fn input_of(&mut self, f: &FeatureSpec) -> Result<(u8, f64, f64)> {
        let (kind, scale) = match &f.kind {
            FeatureKind::SensorRise(a) => (
                InputKind::SensorRise {
                    a: self.sensor_of(a)?,
                },
                16.0,
            ),
            FeatureKind::SensorDiff(a, b) => (
                InputKind::SensorDiff {
                    a: self.sensor_of(a)?,
                    b: self.sensor_of(b)?,
                },
                16.0,
            ),
            FeatureKind::Spindle => (InputKind::Spindle, 1.0),
        };
        anyhow::ensure!(
            f.max > f.min,
            "feature {:?} has an empty training range",
            f.kind
        );
        let (lo, hi) = (f.min * scale, f.max * scale);
        let mut lo2 = lo.floor();
        let mut hi2 = hi.ceil();
        if hi2 - lo2 < 2.0 {
            lo2 -= 1.0;
            hi2 += 1.0;
        }
        let a = (hi2 - lo2) / (hi - lo);
        let c = (lo2 + hi2 - lo - hi) / (hi - lo);
        let spec = FloatInput {
            kind,
            tau_s: f.tau_s.filter(|t| *t > 0.0),
            min: lo2,
            max: hi2,
        };
        let inputs = &mut self.model.inputs;
        let idx = match inputs.iter().position(|i| *i == spec) {
            Some(i) => i,
            None => {
                if inputs.len() >= MAX_INPUTS {
                    anyhow::bail!(
                        "the model needs more than {MAX_INPUTS} distinct inputs, the most a board image holds (MAX_INPUTS)"
                    );
                }
                inputs.push(spec);
                inputs.len() - 1
            }
        };
        Ok((idx as u8, a, c))
    }

    /// The terms of a linear model scaled by `w`, the normalisation change
    /// folded in, constant last (`w = 1` leaves every figure as it is).
    fn linear_terms(
        &mut self,
        features: &[FeatureSpec],
        coefs: &[f64],
        c0: f64,
        w: f64,
    ) -> Result<Vec<FloatTerm>> {
        let mut terms = vec![];
        let mut c0 = c0 * w;
        for (f, coef) in features.iter().zip(coefs) {
            let (i, a, c) = self.input_of(f)?;
            let coef = coef * w;
            c0 += coef * c;
            terms.push(FloatTerm {
                coef_um: coef * a,
                input: Some(i),
                input_power: 1,
                position_power: 0,
            });
        }
        terms.push(FloatTerm {
            coef_um: c0,
            input: None,
            input_power: 0,
            position_power: 0,
        });
        Ok(terms)
    }

    /// Direction `ch` with the networks and table its choice ships.
    fn add_direction(&mut self, file: &ModelFile, opts: &ExportOptions, ch: &str) -> Result<()> {
        let choice = choice_for(file, opts, ch)?;
        let d = self.model.directions.len() as u8;
        let name = ch.trim_start_matches('d').trim_end_matches("_um");
        self.model.directions.push(FloatDirection {
            name: name.to_string(),
            max_correction_um: opts.max_correction_um,
            max_rate_um_per_s: opts.max_rate_um_per_s,
        });
        let (w_table, w_nets) = blend_shares(file, ch, choice)?;
        let members: Vec<_> = match choice {
            Choice::Net => file.nets.iter().filter(|n| n.channel == ch).collect(),
            Choice::Blend if w_nets > 0.0 => file.nets.iter().filter(|n| n.channel == ch).collect(),
            Choice::Hybrid => file
                .hybrid_nets
                .iter()
                .filter(|n| n.channel == ch)
                .collect(),
            _ => vec![],
        };
        let mlr = match choice {
            Choice::MlrStatic => file.mlr_static.iter().find(|m| m.channel == ch),
            Choice::Ridge => file.ridge.iter().find(|m| m.channel == ch),
            Choice::Mlr | Choice::Hybrid | Choice::Blend => {
                file.mlr.iter().find(|m| m.channel == ch)
            }
            Choice::Net | Choice::None => None,
        };
        let blend_nets = choice == Choice::Blend && w_nets > 0.0;
        if matches!(choice, Choice::Net | Choice::Hybrid) || blend_nets {
            self.add_nets(ch, d, choice, &members, w_nets)?;
        }
        let blend_table = choice == Choice::Blend && w_table > 0.0;
        let table = matches!(
            choice,
            Choice::Mlr | Choice::MlrStatic | Choice::Ridge | Choice::Hybrid
        );
        if table || blend_table {
            let Some(m) = mlr else {
                anyhow::bail!("no fitted {choice:?} model for channel {ch}");
            };
            if self.model.tables.len() >= MAX_TABLES || m.features.len() + 1 > MAX_TERMS {
                anyhow::bail!(
                    "channel {ch}: the board image holds at most {MAX_TABLES} tables of {MAX_TERMS} terms (MAX_TABLES, MAX_TERMS)"
                );
            }
            let terms = self.linear_terms(&m.features, &m.coef, m.c0, w_table)?;
            self.model.tables.push(FloatTable {
                direction: d,
                axis: None,
                terms,
            });
        }
        Ok(())
    }

    /// The networks of direction `d` (channel `ch`): the ensemble's mean,
    /// each member's output layer scaled by 1/k (and by the blend's `w_nets`).
    fn add_nets(
        &mut self,
        ch: &str,
        d: u8,
        choice: Choice,
        members: &[&NetParams],
        w_nets: f64,
    ) -> Result<()> {
        if members.is_empty() {
            anyhow::bail!(
                "no fitted {} network for channel {ch} (fit without --mlr-only)",
                match choice {
                    Choice::Hybrid => "hybrid",
                    Choice::Blend => "blend",
                    _ => "ga-bpn",
                }
            );
        }
        if self.model.nets.len() + members.len() > MAX_NETS {
            anyhow::bail!(
                "channel {ch} needs {} networks; the board image holds at most {MAX_NETS} in all (MAX_NETS)",
                members.len()
            );
        }
        let k = members.len() as f64 / w_nets;
        for n in members {
            if n.features.len() > MAX_NET_INPUTS {
                anyhow::bail!(
                    "channel {ch}: a network with {} inputs; the board takes at most {MAX_NET_INPUTS} (MAX_NET_INPUTS)",
                    n.features.len()
                );
            }
            let mut inputs = vec![];
            let mut folds = vec![];
            for f in &n.features {
                let (i, a, c) = self.input_of(f)?;
                inputs.push(i);
                folds.push((a, c));
            }
            let w1: Vec<Vec<f64>> =
                n.w1.iter()
                    .map(|row| row.iter().zip(&folds).map(|(w, (a, _))| w * a).collect())
                    .collect();
            let b1 = n
                .w1
                .iter()
                .zip(&n.b1)
                .map(|(row, b)| b + row.iter().zip(&folds).map(|(w, (_, c))| w * c).sum::<f64>())
                .collect();
            self.model.nets.push(FloatNet {
                direction: d,
                inputs,
                w1,
                b1,
                w2: n.w2.iter().map(|w| w / k).collect(),
                b2: n.b2 / k,
            });
        }
        Ok(())
    }

    /// Fallback models (image v2) in the board's priority order: the board
    /// serves a direction with the first fallback whose sensors are all
    /// valid. One that would need inputs beyond the board's is left out
    /// (said on stderr); `export` drops the last ones if the image would
    /// exceed MAX_IMAGE_BYTES.
    fn add_fallbacks(&mut self, file: &ModelFile, channels: &[String]) {
        for fb in fallbacks_by_priority(file) {
            let Some(d) = channels.iter().position(|c| *c == fb.channel) else {
                continue;
            };
            self.add_fallback(fb, d as u8);
        }
    }

    fn add_fallback(&mut self, fb: &FallbackParams, d: u8) {
        // Only sensors the exported model reads: a fallback for any other is never used.
        let excluded: Option<Vec<u8>> = fb
            .excluded
            .iter()
            .map(|name| {
                let ch = self.temperature_columns.iter().position(|c| c == name)?;
                self.model
                    .sensors
                    .iter()
                    .position(|s| usize::from(s.channel) == ch)
                    .map(|i| i as u8)
            })
            .collect();
        let Some(excluded) = excluded else { return };
        let held_terms: usize = self.model.fallbacks.iter().map(|f| f.terms.len()).sum();
        if self.model.fallbacks.len() >= MAX_FALLBACKS
            || held_terms + fb.params.features.len() + 1 > MAX_FALLBACK_TERMS
        {
            eprintln!(
                "note: fallback of {} without {} left out: the image holds {MAX_FALLBACKS} fallbacks of {MAX_FALLBACK_TERMS} terms in all",
                fb.channel,
                fb.excluded.join("+")
            );
            return;
        }
        let (n_sensors, n_inputs) = (self.model.sensors.len(), self.model.inputs.len());
        let m = &fb.params;
        match self.linear_terms(&m.features, &m.coef, m.c0, 1.0) {
            Ok(terms) => self.model.fallbacks.push(FloatFallback {
                direction: d,
                excluded,
                terms,
            }),
            Err(e) => {
                self.model.sensors.truncate(n_sensors);
                self.model.inputs.truncate(n_inputs);
                eprintln!(
                    "note: fallback of {} without {} left out: {e}",
                    fb.channel,
                    fb.excluded.join("+")
                );
            }
        }
    }
}

/// Parse `dch5_um=mlr,dch3_um=ridge` (`net` is an alias of `ga-bpn`).
pub fn parse_choices(s: &str) -> Result<Vec<(String, Choice)>> {
    s.split(',')
        .filter(|p| !p.trim().is_empty())
        .map(|p| {
            let (ch, k) = p.split_once('=').ok_or_else(|| {
                anyhow::anyhow!("expected CHANNEL=ga-bpn|hybrid|mlr|mlr-static|ridge, got {p}")
            })?;
            Ok((ch.trim().to_string(), Choice::parse(k)?))
        })
        .collect()
}

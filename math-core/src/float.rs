//! The same model in f64 (the desktop's reference) and the quantizer from
//! float parameters to the fixed-point [`Model`], with a report of the worst
//! fixed-vs-float deviation over the admissible input range.

use crate::image::{
    self, Axis, Direction, EnvelopeMode, EnvelopePolicy, InputKind, InputSpec, Lag, Model, Net,
    SensorRef, Table, Term, NONE,
};
use crate::limits::*;

#[derive(Debug, Clone, PartialEq)]
pub struct FloatInput {
    pub kind: InputKind,
    /// First-order lag time constant, seconds.
    pub tau_s: Option<f64>,
    /// Training envelope in raw units (1/16 °C or rpm), whole numbers.
    pub min: f64,
    pub max: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatNet {
    pub direction: u8,
    pub inputs: Vec<u8>,
    /// w1[hidden][input], b1[hidden]: on inputs normalised to [-1, 1].
    pub w1: Vec<Vec<f64>>,
    pub b1: Vec<f64>,
    /// Output layer in µm.
    pub w2: Vec<f64>,
    pub b2: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatTerm {
    pub coef_um: f64,
    pub input: Option<u8>,
    pub input_power: u8,
    pub position_power: u8,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatTable {
    pub direction: u8,
    pub axis: Option<u8>,
    pub terms: Vec<FloatTerm>,
}

/// A fallback model (image format v2): a static polynomial table that serves
/// `direction` without the `excluded` model sensors (one or two).
#[derive(Debug, Clone, PartialEq)]
pub struct FloatFallback {
    pub direction: u8,
    pub excluded: Vec<u8>,
    pub terms: Vec<FloatTerm>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatDirection {
    pub name: String,
    pub max_correction_um: f64,
    pub max_rate_um_per_s: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatAxis {
    pub name: String,
    /// µm (or 0.001°), whole numbers.
    pub pos_min: f64,
    pub pos_max: f64,
    pub ref_pos: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FloatModel {
    pub model_version: u32,
    pub step_ms: u32,
    pub warmup_s: u32,
    pub fixed_reference: bool,
    pub sensors: Vec<SensorRef>,
    pub directions: Vec<FloatDirection>,
    pub axes: Vec<FloatAxis>,
    pub inputs: Vec<FloatInput>,
    pub nets: Vec<FloatNet>,
    pub tables: Vec<FloatTable>,
    /// Fallback models in priority order (empty: a v1 image).
    pub fallbacks: Vec<FloatFallback>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum QuantizeError {
    /// A parameter does not fit its fixed-point format.
    OutOfRange { what: String, value: f64 },
    /// The result is not a valid image.
    Image(image::ImageError),
}

impl core::fmt::Display for QuantizeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            QuantizeError::OutOfRange { what, value } => {
                write!(f, "{what} = {value} does not fit its fixed-point format")
            }
            QuantizeError::Image(e) => write!(f, "quantized model is not a valid image: {e}"),
        }
    }
}

impl std::error::Error for QuantizeError {}

/// Worst fixed-vs-float deviation found by [`FloatModel::quantize`].
#[derive(Debug, Clone, PartialEq)]
pub struct QuantReport {
    /// Per direction, max |fixed − float| in µm over all samples.
    pub max_deviation_um: Vec<f64>,
    /// Input features (raw units) and positions where the worst deviation occurred.
    pub worst_features: Vec<f64>,
    pub worst_positions: Vec<f64>,
    pub samples: usize,
}

fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

fn normalise(v: f64, min: f64, max: f64) -> f64 {
    2.0 * (v.clamp(min, max) - min) / (max - min) - 1.0
}

/// [`normalise`] over the extended span of the envelope policy
/// `extrapolate`: the line continues [`EXTRAPOLATE_WIDTHS`] widths beyond
/// each edge and is held there (within ±(1 + 2W)), as
/// [`crate::fixed::Span::normalise_extended`].
fn normalise_extended(v: f64, min: f64, max: f64) -> f64 {
    let reach = f64::from(EXTRAPOLATE_WIDTHS) * (max - min);
    2.0 * (v.clamp(min - reach, max + reach) - min) / (max - min) - 1.0
}

// Host-side f64 reference: a float model's indices come from the fit and
// are checked by `FloatModel::quantize` (through `Model::parse`); an
// inconsistent one is the caller's bug and panics on the desktop (the
// indexing allowed below).
impl FloatNet {
    #[allow(
        clippy::indexing_slicing,
        reason = "x has one entry per model input; net input indices are below"
    )]
    pub fn evaluate_um(&self, x: &[f64]) -> f64 {
        let mut y = self.b2;
        for ((row, &b1), &w2) in self.w1.iter().zip(&self.b1).zip(&self.w2) {
            let z = b1
                + row
                    .iter()
                    .zip(&self.inputs)
                    .map(|(w, &i)| w * x[usize::from(i)])
                    .sum::<f64>();
            y += w2 * sigmoid(z);
        }
        y
    }
}

impl FloatTable {
    #[allow(
        clippy::indexing_slicing,
        reason = "x has one entry per model input; term input indices are below"
    )]
    fn evaluate_um(&self, x: &[f64], p: f64, derivative: bool) -> f64 {
        let mut y = 0.0;
        for t in &self.terms {
            let xi = t.input.map(|i| x[usize::from(i)]).unwrap_or(1.0);
            let xv = xi.powi(i32::from(t.input_power));
            if derivative {
                if t.position_power > 0 {
                    y += t.coef_um
                        * f64::from(t.position_power)
                        * p.powi(i32::from(t.position_power) - 1)
                        * xv;
                }
            } else {
                y += t.coef_um * p.powi(i32::from(t.position_power)) * xv;
            }
        }
        y
    }
}

impl FloatModel {
    /// Normalised inputs, clamped to the envelope.
    pub fn normalise(&self, features: &[f64]) -> Vec<f64> {
        self.inputs
            .iter()
            .zip(features)
            .map(|(i, &v)| normalise(v, i.min, i.max))
            .collect()
    }

    /// Predicted error per direction (µm) for features (raw units, after lags) and positions.
    #[allow(
        clippy::indexing_slicing,
        reason = "directions of nets and tables are below directions.len()"
    )]
    pub fn evaluate_um(&self, features: &[f64], positions: &[f64]) -> Vec<f64> {
        let x = self.normalise(features);
        let mut y = vec![0.0; self.directions.len()];
        for n in &self.nets {
            y[usize::from(n.direction)] += n.evaluate_um(&x);
        }
        for t in &self.tables {
            let p = self.position_norm(t.axis, positions);
            y[usize::from(t.direction)] += t.evaluate_um(&x, p, false);
        }
        y
    }

    /// [`FloatModel::evaluate_um`] under the image's envelope policy per
    /// direction (`None`: every direction holds, as an image without the
    /// section): a direction under `extrapolate` is evaluated with its
    /// inputs over the extended span (the compensator's rule 4), the others
    /// with every input held at the edge of its range.
    #[allow(
        clippy::indexing_slicing,
        reason = "directions of nets and tables are below directions.len()"
    )]
    pub fn evaluate_um_with_policy(
        &self,
        features: &[f64],
        positions: &[f64],
        policies: Option<&[EnvelopePolicy]>,
    ) -> Vec<f64> {
        let mut y = self.evaluate_um(features, positions);
        let extrapolates = |d: u8| {
            policies
                .and_then(|p| p.get(usize::from(d)))
                .is_some_and(|p| p.mode == EnvelopeMode::Extrapolate)
        };
        if !(0..self.directions.len()).any(|d| u8::try_from(d).is_ok_and(extrapolates)) {
            return y;
        }
        let x: Vec<f64> = self
            .inputs
            .iter()
            .zip(features)
            .map(|(i, &v)| normalise_extended(v, i.min, i.max))
            .collect();
        for (d, yd) in (0u8..).zip(y.iter_mut()) {
            if extrapolates(d) {
                *yd = 0.0;
            }
        }
        for n in self.nets.iter().filter(|n| extrapolates(n.direction)) {
            y[usize::from(n.direction)] += n.evaluate_um(&x);
        }
        for t in self.tables.iter().filter(|t| extrapolates(t.direction)) {
            let p = self.position_norm(t.axis, positions);
            y[usize::from(t.direction)] += t.evaluate_um(&x, p, false);
        }
        y
    }

    /// Per axis (offset µm at the reference position, slope µm/m).
    pub fn axis_pairs(&self, features: &[f64]) -> Vec<(f64, f64)> {
        let x = self.normalise(features);
        self.axes
            .iter()
            .zip(0u8..)
            .map(|(ax, a)| {
                let pr = normalise(ax.ref_pos, ax.pos_min, ax.pos_max);
                let tables = self.tables.iter().filter(|t| t.axis == Some(a));
                let (mut off, mut der) = (0.0, 0.0);
                for t in tables {
                    off += t.evaluate_um(&x, pr, false);
                    der += t.evaluate_um(&x, pr, true);
                }
                (off, der / ((ax.pos_max - ax.pos_min) / 2.0) * 1e6)
            })
            .collect()
    }

    #[allow(clippy::indexing_slicing, reason = "table axes are below axes.len()")]
    fn position_norm(&self, axis: Option<u8>, positions: &[f64]) -> f64 {
        match axis {
            Some(a) => {
                let ax = &self.axes[usize::from(a)];
                normalise(
                    positions.get(usize::from(a)).copied().unwrap_or(ax.ref_pos),
                    ax.pos_min,
                    ax.pos_max,
                )
            }
            None => 0.0,
        }
    }

    /// Quantize to the fixed-point model (validated by encoding and parsing
    /// it) and measure the worst deviation over the admissible inputs.
    pub fn quantize(&self) -> Result<(Model, QuantReport), QuantizeError> {
        let mut m = Model::empty(self.model_version, self.step_ms);
        m.warmup_s = self.warmup_s;
        m.flags = if self.fixed_reference {
            image::FLAG_FIXED_REFERENCE
        } else {
            0
        };
        let too_many = |what: &str| QuantizeError::OutOfRange {
            what: format!("number of {what}"),
            value: f64::NAN,
        };
        for s in &self.sensors {
            m.sensors.push(*s).map_err(|_| too_many("sensors"))?;
        }
        for d in &self.directions {
            let dir = Direction {
                name: image::name8(&d.name),
                max_correction: q(d.max_correction_um * 10.0, 1.0, "max correction")?,
                max_rate: q(d.max_rate_um_per_s * 10.0, 1.0, "max rate")?,
            };
            m.directions.push(dir).map_err(|_| too_many("directions"))?;
        }
        for a in &self.axes {
            let ax = Axis {
                name: image::name8(&a.name),
                pos_min: q(a.pos_min, 1.0, "axis min")?,
                pos_max: q(a.pos_max, 1.0, "axis max")?,
                ref_pos: q(a.ref_pos, 1.0, "axis reference")?,
            };
            m.axes.push(ax).map_err(|_| too_many("axes"))?;
        }
        for (i, inp) in self.inputs.iter().enumerate() {
            if inp.min.fract() != 0.0 || inp.max.fract() != 0.0 {
                return Err(QuantizeError::OutOfRange {
                    what: format!("input {i} envelope (must be whole raw units)"),
                    value: inp.min,
                });
            }
            let lag = match inp.tau_s {
                None => None,
                Some(tau) => Some(lag(tau, self.step_ms).map_err(|e| match e {
                    QuantizeError::OutOfRange { value, .. } => QuantizeError::OutOfRange {
                        what: format!("input {i} time constant"),
                        value,
                    },
                    other => other,
                })?),
            };
            let spec = InputSpec {
                kind: inp.kind,
                lag,
                min: q(inp.min, 1.0, "input min")?,
                max: q(inp.max, 1.0, "input max")?,
            };
            m.inputs.push(spec).map_err(|_| too_many("inputs"))?;
        }
        for n in &self.nets {
            if n.w1.len() > MAX_HIDDEN || n.inputs.len() > MAX_NET_INPUTS {
                return Err(too_many("net neurons"));
            }
            // (Was a panic: a row longer than the board's inputs, or fewer
            // biases or output weights than hidden neurons.)
            let shape_ok = n.b1.len() >= n.w1.len()
                && n.w2.len() >= n.w1.len()
                && n.w1.iter().all(|row| row.len() <= MAX_NET_INPUTS);
            let n_hidden = u8::try_from(n.w1.len()).ok().filter(|_| shape_ok);
            let mut net = Net::new(
                n.direction,
                &n.inputs,
                n_hidden.ok_or_else(|| too_many("net weights"))?,
            );
            let hidden = net.w1.iter_mut().zip(&mut net.b1).zip(&mut net.w2);
            for (((dst, b1), w2), ((row, &fb1), &fw2)) in
                hidden.zip(n.w1.iter().zip(&n.b1).zip(&n.w2))
            {
                for (d, w) in dst.iter_mut().zip(row) {
                    *d = q(*w, 65536.0, "W1")?;
                }
                *b1 = q(fb1, 65536.0, "b1")?;
                *w2 = q(fw2 * 10.0, 256.0, "w2")?;
            }
            net.b2 = q(n.b2 * 10.0, 256.0, "b2")?;
            m.nets.push(net).map_err(|_| too_many("nets"))?;
        }
        for t in &self.tables {
            let mut tab = Table {
                direction: t.direction,
                axis: t.axis.unwrap_or(NONE),
                terms: heapless::Vec::new(),
            };
            for term in &t.terms {
                let tm = Term {
                    coef: q(term.coef_um * 10.0, 256.0, "table coefficient")?,
                    input: term.input.unwrap_or(NONE),
                    input_power: term.input_power,
                    position_power: term.position_power,
                };
                tab.terms.push(tm).map_err(|_| too_many("table terms"))?;
            }
            m.tables.push(tab).map_err(|_| too_many("tables"))?;
        }
        for f in &self.fallbacks {
            let mut terms: heapless::Vec<Term, MAX_TERMS> = heapless::Vec::new();
            for term in &f.terms {
                let tm = Term {
                    coef: q(term.coef_um * 10.0, 256.0, "fallback coefficient")?,
                    input: term.input.unwrap_or(NONE),
                    input_power: term.input_power,
                    position_power: term.position_power,
                };
                terms.push(tm).map_err(|_| too_many("fallback terms"))?;
            }
            let ex = |i: usize| f.excluded.get(i).copied().unwrap_or(NONE);
            if f.excluded.is_empty() || f.excluded.len() > 2 {
                return Err(too_many("fallback excluded sensors"));
            }
            m.push_fallback(f.direction, [ex(0), ex(1)], &terms)
                .map_err(|_| too_many("fallbacks"))?;
        }
        let mut buf = vec![0u8; m.encoded_len()];
        m.encode(&mut buf).map_err(|_| too_many("bytes"))?;
        let model = Model::parse(&buf).map_err(QuantizeError::Image)?;
        let report = self.deviation(&model);
        Ok((model, report))
    }

    /// Worst |fixed − float| over the admissible inputs: every corner of the
    /// input box, sweeps of each input across its range with the others at
    /// the centre, and seeded random interior points; each sample lies on the
    /// board's Q8 grid so both sides see the very same input.
    #[allow(
        clippy::indexing_slicing,
        clippy::cast_possible_truncation,
        reason = "every point has n_in + n_ax coordinates and d < that; one deviation per direction; \
                  features and positions lie in the envelope, far inside i32"
    )]
    pub fn deviation(&self, model: &Model) -> QuantReport {
        let n_in = self.inputs.len();
        let n_ax = self.axes.len();
        let dims = n_in + n_ax;
        let range = |d: usize| -> (f64, f64) {
            if d < n_in {
                (self.inputs[d].min, self.inputs[d].max)
            } else {
                let a = &self.axes[d - n_in];
                (a.pos_min, a.pos_max)
            }
        };
        let mut points: Vec<Vec<f64>> = Vec::new();
        if dims <= 12 {
            for mask in 0..(1u32 << dims) {
                points.push(
                    (0..dims)
                        .map(|d| {
                            if mask >> d & 1 == 1 {
                                range(d).1
                            } else {
                                range(d).0
                            }
                        })
                        .collect(),
                );
            }
        }
        let centre: Vec<f64> = (0..dims).map(|d| (range(d).0 + range(d).1) / 2.0).collect();
        for d in 0..dims {
            for k in 0..=200 {
                let mut p = centre.clone();
                let (lo, hi) = range(d);
                p[d] = lo + (hi - lo) * f64::from(k) / 200.0;
                points.push(p);
            }
        }
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..20_000 {
            points.push(
                (0..dims)
                    .map(|d| {
                        rng ^= rng << 13;
                        rng ^= rng >> 7;
                        rng ^= rng << 17;
                        let (lo, hi) = range(d);
                        lo + (hi - lo) * ((rng >> 11) as f64 / (1u64 << 53) as f64)
                    })
                    .collect(),
            );
        }
        let mut report = QuantReport {
            max_deviation_um: vec![0.0; self.directions.len()],
            worst_features: vec![],
            worst_positions: vec![],
            samples: points.len(),
        };
        let mut worst = -1.0;
        for p in &points {
            // Features on the board's Q8 grid; positions whole µm.
            let fq: Vec<i32> = p[..n_in]
                .iter()
                .map(|v| (v * 256.0).round() as i32)
                .collect();
            let pos: Vec<i32> = p[n_in..].iter().map(|v| v.round() as i32).collect();
            let ff: Vec<f64> = fq.iter().map(|&v| f64::from(v) / 256.0).collect();
            let pf: Vec<f64> = pos.iter().map(|&v| f64::from(v)).collect();
            let fixed = model.evaluate(&fq, &pos);
            let float = self.evaluate_um(&ff, &pf);
            for (d, f) in float.iter().enumerate() {
                let dev = (f64::from(fixed.corrections[d]) / 10.0 - f).abs();
                if dev > report.max_deviation_um[d] {
                    report.max_deviation_um[d] = dev;
                }
                if dev > worst {
                    worst = dev;
                    report.worst_features = ff.clone();
                    report.worst_positions = pf.clone();
                }
            }
        }
        report
    }
}

/// The lag filter of time constant `tau_s` (seconds) for a model stepping
/// every `step_ms`: its per-step decay exp(−step/τ) in Q30, as the image
/// stores it (what the quantizer writes and what `tcomp fit` trains with).
pub fn lag(tau_s: f64, step_ms: u32) -> Result<Lag, QuantizeError> {
    if !(tau_s > 0.0 && tau_s.is_finite() && tau_s < f64::from(u32::MAX)) || step_ms == 0 {
        return Err(QuantizeError::OutOfRange {
            what: "lag time constant".to_string(),
            value: tau_s,
        });
    }
    let d = (-(f64::from(step_ms) / 1000.0) / tau_s).exp();
    #[allow(
        clippy::cast_possible_truncation,
        reason = "0 < tau_s < u32::MAX (checked above); the decay is capped below 2^30"
    )]
    Ok(Lag {
        tau_s: tau_s.round() as u32,
        decay_q30: q(d, (1u64 << 30) as f64, "lag decay")?.min((1 << 30) - 1) as u32,
    })
}

/// Round `v · scale` to i32 or say which parameter does not fit.
fn q(v: f64, scale: f64, what: &str) -> Result<i32, QuantizeError> {
    let s = (v * scale).round();
    if !s.is_finite() || s < f64::from(i32::MIN) || s > f64::from(i32::MAX) {
        return Err(QuantizeError::OutOfRange {
            what: what.to_string(),
            value: v,
        });
    }
    #[allow(
        clippy::cast_possible_truncation,
        reason = "s is within the i32 range (checked above)"
    )]
    Ok(s as i32)
}

/// A plausible demonstration model (random weights from `seed`): six sensors
/// by channel, five inputs (three temperature rises, two of them lagged, a
/// sensor difference and the lagged spindle speed), a 5-11-1 network for Z,
/// a 3-6-1 network plus a position-dependent table for X (axis X) and a
/// temperature-only table for Y. Used for golden vectors, benchmarks and the
/// demo until a fitted model is exported.
pub fn demo_model(seed: u64) -> FloatModel {
    let mut rng = seed.wrapping_mul(0x2545_F491_4F6C_DD1D) | 1;
    let mut uniform = move |lo: f64, hi: f64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        lo + (hi - lo) * ((rng >> 11) as f64 / (1u64 << 53) as f64)
    };
    let sensors = (0..6)
        .map(|c| SensorRef {
            rom: [0; 8],
            channel: c,
            ref_temp: 20 * 16,
        })
        .collect();
    let dir = |name: &str, max: f64, rate: f64| FloatDirection {
        name: name.into(),
        max_correction_um: max,
        max_rate_um_per_s: rate,
    };
    let input = |kind, tau_s, min, max| FloatInput {
        kind,
        tau_s,
        min,
        max,
    };
    let net = |direction: u8,
               inputs: Vec<u8>,
               hidden: usize,
               uniform: &mut dyn FnMut(f64, f64) -> f64| FloatNet {
        direction,
        w1: (0..hidden)
            .map(|_| inputs.iter().map(|_| uniform(-3.0, 3.0)).collect())
            .collect(),
        b1: (0..hidden).map(|_| uniform(-2.0, 2.0)).collect(),
        w2: (0..hidden).map(|_| uniform(-20.0, 20.0)).collect(),
        b2: uniform(-5.0, 5.0),
        inputs,
    };
    let nets = vec![
        net(0, vec![0, 1, 2, 3, 4], 11, &mut uniform),
        net(1, vec![0, 1, 4], 6, &mut uniform),
    ];
    let term = |coef_um, input, input_power, position_power| FloatTerm {
        coef_um,
        input,
        input_power,
        position_power,
    };
    FloatModel {
        model_version: 1,
        step_ms: 1000,
        warmup_s: 1800,
        fixed_reference: false,
        sensors,
        directions: vec![
            dir("Z", 100.0, 2.0),
            dir("X", 50.0, 1.0),
            dir("Y", 30.0, 5.0),
        ],
        axes: vec![FloatAxis {
            name: "X".into(),
            pos_min: -100_000.0,
            pos_max: 800_000.0,
            ref_pos: 0.0,
        }],
        inputs: vec![
            input(InputKind::SensorRise { a: 0 }, Some(1800.0), -16.0, 480.0),
            input(InputKind::SensorRise { a: 1 }, Some(3600.0), -16.0, 400.0),
            input(InputKind::SensorRise { a: 2 }, None, -32.0, 320.0),
            input(InputKind::SensorDiff { a: 3, b: 4 }, None, -160.0, 160.0),
            input(InputKind::Spindle, Some(2400.0), 0.0, 12_000.0),
        ],
        nets,
        tables: vec![
            FloatTable {
                direction: 1,
                axis: Some(0),
                terms: vec![
                    term(uniform(-8.0, 8.0), Some(0), 1, 1),
                    term(uniform(-8.0, 8.0), Some(1), 1, 0),
                    term(uniform(-4.0, 4.0), Some(4), 1, 2),
                ],
            },
            FloatTable {
                direction: 2,
                axis: None,
                terms: vec![
                    term(uniform(-6.0, 6.0), Some(2), 1, 0),
                    term(uniform(-3.0, 3.0), Some(3), 2, 0),
                    term(1.5, None, 0, 0),
                ],
            },
        ],
        fallbacks: vec![],
    }
}

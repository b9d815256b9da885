//! The candidate unmodelled effects: switchable physics terms with named
//! parameters, parsed from `NAME=k1:v1,k2:v2`.

use anyhow::{anyhow, bail, Result};
use serde_json::{json, Value};

/// All effect names, in the order the diagnoser tries them.
pub const EFFECT_NAMES: [&str; 8] = [
    "convection",
    "ambient_drift",
    "sensor_lag",
    "bearing_nonlinear",
    "coolant",
    "ballscrew",
    "bending",
    "sensor_offset",
];

/// Every effect the simulator knows: [`EFFECT_NAMES`] (the closed-world
/// blind benchmark's library) and `chiller`, which needs a `[coolant]`
/// circuit with a tank.
pub const ALL_EFFECT_NAMES: [&str; 9] = [
    "convection",
    "ambient_drift",
    "sensor_lag",
    "bearing_nonlinear",
    "coolant",
    "chiller",
    "ballscrew",
    "bending",
    "sensor_offset",
];

#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Free convection to air: extra conductance h·A on every node with an area.
    Convection { h_w_per_m2k: f64 },
    /// Ambient deviates from the nominal: amp·(sin(2πt/P + φ) − sin φ) + rate·t.
    AmbientDrift {
        amp_c: f64,
        phase_h: f64,
        rate_c_per_h: f64,
        period_h: f64,
    },
    /// First-order lag on one sensor's reading (every sensor when `sensor`
    /// is not given).
    SensorLag { tau_s: f64, sensor: Option<String> },
    /// Extra bearing heat k·(n/n_max)^p on every bearing node, or on
    /// `node` only.
    BearingNonlinear {
        k_w: f64,
        p: f64,
        node: Option<String>,
    },
    /// Coolant loop on the coolant nodes while `coolant_on`: conductance g to
    /// the coolant at ambient + offset + chiller sawtooth (amp, period).
    Coolant {
        g_w_per_k: f64,
        offset_c: f64,
        amp_c: f64,
        period_s: f64,
    },
    /// The chiller of the `[coolant]` circuit cycles on a thermostat with
    /// hysteresis `band_c` around the set point instead of holding it: the
    /// tank takes a constant load `load_frac·power_w` (pump, losses) and the
    /// chiller removes `power_w` while on. Starts off, tank at the set point.
    Chiller {
        band_c: f64,
        power_w: f64,
        load_frac: f64,
    },
    /// Ball-screw / axis-drive heat k·feed_activity on the ball-screw nodes.
    Ballscrew { k_w: f64 },
    /// Bending: k·(T_a − T_b) added to the configured direction.
    Bending { k_um_per_k: f64 },
    /// Bias on one sensor from `at_s` (run time) on: a constant offset
    /// when 0, a step otherwise. `run` names the one run it applies to in a
    /// diagnosis (all runs when not given; `tcomp sim` ignores it).
    SensorOffset {
        sensor: String,
        offset_c: f64,
        at_s: f64,
        run: Option<String>,
    },
}

fn num(kv: &[(String, String)], key: &str, default: Option<f64>, spec: &str) -> Result<f64> {
    let v = match kv.iter().find(|(k, _)| k == key) {
        Some((_, v)) => v
            .parse::<f64>()
            .map_err(|_| anyhow!("effect `{spec}`: `{key}` must be a number, got `{v}`"))?,
        None => default.ok_or_else(|| anyhow!("effect `{spec}`: missing parameter `{key}`"))?,
    };
    let name = spec.split_once('=').map_or(spec, |(n, _)| n).trim();
    let (lo, hi, unit) = param_range(name, key);
    super::limits::within(format_args!("effect `{spec}`: {key}"), v, lo, hi, unit)?;
    Ok(v)
}

/// What a user may ask of an effect parameter on the command line: finite
/// and of a physically possible size (listed in examples/machines/README.md).
fn param_range(effect: &str, key: &str) -> (f64, f64, &'static str) {
    match (effect, key) {
        ("convection", "h") => (0.0, 1e3, "W/(m²·K)"),
        ("ambient_drift", "amp_c") => (-50.0, 50.0, "°C"),
        ("ambient_drift", "phase_h") => (-1e4, 1e4, "h"),
        ("ambient_drift", "rate_c_per_h") => (-50.0, 50.0, "°C/h"),
        ("ambient_drift", "period_h") => (1e-3, 1e4, "h"),
        ("sensor_lag", "tau_s") => (0.0, 1e5, "s"),
        ("bearing_nonlinear", "k_w") | ("ballscrew", "k_w") => (0.0, 1e5, "W"),
        ("bearing_nonlinear", "p") => (0.0, 10.0, ""),
        ("coolant", "g_w_per_k") => (0.0, 1e6, "W/K"),
        ("coolant", "offset_c") | ("coolant", "amp_c") => (-100.0, 100.0, "°C"),
        ("coolant", "period_s") => (1.0, 1e6, "s"),
        ("chiller", "band_c") => (0.0, 50.0, "°C"),
        ("chiller", "power_w") => (0.0, 1e6, "W"),
        ("chiller", "load_frac") => (0.0, 1.0, ""),
        ("sensor_offset", "at_s") => (0.0, 1e8, "s"),
        ("bending", "k_um_per_k") => (-1e3, 1e3, "µm/K"),
        ("sensor_offset", "offset_c") => (-100.0, 100.0, "°C"),
        _ => (f64::MIN, f64::MAX, ""),
    }
}

impl Effect {
    pub fn name(&self) -> &'static str {
        match self {
            Effect::Convection { .. } => "convection",
            Effect::AmbientDrift { .. } => "ambient_drift",
            Effect::SensorLag { .. } => "sensor_lag",
            Effect::BearingNonlinear { .. } => "bearing_nonlinear",
            Effect::Coolant { .. } => "coolant",
            Effect::Chiller { .. } => "chiller",
            Effect::Ballscrew { .. } => "ballscrew",
            Effect::Bending { .. } => "bending",
            Effect::SensorOffset { .. } => "sensor_offset",
        }
    }

    /// Whether the effect changes readings only, not the machine's
    /// temperatures (`sensor_lag`, `sensor_offset`).
    pub fn is_sensor_only(&self) -> bool {
        matches!(self, Effect::SensorLag { .. } | Effect::SensorOffset { .. })
    }

    /// Parse `NAME=k1:v1,k2:v2` (or bare `NAME` for the defaults).
    pub fn parse(spec: &str) -> Result<Effect> {
        let (name, rest) = match spec.split_once('=') {
            Some((n, r)) => (n.trim(), r.trim()),
            None => (spec.trim(), ""),
        };
        let mut kv = Vec::new();
        for part in rest.split(',').filter(|p| !p.trim().is_empty()) {
            let (k, v) = part
                .split_once(':')
                .ok_or_else(|| anyhow!("effect `{spec}`: parameter `{part}` is not key:value"))?;
            kv.push((k.trim().to_string(), v.trim().to_string()));
        }
        let allowed: &[&str] = match name {
            "convection" => &["h"],
            "ambient_drift" => &["amp_c", "phase_h", "rate_c_per_h", "period_h"],
            "sensor_lag" => &["tau_s", "sensor"],
            "bearing_nonlinear" => &["k_w", "p", "node"],
            "coolant" => &["g_w_per_k", "offset_c", "amp_c", "period_s"],
            "chiller" => &["band_c", "power_w", "load_frac"],
            "ballscrew" => &["k_w"],
            "bending" => &["k_um_per_k"],
            "sensor_offset" => &["sensor", "offset_c", "at_s", "run"],
            _ => bail!(
                "unknown effect `{name}` (known: {})",
                ALL_EFFECT_NAMES.join(", ")
            ),
        };
        for (k, _) in &kv {
            if !allowed.contains(&k.as_str()) {
                bail!(
                    "effect `{name}`: unknown parameter `{k}` (known: {})",
                    allowed.join(", ")
                );
            }
        }
        let text = |key: &str| kv.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone());
        let e = match name {
            "convection" => Effect::Convection {
                h_w_per_m2k: num(&kv, "h", Some(10.0), spec)?,
            },
            "ambient_drift" => Effect::AmbientDrift {
                amp_c: num(&kv, "amp_c", Some(1.0), spec)?,
                phase_h: num(&kv, "phase_h", Some(0.0), spec)?,
                rate_c_per_h: num(&kv, "rate_c_per_h", Some(0.0), spec)?,
                period_h: num(&kv, "period_h", Some(24.0), spec)?,
            },
            "sensor_lag" => Effect::SensorLag {
                tau_s: num(&kv, "tau_s", Some(120.0), spec)?,
                sensor: text("sensor"),
            },
            "bearing_nonlinear" => Effect::BearingNonlinear {
                k_w: num(&kv, "k_w", Some(30.0), spec)?,
                p: num(&kv, "p", Some(2.0), spec)?,
                node: text("node"),
            },
            "coolant" => Effect::Coolant {
                g_w_per_k: num(&kv, "g_w_per_k", Some(15.0), spec)?,
                offset_c: num(&kv, "offset_c", Some(-1.0), spec)?,
                amp_c: num(&kv, "amp_c", Some(0.5), spec)?,
                period_s: num(&kv, "period_s", Some(900.0), spec)?,
            },
            "chiller" => Effect::Chiller {
                band_c: num(&kv, "band_c", Some(1.0), spec)?,
                power_w: num(&kv, "power_w", Some(800.0), spec)?,
                load_frac: num(&kv, "load_frac", Some(0.5), spec)?,
            },
            "ballscrew" => Effect::Ballscrew {
                k_w: num(&kv, "k_w", Some(50.0), spec)?,
            },
            "bending" => Effect::Bending {
                k_um_per_k: num(&kv, "k_um_per_k", Some(1.0), spec)?,
            },
            "sensor_offset" => Effect::SensorOffset {
                sensor: text("sensor")
                    .ok_or_else(|| anyhow!("effect `{spec}`: missing parameter `sensor`"))?,
                offset_c: num(&kv, "offset_c", Some(0.5), spec)?,
                at_s: num(&kv, "at_s", Some(0.0), spec)?,
                run: text("run"),
            },
            _ => unreachable!(),
        };
        e.validate()?;
        Ok(e)
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str| Err(anyhow!("effect `{}`: {what}", self.name()));
        match self {
            Effect::SensorLag { tau_s, .. } if !(*tau_s >= 0.0) => bad("tau_s must be ≥ 0"),
            Effect::Chiller {
                band_c,
                power_w,
                load_frac,
            } if !(*band_c >= 0.0 && *power_w >= 0.0 && (0.0..=1.0).contains(load_frac)) => {
                bad("band_c and power_w must be ≥ 0 and load_frac within 0..=1")
            }
            Effect::AmbientDrift { period_h, .. } if !(*period_h > 0.0) => {
                bad("period_h must be > 0")
            }
            Effect::Coolant {
                g_w_per_k,
                period_s,
                ..
            } if !(*g_w_per_k >= 0.0) || !(*period_s > 0.0) => {
                bad("g_w_per_k must be ≥ 0 and period_s > 0")
            }
            Effect::Convection { h_w_per_m2k } if !(*h_w_per_m2k >= 0.0) => bad("h must be ≥ 0"),
            _ => Ok(()),
        }
    }

    /// Parameters as a JSON object.
    pub fn params_json(&self) -> Value {
        match self {
            Effect::Convection { h_w_per_m2k } => json!({ "h": h_w_per_m2k }),
            Effect::AmbientDrift {
                amp_c,
                phase_h,
                rate_c_per_h,
                period_h,
            } => {
                json!({"amp_c": amp_c, "phase_h": phase_h, "rate_c_per_h": rate_c_per_h, "period_h": period_h})
            }
            Effect::SensorLag { tau_s, sensor } => match sensor {
                Some(s) => json!({ "tau_s": tau_s, "sensor": s }),
                None => json!({ "tau_s": tau_s }),
            },
            Effect::Chiller {
                band_c,
                power_w,
                load_frac,
            } => json!({"band_c": band_c, "power_w": power_w, "load_frac": load_frac}),
            Effect::BearingNonlinear { k_w, p, node } => match node {
                Some(n) => json!({"k_w": k_w, "p": p, "node": n}),
                None => json!({"k_w": k_w, "p": p}),
            },
            Effect::Coolant {
                g_w_per_k,
                offset_c,
                amp_c,
                period_s,
            } => {
                json!({"g_w_per_k": g_w_per_k, "offset_c": offset_c, "amp_c": amp_c, "period_s": period_s})
            }
            Effect::Ballscrew { k_w } => json!({ "k_w": k_w }),
            Effect::Bending { k_um_per_k } => json!({ "k_um_per_k": k_um_per_k }),
            Effect::SensorOffset {
                sensor,
                offset_c,
                at_s,
                run,
            } => {
                let mut v = json!({"sensor": sensor, "offset_c": offset_c});
                if *at_s > 0.0 {
                    v["at_s"] = json!(at_s);
                }
                if let Some(r) = run {
                    v["run"] = json!(r);
                }
                v
            }
        }
    }

    /// The `--effect` spelling of this effect (round-trips through `parse`).
    pub fn to_spec(&self) -> String {
        let p = self.params_json();
        let mut parts = Vec::new();
        if let Some(o) = p.as_object() {
            for (k, v) in o {
                match v {
                    Value::String(s) => parts.push(format!("{k}:{s}")),
                    other => parts.push(format!("{k}:{other}")),
                }
            }
        }
        format!("{}={}", self.name(), parts.join(","))
    }
}

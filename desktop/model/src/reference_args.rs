//! The flags of `tcomp replay`'s probe references and re-zeros, as typed
//! ([`ReferenceArgs`]), and their parsing into the math core's rule
//! parameters, the board's ask rule and times ([`crate::reference_replay`]
//! runs them).

use anyhow::{anyhow, bail, Result};
use thermocomp_core::ask::AskParams;
use thermocomp_core::reference::ReferenceParams;

/// The references and re-zeros `tcomp replay` simulates, as its flags give
/// them (text as typed; parsed here).
#[derive(Debug, Clone, Default)]
pub struct ReferenceArgs {
    /// Simulate a probe reference at the gauge every this long (`1h`,
    /// `30min`, `900s`, `900`), from the run's start.
    pub every: Option<String>,
    /// Shift the clock schedule: the first reference this long after the
    /// run's start, then every `--reference-every` (`10min`; below the
    /// interval). 0 (the default): the first at one interval. Clock phase
    /// moves the figures a lot (a reference minutes before a speed change
    /// teaches little): compare schedules over several phases.
    pub phase: Option<String>,
    /// Also simulate a reference this long after every change of the run's
    /// `spindle_rpm` (a probing cycle triggered by the operating state
    /// rather than the clock), e.g. `10min`.
    pub after_change: Option<String>,
    /// σ of the simulated probe noise, µm (also the rule's σ_r unless
    /// `--reference-param sigma_ref_um=` says otherwise).
    pub noise_um: f64,
    /// Corrupt a share of the references: `5%:50` = 5 % of them +50 µm.
    pub outliers: Option<String>,
    /// Seed of the simulated noise and outliers.
    pub seed: u64,
    /// Operator re-zero (touch-off) at this time: seconds of the run or a
    /// percentage of its rows (`60%`); repeatable.
    pub rezero_at: Vec<String>,
    /// A parameter of the update rule, NAME=VALUE: sigma_ref_um,
    /// sigma_bias_um, tau_bias_h, sigma_rate_um_h, tau_rate_h, gate_k,
    /// gate_abs_um, max_step_um, max_bias_um, max_rate_um_h; repeatable.
    pub params: Vec<String>,
    /// Write every row (time, per direction: measured, model, served with
    /// references) to this CSV.
    pub dump: Option<std::path::PathBuf>,
    /// Probe when the board asks, by its rule with these parameters
    /// (`--reference-when-asked`; [`ask_params`] reads the flags). Not
    /// with a clock schedule.
    pub when_asked: Option<AskParams>,
}

impl ReferenceArgs {
    /// Any reference or re-zero asked for.
    pub fn is_active(&self) -> bool {
        self.every.is_some()
            || self.after_change.is_some()
            || self.when_asked.is_some()
            || !self.rezero_at.is_empty()
    }
}

/// The board's asking rule from `--ask-settle`, `--ask-interval` (durations,
/// `0` switches that part off) and `--ask-speed-step` (rpm); each not given
/// is [`AskParams::SUGGESTED`]'s.
pub fn ask_params(
    settle: Option<&str>,
    interval: Option<&str>,
    speed_step_rpm: Option<u16>,
) -> Result<AskParams> {
    let secs = |flag: &str, v: Option<&str>, default: u16| -> Result<u16> {
        let Some(v) = v.map(str::trim) else {
            return Ok(default);
        };
        if v.trim_end_matches(['s', 'h'])
            .trim_end_matches("min")
            .trim()
            == "0"
        {
            return Ok(0);
        }
        let s = parse_duration_s(v).map_err(|e| anyhow!("{flag} {e}"))?;
        if s.round() > f64::from(u16::MAX) || s.round() < 1.0 {
            bail!("{flag} {v}: between 1 s and 18 h (65535 s), or 0 (off)");
        }
        Ok(s.round() as u16)
    };
    let d = AskParams::SUGGESTED;
    Ok(AskParams {
        settle_s: secs("--ask-settle", settle, d.settle_s)?,
        max_interval_s: secs("--ask-interval", interval, d.max_interval_s)?,
        speed_step_rpm: speed_step_rpm.unwrap_or(d.speed_step_rpm),
    })
}

/// Parse a duration: `1h`, `4h`, `30min`, `90s`, `900` (seconds).
pub fn parse_duration_s(text: &str) -> Result<f64> {
    let t = text.trim();
    let (num, scale) = if let Some(v) = t.strip_suffix("min") {
        (v, 60.0)
    } else if let Some(v) = t.strip_suffix('h') {
        (v, 3600.0)
    } else if let Some(v) = t.strip_suffix("ms") {
        (v, 0.001)
    } else if let Some(v) = t.strip_suffix('s') {
        (v, 1.0)
    } else {
        (t, 1.0)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| anyhow!("{text}: expected a duration such as 1h, 30min, 900s"))?;
    if !(v > 0.0 && v.is_finite()) {
        bail!("{text}: a duration must be above 0");
    }
    Ok(v * scale)
}

fn um_to_nm(v: f64, name: &str) -> Result<u32> {
    if !(v >= 0.0 && v * 1000.0 <= f64::from(u32::MAX)) {
        bail!("--reference-param {name}: {v} out of range");
    }
    Ok((v * 1000.0).round() as u32)
}

fn hours_to_s(v: f64, name: &str) -> Result<u32> {
    if !(v > 0.0 && v * 3600.0 <= f64::from(u32::MAX)) {
        bail!("--reference-param {name}: {v} out of range");
    }
    Ok((v * 3600.0).round().max(1.0) as u32)
}

/// The rule's parameters: the core's defaults, σ_r from the simulated
/// noise, then each `NAME=VALUE`.
pub fn parse_params(args: &ReferenceArgs) -> Result<ReferenceParams> {
    let mut p = ReferenceParams::DEFAULT;
    p.sigma_ref_nm = um_to_nm(args.noise_um, "reference-noise-um")?;
    for spec in &args.params {
        let (name, value) = spec
            .split_once('=')
            .ok_or_else(|| anyhow!("--reference-param {spec}: expected NAME=VALUE"))?;
        let (name, value) = (name.trim(), value.trim());
        let v: f64 = value
            .parse()
            .map_err(|_| anyhow!("--reference-param {spec}: {value} is not a number"))?;
        match name {
            "sigma_ref_um" => p.sigma_ref_nm = um_to_nm(v, name)?,
            "sigma_bias_um" => p.sigma_bias_nm = um_to_nm(v, name)?,
            "tau_bias_h" => p.tau_bias_s = hours_to_s(v, name)?,
            "sigma_rate_um_h" => p.sigma_rate_nm_h = um_to_nm(v, name)?,
            "tau_rate_h" => p.tau_rate_s = hours_to_s(v, name)?,
            "gate_k" => {
                if !(0.0..=6000.0).contains(&v) {
                    bail!("--reference-param {spec}: gate_k out of range 0-6000");
                }
                p.gate_k_x10 = (v * 10.0).round() as u16
            }
            "gate_abs_um" => p.gate_abs_nm = um_to_nm(v, name)?,
            "max_step_um" => p.max_step_nm = um_to_nm(v, name)?,
            "max_bias_um" => p.max_bias_nm = um_to_nm(v, name)?,
            "max_rate_um_h" => p.max_rate_nm_h = um_to_nm(v, name)?,
            _ => bail!(
                "--reference-param {spec}: unknown parameter {name} (sigma_ref_um, sigma_bias_um, tau_bias_h, sigma_rate_um_h, tau_rate_h, gate_k, gate_abs_um, max_step_um, max_bias_um, max_rate_um_h)"
            ),
        }
    }
    Ok(p.sanitised())
}

/// `5%:50` → (0.05, 50.0).
pub fn parse_outliers(spec: &str) -> Result<(f64, f64)> {
    let (share, um) = spec
        .split_once(':')
        .ok_or_else(|| anyhow!("--reference-outliers {spec}: expected SHARE%:UM, e.g. 5%:50"))?;
    let share: f64 = share
        .trim()
        .trim_end_matches('%')
        .parse()
        .map_err(|_| anyhow!("--reference-outliers {spec}: bad share"))?;
    let um: f64 = um
        .trim()
        .parse()
        .map_err(|_| anyhow!("--reference-outliers {spec}: bad offset"))?;
    if !(0.0..=100.0).contains(&share) || !um.is_finite() {
        bail!("--reference-outliers {spec}: share 0-100 %, a finite offset");
    }
    Ok((share / 100.0, um))
}

/// A time of the run: seconds or a percentage of its rows (as `--fail-sensor`).
pub(crate) fn parse_time_ms(spec: &str, time_s: &[f64]) -> Result<u64> {
    let at = spec.trim();
    if let Some(p) = at.strip_suffix('%') {
        let p: f64 = p
            .trim()
            .parse()
            .map_err(|_| anyhow!("--reference-at {spec}: not a percentage"))?;
        if !(0.0..=100.0).contains(&p) {
            bail!("--reference-at {spec}: percentage outside 0-100");
        }
        let row = ((p / 100.0) * time_s.len() as f64) as usize;
        Ok(time_s
            .get(row)
            .map_or(u64::MAX, |s| (s * 1000.0).round() as u64))
    } else {
        let s = parse_duration_s(at).or_else(|e| {
            if at.trim_end_matches('s').trim().parse::<f64>() == Ok(0.0) {
                Ok(0.0)
            } else {
                Err(e)
            }
        })?;
        Ok((s * 1000.0).round() as u64)
    }
}

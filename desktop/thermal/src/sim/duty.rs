//! Duty cycles: piecewise-constant spindle speed, axis activity, coolant and
//! ambient. From a TOML segment list (`examples/duty/*.toml`) or a CSV with
//! `time_s` and any of `spindle_rpm|rpm`, `feed_activity|feed`,
//! `coolant_on|coolant`, `ambient_c|T_ambient` (a run CSV is a valid duty).

use anyhow::{anyhow, bail, Context, Result};
use serde::Deserialize;
use std::path::Path;

use super::limits;

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct DutyFile {
    name: Option<String>,
    #[serde(default)]
    description: String,
    #[serde(default)]
    sample_period_s: Option<f64>,
    /// Repeat the segment list this many times.
    #[serde(default)]
    repeat: Option<usize>,
    #[serde(rename = "segment")]
    segments: Vec<Segment>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct Segment {
    #[serde(default)]
    duration_s: Option<f64>,
    #[serde(default)]
    duration_min: Option<f64>,
    #[serde(default)]
    rpm: f64,
    #[serde(default)]
    feed: f64,
    #[serde(default)]
    coolant: f64,
    #[serde(default)]
    ambient_c: Option<f64>,
}

/// Breakpoints: value `i` holds from `t[i]` to `t[i+1]` (the last to `end_s`).
#[derive(Clone, Debug, Default)]
pub struct Duty {
    pub name: String,
    pub t: Vec<f64>,
    pub rpm: Vec<f64>,
    pub feed: Vec<f64>,
    pub coolant: Vec<f64>,
    pub ambient: Vec<Option<f64>>,
    pub end_s: f64,
    pub sample_period_s: Option<f64>,
}

/// Uniform input grid for the simulator: row `k` at `t0 + k·dt`, inputs
/// applied over `[t_k, t_k + dt)`.
#[derive(Clone, Debug)]
pub struct Inputs {
    pub t0: f64,
    pub dt: f64,
    pub rpm: Vec<f64>,
    pub feed: Vec<f64>,
    pub coolant: Vec<f64>,
    /// Absolute ambient [°C] (the nominal, known ambient).
    pub ambient: Vec<f64>,
}

impl Inputs {
    pub fn len(&self) -> usize {
        self.rpm.len()
    }
    pub fn is_empty(&self) -> bool {
        self.rpm.is_empty()
    }
    pub fn time(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }
}

impl Duty {
    pub fn load(path: &Path) -> Result<Duty> {
        let is_toml = path.extension().and_then(|e| e.to_str()) == Some("toml");
        let text = if is_toml {
            super::limits::read_toml_text(path, "duty file")?
        } else {
            std::fs::read_to_string(path)
                .with_context(|| format!("cannot read duty file {}", path.display()))?
        };
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("duty")
            .to_string();
        let d = if is_toml {
            Duty::from_toml(&text, &name)
        } else {
            Duty::from_csv(&text, &name)
        };
        d.with_context(|| format!("in duty file {}", path.display()))
    }

    pub fn from_toml(text: &str, default_name: &str) -> Result<Duty> {
        let f: DutyFile = toml::from_str(text).map_err(|e| limits::toml_error(text, &e))?;
        let _ = &f.description;
        if f.segments.is_empty() {
            bail!("no [[segment]]");
        }
        let repeat = f.repeat.unwrap_or(1);
        if !(1..=limits::MAX_DUTY_SEGMENTS).contains(&repeat) {
            bail!(
                "repeat = {repeat}: allowed 1..={}",
                limits::MAX_DUTY_SEGMENTS
            );
        }
        limits::count(
            "segments with repeat",
            f.segments.len().saturating_mul(repeat),
            limits::MAX_DUTY_SEGMENTS,
        )?;
        if let Some(p) = f.sample_period_s {
            limits::within("sample_period_s", p, 1.0, limits::MAX_SAMPLE_PERIOD_S, "s")?;
        }
        let (t_lo, t_hi) = tcomp_data::runcsv::TEMPERATURE_RANGE_C;
        let max_s = limits::MAX_SIM_HOURS * 3600.0;
        for (i, s) in f.segments.iter().enumerate() {
            let key = |k: &str| format!("segment {}: {k}", i + 1);
            if let Some(d) = s.duration_s {
                limits::positive(key("duration_s"), d, max_s, "s")?;
            }
            if let Some(m) = s.duration_min {
                limits::positive(key("duration_min"), m, max_s / 60.0, "min")?;
            }
            limits::within(
                key("rpm"),
                s.rpm,
                0.0,
                tcomp_data::runcsv::MAX_SPINDLE_RPM,
                "rpm",
            )?;
            limits::within(key("feed"), s.feed, 0.0, 1.0, "")?;
            limits::within(key("coolant"), s.coolant, 0.0, 1.0, "")?;
            if let Some(a) = s.ambient_c {
                limits::within(key("ambient_c"), a, t_lo, t_hi, "°C")?;
            }
        }
        let mut d = Duty {
            name: f.name.unwrap_or_else(|| default_name.to_string()),
            sample_period_s: f.sample_period_s,
            ..Default::default()
        };
        let mut t = 0.0;
        for _ in 0..repeat {
            for (i, s) in f.segments.iter().enumerate() {
                let dur = match (s.duration_s, s.duration_min) {
                    (Some(x), None) => x,
                    (None, Some(m)) => m * 60.0,
                    _ => bail!(
                        "segment {}: give exactly one of duration_s, duration_min",
                        i + 1
                    ),
                };
                if !(dur > 0.0) || s.rpm < 0.0 || !(0.0..=1.0).contains(&s.feed) {
                    bail!(
                        "segment {}: need duration > 0, rpm ≥ 0, 0 ≤ feed ≤ 1",
                        i + 1
                    );
                }
                d.t.push(t);
                d.rpm.push(s.rpm);
                d.feed.push(s.feed);
                d.coolant.push(if s.coolant > 0.5 { 1.0 } else { 0.0 });
                d.ambient.push(s.ambient_c);
                t += dur;
            }
        }
        d.end_s = t;
        if t > max_s {
            bail!(
                "the duty lasts {:.1} h: at most {} h",
                t / 3600.0,
                limits::MAX_SIM_HOURS
            );
        }
        Ok(d)
    }

    pub fn from_csv(text: &str, name: &str) -> Result<Duty> {
        let run = tcomp_data::runcsv::Run::from_reader(std::io::Cursor::new(text))?;
        Duty::from_run(&run, name)
    }

    /// The duty of a run file (spindle_rpm, feed_activity, coolant_on, and
    /// `T_ambient`/`ambient_c` when present). Missing values hold the last one.
    pub fn from_run(run: &tcomp_data::runcsv::Run, name: &str) -> Result<Duty> {
        let t = run.time_s();
        if t.len() < 2 {
            bail!("duty needs at least two rows");
        }
        let pick = |names: &[&str]| names.iter().find_map(|n| run.col(n));
        let rpm =
            pick(&["spindle_rpm", "rpm"]).ok_or_else(|| anyhow!("no `spindle_rpm` column"))?;
        let fill = |c: Option<&[Option<f64>]>, dflt: f64| -> Vec<f64> {
            let mut last = dflt;
            (0..t.len())
                .map(|i| {
                    if let Some(v) = c.and_then(|c| c[i]) {
                        last = v;
                    }
                    last
                })
                .collect()
        };
        // The run reader checks the format's own columns; the duty's short
        // spellings are checked here.
        let (t_lo, t_hi) = tcomp_data::runcsv::TEMPERATURE_RANGE_C;
        for (col, lo, hi, unit) in [
            ("rpm", 0.0, tcomp_data::runcsv::MAX_SPINDLE_RPM, "rpm"),
            ("feed", 0.0, 1.0, ""),
            ("coolant", 0.0, 1.0, ""),
            ("ambient_c", t_lo, t_hi, "°C"),
        ] {
            for (r, v) in run.col(col).unwrap_or(&[]).iter().enumerate() {
                if let Some(v) = v {
                    limits::within(
                        format_args!("row {}, column `{col}`", r + 1),
                        *v,
                        lo,
                        hi,
                        unit,
                    )?;
                }
            }
        }
        let amb_col = pick(&["ambient_c", "T_ambient"]);
        let dt_last = t[t.len() - 1] - t[t.len() - 2];
        Ok(Duty {
            name: name.to_string(),
            rpm: fill(Some(rpm), 0.0),
            feed: fill(pick(&["feed_activity", "feed"]), 0.0),
            coolant: fill(pick(&["coolant_on", "coolant"]), 0.0),
            ambient: match amb_col {
                Some(c) => {
                    let f = fill(Some(c), f64::NAN);
                    f.into_iter()
                        .map(|v| if v.is_nan() { None } else { Some(v) })
                        .collect()
                }
                None => vec![None; t.len()],
            },
            end_s: t[t.len() - 1] + dt_last,
            sample_period_s: Some(dt_last),
            t,
        })
    }

    /// One input row per breakpoint (for duties read from a uniformly
    /// sampled run; dt = the median breakpoint spacing).
    pub fn inputs_rows(&self, ambient_c: f64) -> Inputs {
        let mut d: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).collect();
        d.sort_by(|a, b| a.total_cmp(b));
        let dt = d.get(d.len() / 2).copied().unwrap_or(1.0);
        Inputs {
            t0: self.t.first().copied().unwrap_or(0.0),
            dt,
            rpm: self.rpm.clone(),
            feed: self.feed.clone(),
            coolant: self.coolant.clone(),
            ambient: self
                .ambient
                .iter()
                .map(|a| a.unwrap_or(ambient_c))
                .collect(),
        }
    }

    /// Sample onto a uniform grid of `dt` for `duration_s` (default: the
    /// duty's length); the duty's last segment holds beyond its end.
    pub fn inputs(&self, dt: f64, duration_s: Option<f64>, ambient_c: f64) -> Inputs {
        let dur = duration_s.unwrap_or(self.end_s - self.t.first().copied().unwrap_or(0.0));
        let t0 = self.t.first().copied().unwrap_or(0.0);
        let k = ((dur / dt) + 1e-9).floor().max(1.0) as usize;
        let mut inp = Inputs {
            t0,
            dt,
            rpm: Vec::with_capacity(k),
            feed: Vec::with_capacity(k),
            coolant: Vec::with_capacity(k),
            ambient: Vec::with_capacity(k),
        };
        let mut j = 0;
        for i in 0..k {
            let t = t0 + i as f64 * dt;
            while j + 1 < self.t.len() && self.t[j + 1] <= t + 1e-9 {
                j += 1;
            }
            inp.rpm.push(self.rpm[j]);
            inp.feed.push(self.feed[j]);
            inp.coolant.push(self.coolant[j]);
            inp.ambient.push(self.ambient[j].unwrap_or(ambient_c));
        }
        inp
    }
}

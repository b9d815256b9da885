//! Command-line arguments of `tcomp fit` (used by `main.rs`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use tcomp_model::fit::net::NetOpts;
use tcomp_model::fit::parse_feature;
use tcomp_model::fit::pipeline::{self as run, Candidates, FeatureChoice, FitConfig};
use tcomp_model::probe_drift;

#[derive(clap::Args, Debug, Clone)]
pub struct FitArgs {
    /// Training runs (run CSVs); none with `--probe-drift` alone.
    #[arg(required_unless_present_any = ["probe_drift", "probe_drift_um_per_k"])]
    pub train: Vec<PathBuf>,
    /// Estimate the probe's own temperature drift (µm/K, the board's holding
    /// register 43) from this run, recorded with the target not moving
    /// (`probe_raw_um` or `dprobe_um` against `--probe-channel`).
    #[arg(long, value_name = "RUN", requires = "probe_channel")]
    pub probe_drift: Option<PathBuf>,
    /// The probe's drift given (µm/K) instead of estimated.
    #[arg(
        long,
        value_name = "UM_PER_K",
        conflicts_with = "probe_drift",
        allow_hyphen_values = true
    )]
    pub probe_drift_um_per_k: Option<f64>,
    /// The temperature column of the DS18B20 beside the probe (e.g. T05).
    #[arg(long, value_name = "COLUMN")]
    pub probe_channel: Option<String>,
    /// Held-out runs to validate on (never trained on).
    #[arg(long, num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// Chronological split of each training run: train on [0,a), validate on [a,b).
    #[arg(long, value_name = "A,B")]
    pub split_chrono: Option<String>,
    /// `auto`, or a comma list: `T_t3`, `T_t3@3600` (lag s), `T_t3-T_t5`, `rpm@1800`.
    #[arg(long, default_value = "auto")]
    pub features: String,
    /// Candidate lags for `auto`, seconds (0 = no lag).
    #[arg(long, default_value = "0,1800,3600,7200,10800,21600")]
    pub lags: String,
    /// Also choose each chosen input's lag by forward-chaining CV on the
    /// training rows among these lags, seconds: `geometric` (0, 225 s · 2^k
    /// up to 8 h) or a comma list; off by default.
    #[arg(long, value_name = "LAGS")]
    pub lag_grid: Option<String>,
    /// `auto` candidates: `selected` (sensors chosen by `select`) or `all`.
    #[arg(long, default_value = "selected")]
    pub candidates: String,
    /// Maximum number of inputs for `auto` (≤ 8).
    #[arg(long, default_value_t = 5)]
    pub max_inputs: usize,
    /// Sensor groups for the selection.
    #[arg(long, default_value_t = 5)]
    pub groups: usize,
    /// Channels to fit (comma list; default all `d..._um`).
    #[arg(long)]
    pub channels: Option<String>,
    /// The candidate sensors of `--features auto`, e.g. `T_a,T_b` (`select`'s
    /// picks; no new selection): comma list of temperature columns.
    #[arg(long, value_name = "T_a,T_b")]
    pub sensors: Option<String>,
    /// The candidate sensors from `tcomp select --json` output (its
    /// `chosen` list); with `--sensors`, both.
    #[arg(long, value_name = "SELECT_JSON")]
    pub sensors_from: Option<PathBuf>,
    /// Blocked cross-validation folds over the training time for `auto` (1: last 15 % only).
    #[arg(long, default_value_t = 5)]
    pub select_folds: usize,
    /// Hidden units of each network (1..=16).
    #[arg(long, default_value_t = 11)]
    pub hidden: usize,
    /// Seed of the networks' genetic algorithm (the ensemble's members use seed, seed+1, …).
    #[arg(long, default_value_t = 3)]
    pub seed: u64,
    /// Genetic algorithm: individuals per generation (at least 4).
    #[arg(long, default_value_t = 30)]
    pub population: usize,
    /// Genetic algorithm: generations before Levenberg–Marquardt.
    #[arg(long, default_value_t = 30)]
    pub generations: usize,
    /// Maximum Levenberg–Marquardt steps.
    #[arg(long, default_value_t = 300)]
    pub lm_iters: usize,
    /// L2 weight penalty (normalized units).
    #[arg(long, default_value_t = 1e-5)]
    pub l2: f64,
    /// GA-BPN ensemble size per channel (seeds seed, seed+1, ...): the board
    /// serves the members' mean (all channels' networks share the board's limit).
    #[arg(long, default_value_t = 4)]
    pub ensemble: usize,
    /// A simpler model is chosen when its cross-validated RMS is within this
    /// fraction of the best.
    #[arg(long, default_value_t = 0.02)]
    pub choice_margin: f64,
    /// After early stopping, retrain each network on all training rows for
    /// the best number of steps (by default the early-stopped weights are kept).
    #[arg(long)]
    pub refit_full: bool,
    /// Only the MLR models.
    #[arg(long)]
    pub mlr_only: bool,
    /// Also fit and cross-validate the hybrid candidate (lagged MLR +
    /// networks on its residual; off by default: it never won the
    /// cross-validation on FL_THERMAL and doubles the network time).
    #[arg(long)]
    pub hybrid: bool,
    /// Also score and offer the blend `w·mlr + (1−w)·ga-bpn` (weight `w`
    /// from the cross-validation's out-of-fold predictions; scores the
    /// network on every fold; off by default: on FL_THERMAL it wins the
    /// training CV on ch5 for some seeds and loses on the test block).
    #[arg(long)]
    pub blend: bool,
    /// Do not fit or offer the ridge candidate (ridge on the lagged MLR's
    /// inputs, its penalty chosen by forward-chaining time-blocked CV).
    #[arg(long)]
    pub no_ridge: bool,
    /// Cross-validate every network candidate on every fold (by default one
    /// is dropped as soon as its error bound shows it cannot be chosen).
    #[arg(long)]
    pub full_cv: bool,
    /// Do not fit fallback models (degraded mode: models without each model sensor).
    #[arg(long)]
    pub no_fallbacks: bool,
    /// Also fit fallbacks without each pair of a channel's model sensors.
    #[arg(long, conflicts_with = "no_fallbacks")]
    pub fallback_pairs: bool,
    /// Write the fitted models (MLR and networks, JSON).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub accept: super::sanity::AcceptArgs,
    /// Print the report as JSON (`chosen`, `shipped`, `notes`, the figures).
    #[arg(long)]
    pub json: bool,
}

/// `fit`'s long help: an example.
pub const EXAMPLE: &str = "Example:
  tcomp select warmup.csv --json > select.json
  tcomp fit warmup.csv --validate shift.csv --sensors-from select.json --out fit.json
  tcomp export --model fit.json --run warmup.csv -o model.img";

fn parse_list(s: &str, what: &str) -> Result<Vec<f64>> {
    s.split(',')
        .filter(|t| !t.trim().is_empty())
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .with_context(|| format!("{what}: `{t}` is not a number"))
        })
        .collect()
}

impl FitArgs {
    pub fn config(&self) -> Result<FitConfig> {
        let mut cfg = FitConfig::default();
        if let Some(s) = &self.split_chrono {
            let v = parse_list(s, "--split-chrono")?;
            if v.len() != 2 {
                bail!("--split-chrono needs two fractions a,b (e.g. 0.6,0.8), got `{s}`");
            }
            cfg.split_chrono = Some((v[0], v[1]));
        }
        cfg.features = if self.features.trim() == "auto" {
            FeatureChoice::Auto
        } else {
            FeatureChoice::List(
                self.features
                    .split(',')
                    .map(parse_feature)
                    .collect::<Result<_>>()?,
            )
        };
        cfg.lags = parse_list(&self.lags, "--lags")?;
        if cfg.lags.is_empty() || cfg.lags.iter().any(|l| *l < 0.0) {
            bail!("--lags: give one or more lags ≥ 0 s");
        }
        cfg.lag_grid = match self.lag_grid.as_deref().map(str::trim) {
            None => vec![],
            Some("geometric") => tcomp_model::fit::lags::LAG_GRID.to_vec(),
            Some(l) => {
                let v = parse_list(l, "--lag-grid")?;
                if v.is_empty() || v.iter().any(|l| *l < 0.0) {
                    bail!("--lag-grid: give `geometric` or one or more lags ≥ 0 s");
                }
                v
            }
        };
        cfg.candidates = match self.candidates.as_str() {
            "selected" => Candidates::Selected,
            "all" => Candidates::All,
            o => bail!("--candidates must be `selected` or `all`, got `{o}`"),
        };
        cfg.max_inputs = self.max_inputs;
        cfg.groups = self.groups;
        cfg.select_folds = self.select_folds;
        cfg.channels = self
            .channels
            .as_ref()
            .map(|c| c.split(',').map(|s| s.trim().to_string()).collect());
        cfg.net = NetOpts {
            hidden: self.hidden,
            seed: self.seed,
            population: self.population.max(4),
            generations: self.generations,
            lm_iters: self.lm_iters,
            refit_full: self.refit_full,
            l2: self.l2,
            ensemble: self.ensemble.max(1),
            ..NetOpts::default()
        };
        if !(self.choice_margin >= 0.0 && self.choice_margin < 1.0) {
            bail!(
                "--choice-margin must be in [0, 1), got {}",
                self.choice_margin
            );
        }
        cfg.choice_margin = self.choice_margin;
        cfg.skip_net = self.mlr_only;
        cfg.hybrid = self.hybrid;
        cfg.cv_drop = !self.full_cv;
        cfg.blend = self.blend;
        cfg.ridge = !self.no_ridge;
        cfg.fallbacks = !self.no_fallbacks;
        cfg.fallback_pairs = self.fallback_pairs;
        cfg.sensors = self.picked_sensors()?;
        Ok(cfg)
    }

    /// `--sensors` and `--sensors-from`, in that order, each once.
    fn picked_sensors(&self) -> Result<Option<Vec<String>>> {
        let mut picked: Vec<String> = Vec::new();
        if let Some(s) = &self.sensors {
            picked.extend(s.split(',').map(|t| t.trim().to_string()));
        }
        if let Some(p) = &self.sensors_from {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--sensors-from: cannot read {}", p.display()))?;
            let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
                anyhow::anyhow!(
                    "--sensors-from {}: not JSON ({e}); write it with `tcomp select --json`",
                    p.display()
                )
            })?;
            let chosen = v["chosen"].as_array().ok_or_else(|| {
                anyhow::anyhow!(
                    "--sensors-from {}: no `chosen` list: not `tcomp select --json` output",
                    p.display()
                )
            })?;
            for c in chosen {
                let c = c.as_str().ok_or_else(|| {
                    anyhow::anyhow!(
                        "--sensors-from {}: `chosen` holds {c}, not a sensor name",
                        p.display()
                    )
                })?;
                picked.push(c.to_string());
            }
        }
        if self.sensors.is_none() && self.sensors_from.is_none() {
            return Ok(None);
        }
        picked.retain(|s| !s.is_empty());
        let mut out: Vec<String> = Vec::new();
        for s in picked {
            if !out.contains(&s) {
                out.push(s);
            }
        }
        Ok(Some(out))
    }
}

/// `tcomp fit`.
pub fn main(args: FitArgs) -> Result<()> {
    let drift = probe_drift(&args)?;
    if args.train.is_empty() {
        // The probe's drift alone.
        let Some(d) = drift else {
            bail!("no training runs");
        };
        if args.json {
            println!("{}", serde_json::json!({ "probe_drift": d }));
        } else {
            d.print();
        }
        return Ok(());
    }
    let cfg = args.config()?;
    if args.split_chrono.is_some() && args.train.len() != 1 && args.validate.is_empty() {
        // Allowed, but say what happens.
        eprintln!("note: --split-chrono applies to each training run");
    }
    let mut runs = Vec::new();
    for (i, p) in args.train.iter().chain(&args.validate).enumerate() {
        let label = p.display().to_string();
        let r = tcomp_data::runcsv::Run::read(p)?;
        let (command, why) = if i < args.train.len() {
            ("fit", "too few to fit a model and cross-validate it")
        } else {
            ("fit --validate", "an RMS over fewer rows says nothing")
        };
        super::sanity::require_rows(&label, &r, command, why)?;
        runs.push((label, r));
    }
    super::sanity::check_runs(runs.iter().map(|(l, r)| (l.as_str(), r)), &args.accept)?;
    // The bar on the terminal, unless the output is JSON.
    let bar = super::progress::Bar::default();
    let progress: &dyn run::Progress = if args.json { &run::Silent } else { &bar };
    let report = run::fit_runs(runs, args.train.len(), &cfg, progress)?;
    if let Some(out) = &args.out {
        let text = serde_json::to_string_pretty(&report.model_file)?;
        std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))?;
    }
    if args.json {
        let mut v = run::report_json(&report);
        if let (Some(d), Some(o)) = (&drift, v.as_object_mut()) {
            o.insert("probe_drift".into(), serde_json::to_value(d)?);
        }
        if let Some(o) = v.as_object_mut() {
            let ev = serde_json::to_value(&report.model_file.envelope)?;
            o.insert("envelope".into(), ev);
        }
        println!("{v}");
    } else {
        run::print_report(&report);
        for (ch, ev) in &report.model_file.envelope {
            println!("envelope {ch}: {}", ev.why());
        }
        if let Some(d) = &drift {
            d.print();
        }
        if let Some(out) = &args.out {
            println!("\nwrote {}", out.display());
        }
    }
    Ok(())
}

/// `--probe-drift RUN` / `--probe-drift-um-per-k K` with `--probe-channel`.
fn probe_drift(args: &FitArgs) -> Result<Option<probe_drift::ProbeDrift>> {
    let channel = args.probe_channel.as_deref().unwrap_or("T?");
    match (&args.probe_drift, args.probe_drift_um_per_k) {
        (Some(path), _) => {
            let run = tcomp_data::runcsv::Run::read(path)
                .with_context(|| format!("reading {}", path.display()))?;
            Ok(Some(probe_drift::estimate(&run, channel)?))
        }
        (None, Some(k)) => Ok(Some(probe_drift::given(channel, k)?)),
        (None, None) => Ok(None),
    }
}

//! `tcomp export`: a fitted model (or the demo model), optionally with the
//! volumetric section, quantized into the board's model image.

use anyhow::Context;

#[derive(clap::Args)]
pub struct ExportArgs {
    /// Export the built-in demonstration model (random weights from --seed).
    #[arg(long)]
    pub demo: bool,
    /// Fitted parameters written by `tcomp fit --out`.
    #[arg(long, conflicts_with = "demo")]
    pub model: Option<std::path::PathBuf>,
    /// A run CSV whose T_ columns give the board's channel order.
    #[arg(long, requires = "model")]
    pub run: Option<std::path::PathBuf>,
    /// Per-channel override of the fit's cross-validated choice, e.g.
    /// `dch3_um=ga-bpn,dch5_um=mlr` (ga-bpn alias net, hybrid, mlr, mlr-static, ridge).
    #[arg(long, default_value = "")]
    pub r#use: String,
    /// Largest correction the board serves per direction (µm); beyond, it
    /// serves this and flags the row clamped.
    #[arg(long, default_value_t = 200.0)]
    pub max_correction_um: f64,
    /// Largest change of the served correction (µm/s); faster changes are
    /// rate limited and flagged.
    #[arg(long, default_value_t = 1.0)]
    pub max_rate_um_per_s: f64,
    /// The image's model version (the board takes only a newer one unless
    /// `upload --rollback`).
    #[arg(long, default_value_t = 1)]
    pub model_version: u32,
    /// Seed of the `--demo` model's random weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Add the volumetric correction: the JSON of `tcomp geometry table
    /// --json` (image section kind 3; its sensors are found by name
    /// among the --run file's T_ columns).
    #[arg(long)]
    pub geometry: Option<std::path::PathBuf>,
    /// Tool length at full scale of the volumetric section (mm); longer
    /// tools are held there and flagged.
    #[arg(long, default_value_t = 500.0, requires = "geometry")]
    pub tool_max_mm: f64,
    /// Machine position (mm) of the volumetric polynomial's zero, per axis: x,y,z.
    #[arg(long, default_value = "0,0,0", requires = "geometry")]
    pub geometry_origin_mm: String,
    /// Add the five-axis section (image section kind 4): the rotary model
    /// of `tcomp geometry identify-rotary --model-out` (R-test convention,
    /// converted to the board's rotating frame); needs --geometry. A model
    /// with drift (--drift) is served in the section's R-test location
    /// mode; its sensors join the volumetric section (channels: --run).
    #[arg(long)]
    pub rotary: Option<std::path::PathBuf>,
    /// Serve a rotary model whose identification marked terms unobservable.
    #[arg(long, requires = "rotary")]
    pub allow_unobservable: bool,
    /// Serve a volumetric table or rotary model that failed the adequacy
    /// test (`geometry identify`/`identify-rotary`; docs/geometry.md).
    #[arg(long)]
    pub accept_inadequate: bool,
    /// A range and C range of the five-axis section (degrees, min,max);
    /// outside, the angle is held at the edge and flagged.
    #[arg(
        long,
        default_value = "-120,120",
        requires = "rotary",
        allow_hyphen_values = true
    )]
    pub a_range_deg: String,
    /// C range of the five-axis section (degrees, min,max).
    #[arg(
        long,
        default_value = "-720,720",
        requires = "rotary",
        allow_hyphen_values = true
    )]
    pub c_range_deg: String,
    /// The model image to write.
    #[arg(short, long)]
    pub out: std::path::PathBuf,
    /// Sign the image with this private key file (`tcomp keygen`): a board
    /// that stores the public key commits only images it signed.
    #[arg(long)]
    pub sign: Option<std::path::PathBuf>,
    #[command(flatten)]
    pub accept: super::sanity::AcceptArgs,
    /// Print the summary as JSON (`wiring`: each model sensor's board channel).
    #[arg(long)]
    pub json: bool,
}

/// `export`'s long help: an example.
pub const EXAMPLE: &str = "Example:
  tcomp fit warmup.csv --split-chrono 0.6,0.8 --out fit.json
  tcomp export --model fit.json --run warmup.csv -o model.img
  tcomp replay shift.csv model.img";

pub fn main(args: ExportArgs) -> anyhow::Result<()> {
    let ExportArgs {
        demo,
        model,
        run,
        r#use,
        max_correction_um,
        max_rate_um_per_s,
        model_version,
        seed,
        geometry,
        tool_max_mm,
        geometry_origin_mm,
        rotary,
        allow_unobservable,
        accept_inadequate,
        a_range_deg,
        c_range_deg,
        out,
        sign,
        accept,
        json,
    } = args;
    // The adequacy verdicts (refused first; warnings once the image is written).
    let mut adequacy_warnings = Vec::new();
    for p in geometry.iter().chain(&rotary) {
        adequacy_warnings.extend(tcomp_geometry::adequacy::check_json_file(
            p,
            accept_inadequate,
        )?);
    }
    if rotary.is_some() && geometry.is_none() {
        anyhow::bail!(
            "--rotary needs --geometry <vol.json>: the five-axis section adds to the volumetric section"
        );
    }
    // Read the key first: a bad key file costs no fit.
    let sign = sign
        .map(|p| tcomp_model::signing::read_private(&p))
        .transpose()?;
    let run_for_geometry = run.clone();
    let mut columns: Vec<String> = Vec::new();
    let (mut envelope, mut output) = (None, None);
    let float = match (demo, model) {
        (true, _) => {
            let mut demo = thermocomp_core::float::demo_model(seed);
            demo.model_version = model_version;
            demo
        }
        (false, Some(path)) => {
            let text = std::fs::read_to_string(&path)
                .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
            let file: tcomp_model::fit::ModelFile = serde_json::from_str(&text)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            let run =
                run.ok_or_else(|| anyhow::anyhow!("--run <csv> gives the board's channel order"))?;
            let table = tcomp_data::runcsv::Run::read_with_temperatures(&run)?;
            super::sanity::check_runs([(run.display().to_string().as_str(), &table)], &accept)?;
            columns = table
                .temperature_columns()
                .iter()
                .map(|c| c.to_string())
                .collect();
            let roms = table
                .sensor_roms()
                .with_context(|| format!("in run file {}", run.display()))?;
            let opts = tcomp_model::export::ExportOptions {
                model_version,
                max_correction_um,
                max_rate_um_per_s,
                choices: tcomp_model::export::parse_choices(&r#use)?,
                ..Default::default()
            };
            let mut float = tcomp_model::export::float_model_from_fit(&file, &columns, &opts)?;
            tcomp_model::export::name_sensors_by_rom(&mut float, &columns, &roms)?;
            // The envelope policy per direction from the fit's evidence: which and why.
            let (policy, lines) = tcomp_model::export::policies(&file, &float);
            lines.iter().for_each(|l| eprintln!("{l}"));
            envelope = policy;
            // The output low-pass per direction the fit chose: one line each.
            let (decays, lines) = tcomp_model::export::decays(&file, &float);
            lines.iter().for_each(|l| eprintln!("{l}"));
            output = decays;
            float
        }
        (false, None) => {
            anyhow::bail!("say what to export: --demo or --model <fit.json> --run <csv>")
        }
    };
    let rotary_model = rotary
        .as_deref()
        .map(tcomp_geometry::rotary::RotaryModel::read)
        .transpose()?;
    let mut vol_sensors = Vec::new();
    let section = match &geometry {
        Some(path) => Some(geometry_section(
            path,
            &float,
            run_for_geometry.as_deref(),
            (tool_max_mm, &geometry_origin_mm, max_correction_um),
            rotary_model.as_ref(),
            &mut vol_sensors,
        )?),
        None => None,
    };
    let five = match (&rotary, &rotary_model, &section) {
        (Some(path), Some(m), Some((vol, _))) => Some(rotary_section(
            path,
            m,
            vol,
            &vol_sensors,
            [&a_range_deg, &c_range_deg],
            max_correction_um,
            allow_unobservable,
        )?),
        _ => None,
    };
    let mut summary = tcomp_model::export::export_sections(
        &float,
        (section, five),
        (envelope, output),
        &out,
        sign.as_ref(),
    )?;
    for (w, s) in summary.wiring.iter_mut().zip(&float.sensors) {
        w.sensor = columns.get(usize::from(s.channel)).cloned();
    }
    tcomp_model::export::print_summary(&summary, &out, json);
    adequacy_warnings
        .iter()
        .for_each(|w| eprintln!("warning: {w}"));
    Ok(())
}

/// `tcomp export --geometry`: read `geometry table --json`'s polynomial,
/// find its sensors' board channels (the run's T_ columns, by name) and
/// its X, Y, Z position slots (the model's axes of those names, else the
/// first slots the model does not use), quantise it and report the cost.
/// A `rotary` model's drift sensors join the section's sensors (no terms
/// of their own: the five-axis section reads its temperatures there);
/// `sensors` receives the section's sensor names.
fn geometry_section(
    path: &std::path::Path,
    float: &thermocomp_core::float::FloatModel,
    run: Option<&std::path::Path>,
    (tool_max_mm, origin, max_correction_um): (f64, &str, f64),
    rotary: Option<&tcomp_geometry::rotary::RotaryModel>,
    sensors: &mut Vec<String>,
) -> anyhow::Result<tcomp_model::export::GeometrySection> {
    use tcomp_geometry::board::{quantisation_report, quantize, BoardOptions};
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let mut poly: tcomp_geometry::volumetric::VolumetricPoly = serde_json::from_str(&text)
        .map_err(|e| {
            anyhow::anyhow!(
                "{}: not a `tcomp geometry table --json` output: {e}",
                path.display()
            )
        })?;
    if let Some(m) = rotary {
        tcomp_geometry::rotary_board::add_drift_sensors(&mut poly, m)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    sensors.clone_from(&poly.sensors);
    let mut channels = Vec::new();
    if !poly.sensors.is_empty() {
        let run = run.ok_or_else(|| {
            anyhow::anyhow!(
                "{}: the volumetric section reads sensor(s) {} (with the rotary model's drift): --run <csv> gives their board channels",
                path.display(),
                poly.sensors.join(", ")
            )
        })?;
        let columns: Vec<String> = tcomp_data::runcsv::Run::read_with_temperatures(run)?
            .temperature_columns()
            .iter()
            .map(|c| c.to_string())
            .collect();
        for s in &poly.sensors {
            let want = if s.starts_with("T_") {
                s.clone()
            } else {
                format!("T_{s}")
            };
            let ch = columns
                .iter()
                .position(|c| *c == want || c == s)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "{}: sensor {s} of the volumetric polynomial is not among the T_ columns of {}",
                        path.display(),
                        run.display()
                    )
                })?;
            let ch = u8::try_from(ch)
                .ok()
                .filter(|&c| usize::from(c) < thermocomp_core::limits::MAX_SENSORS)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "sensor {s} is board channel {ch}; the board reads channels 0..=19"
                    )
                })?;
            channels.push(ch);
        }
    }
    let o: Vec<f64> = origin
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 3 && v.iter().all(|x| x.is_finite()))
        .ok_or_else(|| {
            anyhow::anyhow!("--geometry-origin-mm {origin:?}: expected three numbers x,y,z (mm)")
        })?;
    let mut slots = [0u8; 3];
    let mut used: Vec<usize> = Vec::new();
    for (k, name) in ["X", "Y", "Z"].iter().enumerate() {
        if let Some(i) = float
            .axes
            .iter()
            .position(|a| a.name.eq_ignore_ascii_case(name))
        {
            slots[k] = i as u8;
            used.push(i);
        }
    }
    for (k, name) in ["X", "Y", "Z"].iter().enumerate() {
        if !float.axes.iter().any(|a| a.name.eq_ignore_ascii_case(name)) {
            let free = (0..thermocomp_core::limits::MAX_AXES)
                .find(|i| *i >= float.axes.len() && !used.contains(i))
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "no free PLC position slot for axis {name} of the volumetric section"
                    )
                })?;
            slots[k] = free as u8;
            used.push(free);
        }
    }
    let opts = BoardOptions {
        channels,
        slots,
        origin_mm: [o[0], o[1], o[2]],
        tool_max_mm,
        max_correction_um,
    };
    let v = quantize(&poly, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let report = quantisation_report(&poly, &v, &opts);
    Ok((v, report))
}

/// `tcomp export --rotary`: the identified rotary model `m` (read from
/// `path`), converted to the board's convention and quantised beside the
/// volumetric section `vol` (its sensors named `sensors`).
fn rotary_section(
    path: &std::path::Path,
    m: &tcomp_geometry::rotary::RotaryModel,
    vol: &thermocomp_core::volumetric::Volumetric,
    sensors: &[String],
    ranges: [&str; 2],
    max_correction_um: f64,
    allow_unobservable: bool,
) -> anyhow::Result<tcomp_model::export::FiveAxisSection> {
    let range = |s: &str, flag: &str| -> anyhow::Result<[f64; 2]> {
        let v: Vec<f64> = s
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 2 && v.iter().all(|x| x.is_finite()) && v[0] < v[1])
            .ok_or_else(|| {
                anyhow::anyhow!("{flag} {s:?}: expected min,max in degrees (min < max)")
            })?;
        Ok([v[0], v[1]])
    };
    let opts = tcomp_geometry::board5::FiveAxisOptions {
        a_range_deg: range(ranges[0], "--a-range-deg")?,
        c_range_deg: range(ranges[1], "--c-range-deg")?,
        max_correction_um,
    };
    tcomp_geometry::rotary_board::rotary_section(m, vol, sensors, &opts, allow_unobservable)
        .map_err(|e| {
            anyhow::anyhow!(
                "{}: {}",
                path.display(),
                tcomp_data::cli_error::one_line(&e)
            )
        })
}

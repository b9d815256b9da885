//! `tcomp geometry predict` (issue 49 item 4): the identified model's
//! tool-tip error at the user's own poses (a CSV: x, y, z, optional a, c,
//! tool, T_<sensor>), and with `--image` what the board serves there — the
//! math core's fixed point, bit-exact — with the difference to the desktop
//! and its stated bound. The computation is `tcomp_geometry::predict`;
//! this file reads the files, checks the poses and prints.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::geometry_table::parse_triple;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::predict::{
    bare, board_inputs, linear_bound_um, rotary_bound_um, same_table, serve, Desktop, DesktopModel,
    LinearModel, PoseIn, Served,
};
use tcomp_geometry::rotary::RotaryModel;
use tcomp_geometry::study::ErrorsJson;
use tcomp_geometry::volumetric::VolumetricPoly;
use thermocomp_core::image::Model;

#[derive(clap::Args, Debug)]
pub struct PredictArgs {
    /// Linear-axis model: errors (errors.json or identify --json output) or
    /// a volumetric table (`geometry table --json`, `fit-thermal --table`).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Rotary model (`geometry identify-rotary --model-out`).
    #[arg(long)]
    pub rotary: Option<PathBuf>,
    /// Poses: a CSV with a header; columns x,y,z [mm] (the PLC's positions),
    /// optional a,c [deg], tool [mm], T_<sensor> [°C], id.
    #[arg(long)]
    pub poses: PathBuf,
    /// Tool length along the spindle [mm] for rows without a `tool` column
    /// (`geometry tooltip`'s default offset 0,0,100).
    #[arg(long, default_value_t = 100.0, allow_hyphen_values = true)]
    pub tool: f64,
    /// Machine position of the linear model's zero x,y,z [mm] (`export
    /// --geometry-origin-mm`; default: the image's, else 0,0,0).
    #[arg(long, allow_hyphen_values = true)]
    pub origin_mm: Option<String>,
    /// A model image (`tcomp export --geometry … [--rotary …]`): also what
    /// the board serves at each pose (the core's fixed point).
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// Predict at poses outside the model's stroke (or the image's ranges,
    /// where the board holds the input at the edge).
    #[arg(long)]
    pub allow_outside: bool,
    /// Use a model whose identification marked terms unobservable.
    #[arg(long)]
    pub allow_unobservable: bool,
    /// Use a model that failed the adequacy test (output marked).
    #[arg(long)]
    pub accept_inadequate: bool,
    #[arg(long)]
    pub json: bool,
}

/// `predict --help`'s example.
pub const EXAMPLE: &str = "Example:
  tcomp geometry identify lines/*.csv --json > id.json
  printf 'x,y,z,tool\\n100,200,50,120\\n400,250,300,80\\n' > poses.csv
  tcomp geometry predict --model id.json --poses poses.csv";

/// One row of the poses file: its line number, label and pose.
struct Row {
    line: usize,
    id: Option<String>,
    pose: PoseIn,
}

fn read_poses(path: &Path, default_tool: f64) -> Result<Vec<Row>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = (text.lines().enumerate())
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((_, header)) = lines.next() else {
        bail!(
            "{}: empty (a header x,y,z[,a,c,tool,T_…] and one row per pose)",
            path.display()
        );
    };
    let cols: Vec<String> = header.split(',').map(|c| c.trim().to_string()).collect();
    let find = |n: &str| cols.iter().position(|c| c.eq_ignore_ascii_case(n));
    for c in &cols {
        let known = ["x", "y", "z", "a", "c", "tool", "id"]
            .iter()
            .any(|k| c.eq_ignore_ascii_case(k));
        if !known && !c.starts_with("T_") {
            bail!(
                "{}: unknown column {c:?} (columns: x, y, z [mm], a, c [deg], tool [mm], T_<sensor> [°C], id)",
                path.display()
            );
        }
    }
    let mut xyz = [0usize; 3];
    for (k, n) in ["x", "y", "z"].iter().enumerate() {
        xyz[k] = find(n).ok_or_else(|| {
            anyhow::anyhow!("{}: no column {n} (the header needs x,y,z)", path.display())
        })?;
    }
    let mut rows = Vec::new();
    for (line, l) in lines {
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if f.len() != cols.len() {
            bail!(
                "{} line {line}: {} fields, the header has {}",
                path.display(),
                f.len(),
                cols.len()
            );
        }
        let num = |i: usize| -> Result<f64> {
            f[i].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "{} line {line}, column {}: {:?} is not a number",
                        path.display(),
                        cols[i],
                        f[i]
                    )
                })
        };
        let opt = |n: &str, d: f64| find(n).map_or(Ok(d), num);
        let mut temps_c = BTreeMap::new();
        for (i, c) in cols.iter().enumerate() {
            if c.starts_with("T_") {
                temps_c.insert(bare(c), num(i)?);
            }
        }
        rows.push(Row {
            line,
            id: find("id").map(|i| f[i].to_string()),
            pose: PoseIn {
                pos_mm: [num(xyz[0])?, num(xyz[1])?, num(xyz[2])?],
                a_deg: opt("a", 0.0)?,
                c_deg: opt("c", 0.0)?,
                tool_mm: opt("tool", default_tool)?,
                temps_c,
            },
        });
    }
    if rows.is_empty() {
        bail!("{}: a header but no poses", path.display());
    }
    Ok(rows)
}

/// The adequacy verdict of a model file: refused when inadequate unless
/// `accept`; a warning on stderr when accepted or unknown.
fn adequacy(
    adequate: Option<bool>,
    failure: Option<&str>,
    path: &Path,
    accept: bool,
) -> Result<Option<bool>> {
    if let Some(w) = tcomp_geometry::adequacy::check_model_file(adequate, path, accept, failure)? {
        eprintln!("warning: {w}");
    }
    Ok(adequate)
}

/// `--model`: errors or a table, told apart by their keys; anything else
/// is named.
fn read_linear(path: &Path, a: &PredictArgs) -> Result<(LinearModel, Option<bool>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let has = |k: &str| v.get(k).is_some();
    if has("terms") && has("stroke_mm") {
        let p: VolumetricPoly = serde_json::from_value(v)
            .map_err(|e| anyhow::anyhow!("{}: not a volumetric table: {e}", path.display()))?;
        if !p.unobservable_terms.is_empty() && !p.unobservable_accepted {
            tcomp_geometry::guard::refuse_model(&p.unobservable_terms, path, a.allow_unobservable)?;
        }
        let failure = p.adequacy.as_ref().map(|x| x.failure.clone());
        let ok = adequacy(p.adequate, failure.as_deref(), path, a.accept_inadequate)?;
        return Ok((LinearModel::Table(Box::new(p)), ok));
    }
    if has("location") || has("components") {
        bail!(
            "{}: this is an identify-rotary model; give it as --rotary",
            path.display()
        );
    }
    if !(has("errors") && has("structure")) {
        bail!(
            "{}: neither an errors file (identify --json, errors.json) nor a volumetric table (geometry table --json)",
            path.display()
        );
    }
    let ej = ErrorsJson::read(path)?;
    let structure = Structure::parse(&ej.structure)
        .with_context(|| format!("{}: structure", path.display()))?;
    tcomp_geometry::guard::refuse_model(&ej.unobservable_terms, path, a.allow_unobservable)?;
    let failure = ej.adequacy.as_ref().map(|x| x.failure.clone());
    let ok = adequacy(ej.adequate, failure.as_deref(), path, a.accept_inadequate)?;
    let m = LinearModel::Errors {
        structure,
        errors: Box::new(ej.to_errors()?),
        stroke_mm: ej.stroke_mm,
    };
    Ok((m, ok))
}

fn read_rotary(path: &Path, a: &PredictArgs) -> Result<(RotaryModel, Option<bool>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if v.get("errors").is_some() || v.get("terms").is_some() {
        bail!(
            "{}: this is a model of the linear axes; give it as --model",
            path.display()
        );
    }
    if v.get("location").is_none() && (v.get("A").is_some() || v.get("C").is_some()) {
        bail!(
            "{}: this is a turntable description (`geometry tooltip --turntable`); --rotary takes an identify-rotary --model-out model",
            path.display()
        );
    }
    let m = RotaryModel::read(path)?;
    if !m.unobservable.is_empty() && !a.allow_unobservable {
        bail!(
            "{}: the R-test files did not determine {} (marked unobservable); its values are not the machine's. Give --allow-unobservable to use it anyway",
            path.display(),
            m.unobservable.join(", ")
        );
    }
    let failure = m.adequacy.as_ref().map(|x| x.failure.clone());
    let ok = adequacy(m.adequate, failure.as_deref(), path, a.accept_inadequate)?;
    Ok((m, ok))
}

fn read_image(path: &Path) -> Result<Model> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let m = Model::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if m.volumetric.is_none() {
        bail!(
            "{}: the image has no volumetric section (export it with --geometry vol.json)",
            path.display()
        );
    }
    Ok(m)
}

/// What the image is compared with, and how it is bounded.
struct Comparison {
    /// "total", "rotary part", "linear part"; `None`: not comparable (why).
    what: std::result::Result<&'static str, String>,
    /// The linear table the image should hold (and its fit to the errors),
    /// or why no bound is stated.
    table: Option<std::result::Result<(VolumetricPoly, f64), String>>,
}

fn comparison(d: &DesktopModel, img: &Model) -> Result<Comparison> {
    let v = img.volumetric.as_ref().expect("read_image checked");
    let five = img.five_axis.is_some();
    let what = match (d.linear.is_some(), d.rotary.is_some(), five) {
        (true, true, true) => Ok("total"),
        (false, true, true) => Ok("rotary part"),
        (true, false, false) => Ok("total"),
        (true, true, false) => Ok("linear part"),
        (_, false, true) => Err(
            "the image serves a five-axis part; give --rotary (the model it was exported from) to compare"
                .to_string(),
        ),
        (false, _, false) => Err(
            "the image has no five-axis section and no --model is given: nothing to compare"
                .to_string(),
        ),
    };
    let table = match &d.linear {
        Some(l) if matches!(what, Ok("total" | "linear part")) => {
            let (p, fit) = l.poly()?;
            Some(same_table(&p, v).map(|()| (p, fit)))
        }
        _ => None,
    };
    Ok(Comparison { what, table })
}

/// The section's sensors by name: the desktop's, in export's order.
fn image_sensors(img: &Model, d: &DesktopModel, path: &Path) -> Result<Vec<String>> {
    let v = img.volumetric.as_ref().expect("read_image checked");
    let names = d.sensors();
    if v.sensors.is_empty() {
        return Ok(Vec::new());
    }
    if names.len() != v.sensors.len() {
        let ch: Vec<String> = v
            .sensors
            .iter()
            .map(|s| s.sensor.channel.to_string())
            .collect();
        bail!(
            "{}: the volumetric section reads {} sensor(s) (board channels {}), the models given name {} ({}): not an image of these models",
            path.display(),
            v.sensors.len(),
            ch.join(", "),
            names.len(),
            names.join(", ")
        );
    }
    Ok(names)
}

/// Refuse a pose outside the model's stroke or the image's ranges.
fn check_outside(row: &Row, d: &DesktopModel, img: Option<&Model>, poses: &Path) -> Result<()> {
    let p = &row.pose;
    let at = format!("{} line {}", poses.display(), row.line);
    let tail = "; --allow-outside to predict there anyway";
    if let Some(l) = &d.linear {
        let s = l.stroke_mm();
        for k in 0..3 {
            let q = p.pos_mm[k] - d.origin_mm[k];
            if !(q >= -1e-6 && q <= s[k] + 1e-6) {
                bail!(
                    "{at}: {} {} mm is outside the model's stroke {}…{} mm{tail}",
                    ["x", "y", "z"][k],
                    p.pos_mm[k],
                    d.origin_mm[k],
                    d.origin_mm[k] + s[k]
                );
            }
        }
    }
    let five_image = img.is_some_and(|m| m.five_axis.is_some());
    if d.rotary.is_none() && (p.a_deg != 0.0 || p.c_deg != 0.0) && !five_image {
        bail!("{at}: A/C given but no --rotary model (and no five-axis image)");
    }
    let Some(img) = img else { return Ok(()) };
    let v = img.volumetric.as_ref().expect("read_image checked");
    for k in 0..3 {
        let (lo, hi) = (v.origin_um[k], v.origin_um[k] + v.stroke_um[k]);
        let um = (p.pos_mm[k] * 1e3).round();
        if !(um >= f64::from(lo) && um <= f64::from(hi)) {
            bail!(
                "{at}: {} {} mm is outside the image's range {}…{} mm (the board holds it at the edge){tail}",
                ["x", "y", "z"][k],
                p.pos_mm[k],
                f64::from(lo) / 1e3,
                f64::from(hi) / 1e3
            );
        }
    }
    let tool_max = f64::from(v.tool_max_um) / 1e3;
    if !(p.tool_mm >= 0.0 && p.tool_mm <= tool_max) {
        bail!(
            "{at}: tool {} mm is outside the image's 0…{tool_max} mm (the board holds it at the edge){tail}",
            p.tool_mm
        );
    }
    if let Some(f) = &img.five_axis {
        for (name, val, r) in [
            ("A", p.a_deg, f.a_range_mdeg),
            ("C", p.c_deg, f.c_range_mdeg),
        ] {
            let m = (val * 1e3).round();
            if !(m >= f64::from(r[0]) && m <= f64::from(r[1])) {
                bail!(
                    "{at}: {name} {val}° is outside the image's range {}…{}°{tail}",
                    f64::from(r[0]) / 1e3,
                    f64::from(r[1]) / 1e3
                );
            }
        }
    }
    Ok(())
}

/// The board's side of one row.
struct Board {
    served: Served,
    /// Served − desktop (at the board's inputs), µm; and its bound.
    diff_um: Option<[f64; 3]>,
    bound_um: Option<f64>,
}

fn board_row(
    img: &Model,
    names: &[String],
    d: &DesktopModel,
    cmp: &Comparison,
    p: &PoseIn,
) -> Result<Board> {
    let v = img.volumetric.as_ref().expect("read_image checked");
    let (inputs, back) = board_inputs(v, names, p)?;
    let served = serve(img, &inputs).expect("read_image checked");
    let Ok(what) = cmp.what else {
        return Ok(Board {
            served,
            diff_um: None,
            bound_um: None,
        });
    };
    let at: Desktop = d.predict(&back)?;
    let (s, want) = match what {
        "rotary part" => (
            served.rotary_um.unwrap_or_default(),
            at.rotary_um.unwrap_or_default(),
        ),
        "linear part" => (served.corrections_um, at.linear_um),
        _ => (served.corrections_um, at.machine_um),
    };
    let diff = std::array::from_fn(|k| s[k] - want[k]);
    let lin = match &cmp.table {
        None => Some(0.0),
        Some(Ok((poly, fit))) => Some(linear_bound_um(poly, v, &inputs, *fit)),
        Some(Err(_)) => None,
    };
    // Each part's bound holds ½ of the 0.1 µm register for its own final
    // rounding; the total is rounded once.
    let rot = match (&d.rotary, &img.five_axis, what) {
        (Some(m), Some(f), "rotary part") => rotary_bound_um(m, f, &back),
        (Some(m), Some(f), "total") => rotary_bound_um(m, f, &back) - 0.05,
        _ => 0.0,
    };
    let bound = lin
        .map(|l| l + rot)
        .filter(|_| !served.clamped() && served.valid());
    Ok(Board {
        served,
        diff_um: Some(diff),
        bound_um: bound,
    })
}

fn origin(a: &PredictArgs, img: Option<&Model>) -> Result<[f64; 3]> {
    let from_img = img
        .and_then(|m| m.volumetric.as_ref())
        .map(|v| v.origin_um.map(|x| f64::from(x) / 1e3));
    let given = a
        .origin_mm
        .as_deref()
        .map(|s| parse_triple(s, "--origin-mm"))
        .transpose()?;
    match (given, from_img) {
        (Some(g), Some(i)) if (0..3).any(|k| (g[k] - i[k]).abs() > 5e-4) => bail!(
            "--origin-mm {g:?} but the image's volumetric origin is {i:?} mm (export --geometry-origin-mm)"
        ),
        (Some(g), _) => Ok(g),
        (None, Some(i)) => Ok(i),
        (None, None) => Ok([0.0; 3]),
    }
}

pub fn predict_cmd(a: PredictArgs) -> Result<()> {
    if a.model.is_none() && a.rotary.is_none() {
        bail!("give --model (errors or table) and/or --rotary (identify-rotary model)");
    }
    if !a.tool.is_finite() {
        bail!("--tool must be a number of mm");
    }
    let mut verdicts = BTreeMap::new();
    let linear = match &a.model {
        Some(p) => {
            let (m, ok) = read_linear(p, &a)?;
            verdicts.insert("model", ok);
            Some(m)
        }
        None => None,
    };
    let rotary = match &a.rotary {
        Some(p) => {
            let (m, ok) = read_rotary(p, &a)?;
            verdicts.insert("rotary", ok);
            Some(m)
        }
        None => None,
    };
    let rows = read_poses(&a.poses, a.tool)?;
    let img = a.image.as_deref().map(read_image).transpose()?;
    let d = DesktopModel {
        linear,
        rotary,
        origin_mm: origin(&a, img.as_ref())?,
    };
    let board = match (&img, &a.image) {
        (Some(m), Some(path)) => Some((m, image_sensors(m, &d, path)?, comparison(&d, m)?)),
        _ => None,
    };
    let mut out = Vec::new();
    for r in &rows {
        if !a.allow_outside {
            check_outside(r, &d, img.as_ref(), &a.poses)?;
        }
        let at = |e: anyhow::Error| anyhow::anyhow!("{} line {}: {e}", a.poses.display(), r.line);
        let desk = d.predict(&r.pose).map_err(at)?;
        let b = match &board {
            Some((m, names, cmp)) => Some(board_row(m, names, &d, cmp, &r.pose).map_err(at)?),
            None => None,
        };
        out.push((desk, b));
    }
    let cmp = board.as_ref().map(|(_, _, c)| c);
    if a.json {
        println!("{}", json(&a, &rows, &out, cmp, &verdicts, &d));
    } else {
        print_text(&a, &rows, &out, cmp, &d);
    }
    Ok(())
}

fn r4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

fn v4(v: [f64; 3]) -> [f64; 3] {
    v.map(r4)
}

fn json(
    a: &PredictArgs,
    rows: &[Row],
    out: &[(Desktop, Option<Board>)],
    cmp: Option<&Comparison>,
    verdicts: &BTreeMap<&str, Option<bool>>,
    d: &DesktopModel,
) -> serde_json::Value {
    use serde_json::json;
    let rows: Vec<_> = rows
        .iter()
        .zip(out)
        .map(|(r, (desk, b))| {
            let p = &r.pose;
            let mut o = json!({
                "line": r.line, "id": r.id,
                "x_mm": p.pos_mm[0], "y_mm": p.pos_mm[1], "z_mm": p.pos_mm[2],
                "a_deg": p.a_deg, "c_deg": p.c_deg, "tool_mm": p.tool_mm, "temps_c": p.temps_c,
                "error_machine_um": desk.machine_um,
                "error_workpiece_um": desk.workpiece_um,
                "exact_workpiece_um": desk.exact_workpiece_um,
                "linear_part_machine_um": desk.linear_um,
                "rotary_part_machine_um": desk.rotary_um,
            });
            if let Some(b) = b {
                o["served"] = json!({
                    "correction_machine_um": b.served.corrections_um,
                    "rotary_part_machine_um": b.served.rotary_um,
                    "status": b.served.status, "five_axis_status": b.served.five_status,
                    "flags": b.served.flags(),
                });
                o["served_minus_desktop_um"] = json!(b.diff_um.map(v4));
                o["bound_um"] = json!(b.bound_um.map(r4));
                o["within_bound"] = json!(b
                    .bound_um
                    .zip(b.diff_um)
                    .map(|(bd, df)| df.iter().all(|x| x.abs() <= bd)));
            }
            o
        })
        .collect();
    let worst = out
        .iter()
        .filter_map(|(_, b)| b.as_ref()?.diff_um)
        .flat_map(|d| d.map(f64::abs))
        .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))));
    let image = cmp.map(|c| {
        json!({
            "path": a.image.as_ref().map(|p| p.display().to_string()),
            "compared": c.what.as_ref().ok(),
            "not_compared": c.what.as_ref().err(),
            "bound_not_stated": c.table.as_ref().and_then(|t| t.as_ref().err()),
            "worst_served_minus_desktop_um": worst.map(r4),
            "inputs": "positions and tool length in µm, A and C in 0.001°, temperatures in 1/16 °C (the board's registers); the difference is taken at those inputs",
        })
    });
    json!({
        "unit": "um",
        "frames": {"machine": "the board's registers 180–185 (the CNC subtracts it)",
                   "workpiece": "geometry tooltip's frame (tool relative to the workpiece); equal to machine without a rotary model"},
        "model": a.model.as_ref().map(|p| p.display().to_string()),
        "rotary": a.rotary.as_ref().map(|p| p.display().to_string()),
        "adequate": verdicts,
        "origin_mm": d.origin_mm,
        "sensors": d.sensors(),
        "image": image,
        "rows": rows,
    })
}

fn fmt3(v: [f64; 3], prec: usize) -> String {
    v.map(|x| format!("{x:+9.prec$}")).join(" ")
}

fn print_text(
    a: &PredictArgs,
    rows: &[Row],
    out: &[(Desktop, Option<Board>)],
    cmp: Option<&Comparison>,
    d: &DesktopModel,
) {
    let five = d.rotary.is_some();
    println!(
        "tool-tip error (µm, x y z; machine frame = what the board serves, the CNC subtracts it{}):",
        if five {
            "; workpiece frame = geometry tooltip's"
        } else {
            "; no rotary model: machine = workpiece frame, as geometry tooltip prints it"
        }
    );
    for (r, (desk, b)) in rows.iter().zip(out) {
        let p = &r.pose;
        let label = r.id.clone().unwrap_or_else(|| format!("line {}", r.line));
        let mut pose = format!(
            "{label}: x,y,z {},{},{} mm, tool {} mm",
            p.pos_mm[0], p.pos_mm[1], p.pos_mm[2], p.tool_mm
        );
        if five || p.a_deg != 0.0 || p.c_deg != 0.0 {
            pose += &format!(", A {}°, C {}°", p.a_deg, p.c_deg);
        }
        for (n, t) in &p.temps_c {
            pose += &format!(", T_{n} {t} °C");
        }
        println!("{pose}");
        println!(
            "  desktop, machine frame    {} µm",
            fmt3(desk.machine_um, 4)
        );
        if five {
            println!(
                "  desktop, workpiece frame  {} µm",
                fmt3(desk.workpiece_um, 4)
            );
        }
        if let Some(e) = desk.exact_workpiece_um {
            println!("  exact chain, workpiece    {} µm", fmt3(e, 4));
        }
        let Some(b) = b else { continue };
        let flags = b.served.flags();
        println!(
            "  board image serves        {} µm{}",
            fmt3(b.served.corrections_um, 1),
            if flags.is_empty() {
                String::new()
            } else {
                format!(" ({})", flags.join(", "))
            }
        );
        if let Some(df) = b.diff_um {
            let worst = df.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let bound = b.bound_um.map_or("no bound stated".to_string(), |bd| {
                format!(
                    "bound {bd:.4} µm{}",
                    if worst <= bd { "" } else { " EXCEEDED" }
                )
            });
            let what = cmp
                .and_then(|c| c.what.as_ref().ok())
                .copied()
                .unwrap_or("");
            println!(
                "  served − desktop ({what})  {} µm, largest {worst:.4} µm, {bound}",
                fmt3(df, 4)
            );
        }
    }
    if let Some(c) = cmp {
        if let Err(why) = &c.what {
            println!(
                "{}: {why}",
                a.image
                    .as_ref()
                    .map_or(String::new(), |p| p.display().to_string())
            );
        }
        if let Some(Err(why)) = &c.table {
            println!(
                "no bound stated: the image's volumetric section is not this model's table ({why})"
            );
        }
        println!("the board's inputs: positions and tool length in µm, A and C in 0.001°, temperatures in 1/16 °C; the difference is taken at those inputs");
    }
}

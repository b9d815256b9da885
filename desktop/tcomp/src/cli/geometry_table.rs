//! `tcomp geometry tooltip|table`: the commands that use an identified
//! model (errors file) as it stands, and the parsing of `x,y,z` triples the
//! geometry commands share. A model with errors marked unobservable
//! (`identify --partial`) is refused unless `--allow-unobservable`.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

use tcomp_geometry::errors::GeometricErrors;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::study::ErrorsJson;

#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// Errors (errors.json or identify --json output).
    #[arg(long)]
    pub model: PathBuf,
    /// Use a model whose identification marked errors unobservable (the
    /// table then carries them and `export --geometry` takes it).
    #[arg(long)]
    pub allow_unobservable: bool,
    /// Build from a model that failed the adequacy test (the table is then
    /// marked `"adequate": false`, and `export --geometry` asks again).
    #[arg(long)]
    pub accept_inadequate: bool,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct TooltipArgs {
    /// Linear-axis errors (errors.json or identify --json output); default none.
    #[arg(long)]
    pub errors: Option<PathBuf>,
    /// Turntable file (five-axis): pivot, offsets and rotary errors.
    #[arg(long)]
    pub turntable: Option<PathBuf>,
    /// Structure when --errors is not given.
    #[arg(long, default_value = "XY/Z")]
    pub structure: String,
    /// Axis positions x,y,z [mm] or x,y,z,a,c [mm, deg].
    #[arg(long, allow_hyphen_values = true)]
    pub at: String,
    /// Tool offset from the spindle gauge point x,y,z [mm].
    #[arg(long, default_value = "0,0,100", allow_hyphen_values = true)]
    pub tool: String,
    /// Use a model whose identification marked errors unobservable.
    #[arg(long)]
    pub allow_unobservable: bool,
    /// Use a model that failed the adequacy test (output marked).
    #[arg(long)]
    pub accept_inadequate: bool,
    #[arg(long)]
    pub json: bool,
}

/// The errors file's adequacy verdict: refused when inadequate (unless
/// `accept`), a warning on stderr when accepted or unknown. Returns the
/// verdict (`None`: unknown).
fn model_adequacy(ej: &ErrorsJson, path: &std::path::Path, accept: bool) -> Result<Option<bool>> {
    if let Some(w) = tcomp_geometry::adequacy::check_model_file(
        ej.adequate,
        path,
        accept,
        ej.adequacy.as_ref().map(|a| a.failure.as_str()),
    )? {
        eprintln!("warning: {w}");
    }
    Ok(ej.adequate)
}

pub fn parse_triple(s: &str, what: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| {
            anyhow::anyhow!("{what}: expected three numbers like 800,500,400, got {s:?}")
        })?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("{what}: expected three numbers like 800,500,400, got {s:?}");
    }
    Ok([v[0], v[1], v[2]])
}

pub fn tooltip_cmd(a: TooltipArgs) -> Result<()> {
    use tcomp_geometry::five_axis::{
        tool_tip_error_exact5, tool_tip_error_linear5, RotaryPos, Turntable,
    };
    let (st, lin, adequate) = match &a.errors {
        Some(p) => {
            let ej = ErrorsJson::read(p)?;
            let st = Structure::parse(&ej.structure)
                .with_context(|| format!("{}: structure", p.display()))?;
            tcomp_geometry::guard::refuse_model(&ej.unobservable_terms, p, a.allow_unobservable)?;
            let adequate = model_adequacy(&ej, p, a.accept_inadequate)?;
            (st, ej.to_errors()?, adequate)
        }
        None => (
            Structure::parse(&a.structure).context("--structure")?,
            GeometricErrors::zero(),
            None,
        ),
    };
    let v: Vec<f64> = a
        .at
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("--at {:?}: expected x,y,z or x,y,z,a,c (numbers)", a.at))?;
    if !(v.len() == 3 || v.len() == 5) || v.iter().any(|x| !x.is_finite()) {
        bail!("--at {:?}: expected x,y,z or x,y,z,a,c (numbers)", a.at);
    }
    let tool = parse_triple(&a.tool, "--tool")?;
    let turntable = match &a.turntable {
        Some(p) => {
            tcomp_geometry::five_axis::refuse_non_turntable(p)?;
            Turntable::read(p)?
        }
        None if v.len() == 5 => bail!("--at gives rotary angles but no --turntable file"),
        None => Turntable::default(),
    };
    let pos = [v[0], v[1], v[2]];
    let r = RotaryPos {
        a_deg: v.get(3).copied().unwrap_or(0.0),
        c_deg: v.get(4).copied().unwrap_or(0.0),
    };
    let exact = tool_tip_error_exact5(&st, &lin, &turntable, pos, r, tool);
    let linear = tool_tip_error_linear5(&st, &lin, &turntable, pos, r, tool);
    if a.json {
        println!(
            "{}",
            serde_json::json!({"frame": "workpiece", "unit": "um",
                "exact_um": [exact.x, exact.y, exact.z],
                "first_order_um": [linear.x, linear.y, linear.z],
                "length_um": exact.norm(), "adequate": adequate})
        );
        return Ok(());
    }
    println!(
        "tool-tip error at x,y,z {:.3},{:.3},{:.3} mm, A {:.3}°, C {:.3}°, tool {:?} mm (workpiece frame):",
        pos[0], pos[1], pos[2], r.a_deg, r.c_deg, tool
    );
    println!(
        "  exact        {:+9.3} {:+9.3} {:+9.3} µm (length {:.3} µm)",
        exact.x,
        exact.y,
        exact.z,
        exact.norm()
    );
    println!(
        "  first order  {:+9.3} {:+9.3} {:+9.3} µm",
        linear.x, linear.y, linear.z
    );
    Ok(())
}

/// The volumetric polynomial as `geometry table --json` and
/// `fit-thermal --table` write it.
pub fn table_json(p: &tcomp_geometry::volumetric::VolumetricPoly) -> Result<serde_json::Value> {
    let mut v = serde_json::to_value(p)?;
    if let Some(o) = v.as_object_mut() {
        // On the board a term is 4 exponent/sensor bytes + 3 × i32 coefficients.
        o.insert(
            "bytes_on_board".into(),
            serde_json::json!(p.terms.len() * 16),
        );
        o.insert("unit".into(), serde_json::json!("um"));
    }
    Ok(v)
}

pub fn table_cmd(a: TableArgs) -> Result<()> {
    let ej = ErrorsJson::read(&a.model)?;
    let st = Structure::parse(&ej.structure)
        .with_context(|| format!("{}: structure", a.model.display()))?;
    tcomp_geometry::guard::refuse_model(&ej.unobservable_terms, &a.model, a.allow_unobservable)?;
    let adequate = model_adequacy(&ej, &a.model, a.accept_inadequate)?;
    let mut p = tcomp_geometry::volumetric::build(&st, ej.stroke_mm, &ej.to_errors()?, None)?;
    p.adequate = adequate;
    p.adequacy = ej.adequacy.clone();
    p.unobservable_terms = ej.unobservable_terms.clone();
    p.unobservable_accepted = a.allow_unobservable && !p.unobservable_terms.is_empty();
    let bytes = p.terms.len() * 16;
    if a.json {
        println!("{}", table_json(&p)?);
        return Ok(());
    }
    println!(
        "volumetric polynomial of {} ({}, strokes {:?} mm): {} terms (of 52 monomials × 3 directions), about {bytes} bytes on the board",
        a.model.display(),
        st,
        ej.stroke_mm,
        p.terms.len()
    );
    println!(
        "largest difference to the first-order kinematics on check points: {:.4} µm (terms below {} µm dropped)",
        p.max_fit_error_um,
        tcomp_geometry::volumetric::DROP_BELOW_UM
    );
    Ok(())
}

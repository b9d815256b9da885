//! `tcomp geometry score --model id.json --truth truth.json [--heldout DIR] [--json]`
//! (issue 29): an identified model against a machine given as tabulated
//! functions and held-out lines (`tcomp_geometry::score`).

use anyhow::{Context, Result};
use std::path::PathBuf;

use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::score::{read_dir_lines, score, TabulatedTruth};
use tcomp_geometry::study::ErrorsJson;

#[derive(clap::Args, Debug)]
pub struct ScoreArgs {
    /// The identified model (identify --json output).
    #[arg(long)]
    pub model: PathBuf,
    /// The machine as tabulated functions (geometry_rich_gen.py's truth.json).
    #[arg(long)]
    pub truth: PathBuf,
    /// Directory of held-out line files to predict.
    #[arg(long)]
    pub heldout: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

pub fn score_cmd(a: ScoreArgs) -> Result<()> {
    let ej = ErrorsJson::read(&a.model)?;
    let st = Structure::parse(&ej.structure)
        .with_context(|| format!("{}: structure", a.model.display()))?;
    let model = ej.to_errors()?;
    let truth = TabulatedTruth::read(&a.truth)?;
    let held = match &a.heldout {
        Some(d) => read_dir_lines(d)?,
        None => Vec::new(),
    };
    let s = score(&st, &model, &truth, &held);
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    println!(
        "worst term RMS {:.2} µm, {:.2} µrad (max {:.2} µm, {:.2} µrad); squareness off by {:.2}, {:.2}, {:.2} µrad",
        s.worst_rms_translational_um,
        s.worst_rms_angular_urad,
        s.worst_max_translational_um,
        s.worst_max_angular_urad,
        s.squareness_error_urad[0],
        s.squareness_error_urad[1],
        s.squareness_error_urad[2]
    );
    if let Some(h) = &s.heldout {
        println!(
            "{} held-out lines: RMS {:.2} µm → {:.2} µm ({:.1} % less)",
            h.lines, h.before_um, h.after_um, h.reduction_pct
        );
    }
    Ok(())
}

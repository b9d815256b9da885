//! Never silently wrong (issue 29): what a set of lines cannot determine
//! ends in a refusal naming it, or in a partial model whose undetermined
//! errors are marked `unobservable`, and the commands that use a model
//! (`geometry table`, `geometry tooltip`, `export --geometry` through the
//! table) refuse such a model unless told. Also the checks on the input
//! files that must name the file at fault.

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

use super::identify::{Identification, RANK_TOL};
use super::kinematics::Structure;
use super::lines::LineFile;

/// The structure every file shares; a file whose structure differs from
/// the others' (the majority) is named by its path.
pub fn common_structure(files: &[LineFile], paths: &[PathBuf]) -> Result<Structure> {
    let Some(first) = files.first() else {
        bail!("no line files");
    };
    let count = |s: &Structure| files.iter().filter(|f| f.structure == *s).count();
    let mut best = first.structure.clone();
    for f in files {
        if count(&f.structure) > count(&best) {
            best = f.structure.clone();
        }
    }
    let odd: Vec<String> = files
        .iter()
        .zip(paths)
        .filter(|(f, _)| f.structure != best)
        .map(|(f, p)| {
            format!(
                "{} (line {}, structure {})",
                p.display(),
                f.spec.id,
                f.structure
            )
        })
        .collect();
    if !odd.is_empty() {
        bail!(
            "{} differ{} in structure from the other {} files ({best}): {}",
            if odd.len() == 1 { "one file" } else { "files" },
            if odd.len() == 1 { "s" } else { "" },
            count(&best),
            odd.join("; ")
        );
    }
    Ok(best)
}

/// The one-line refusal for an identification that leaves errors
/// undetermined, or `Ok` when every error is determined or `partial` is set.
pub fn refuse_unobservable(id: &Identification, lines: usize, partial: bool) -> Result<()> {
    if id.unobservable_terms.is_empty() || partial {
        return Ok(());
    }
    bail!(
        "{lines} lines do not determine {} (rank {} of {}: {} direction(s) with relative singular value below {RANK_TOL:e}); measure the missing line(s) of the plan, or give --partial to write the rest with these marked unobservable",
        id.unobservable_terms.join(", "),
        id.rank,
        id.basis.columns.len(),
        id.unobservable.len()
    )
}

/// Refuse a model (identify --json output) that marks errors unobservable,
/// unless `allow` (the command's `--allow-unobservable`).
pub fn refuse_model(unobservable: &[String], path: &Path, allow: bool) -> Result<()> {
    if unobservable.is_empty() || allow {
        return Ok(());
    }
    bail!(
        "{}: the lines did not determine {} (marked unobservable); its values are not the machine's. Give --allow-unobservable to use it anyway",
        path.display(),
        unobservable.join(", ")
    )
}

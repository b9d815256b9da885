//! How `tcomp geometry identify` and `identify-rotary` state the verdict of
//! the stated adequacy test (`tcomp_geometry::adequacy`): the refusal
//! unless --accept-inadequate, the warning when going on, the verdict in
//! words. A leaf: both commands import it, it imports neither.

use anyhow::{bail, Result};
use tcomp_geometry::adequacy::Adequacy;

/// Refuse an inadequate model unless `accept` (--accept-inadequate):
/// `what` names the model, `fix` says what to measure.
pub fn refuse_inadequate(adq: &Adequacy, accept: bool, what: &str, fix: &str) -> Result<()> {
    if !adq.adequate && !accept {
        bail!("{}", adq.refusal(what, fix));
    }
    Ok(())
}

/// The warning (stderr, after the report) when going on with an
/// inadequate model (`model`: "model", "rotary model"); `None` when adequate.
pub fn inadequate_warning(adq: &Adequacy, model: &str) -> Option<String> {
    (!adq.adequate).then(|| {
        format!(
            "the {model} is inadequate ({}); going on (--accept-inadequate): marked \"adequate\": false, σ's inflated ×{:.1}",
            adq.failure, adq.sigma_inflation
        )
    })
}

/// The adequacy verdict, the σ inflation and the weakly determined
/// combinations in words (identify, identify-rotary).
pub fn print_adequacy(adq: &Adequacy) {
    print_verdict(adq);
    println!(
        "σ's printed are the posterior standard deviations at the stated noise × {:.2} (the measured misfit)",
        adq.sigma_inflation
    );
}

/// The adequacy verdict and the weakly determined combinations in words
/// (the σ's line is the caller's when its σ's come from elsewhere).
pub fn print_verdict(adq: &Adequacy) {
    println!("{}", adq.summary());
    if !adq.weak.is_empty() {
        println!("weakly determined combinations (relative singular value below 1e-2: their σ is over 100× the best-determined direction's):");
        for w in &adq.weak {
            println!(
                "  {} (relative singular value {:.1e})",
                w.words, w.relative_singular_value
            );
        }
    }
}

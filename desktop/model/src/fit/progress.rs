//! How a fit tells its caller how far it is. The library draws nothing:
//! `tcomp fit` and `bench-fit` turn these calls into a terminal bar.

/// Receives a fit's progress: stages one after another, each with steps
/// that may come from any training thread.
pub trait Progress: Sync {
    /// A stage begins: `"cross-validating dch3_um"`, `"GA-BPN dch3_um"`,
    /// `"hybrid dch3_um"`, `"fallback models"`.
    fn begin(&self, stage: &str);
    /// One step of the current stage: a GA generation or an accepted
    /// Levenberg–Marquardt step of one network.
    fn step(&self);
    /// The current stage ended.
    fn end(&self);
}

/// Reports nothing: the fit runs silent.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Progress for Silent {
    fn begin(&self, _stage: &str) {}
    fn step(&self) {}
    fn end(&self) {}
}

//! A candidate effect of `diagnose fit` fitted against the nominal: shared
//! by the tests of `open_effects` and the files it gathers them from.

use serde_json::Value;

use crate::diagnose::ident::{ModelFit, OutFit};

/// A fitted candidate against the nominal.
#[derive(Clone, Debug)]
pub struct Candidate {
    pub name: &'static str,
    pub params: Value,
    /// Outputs whose model changed.
    pub affected: Vec<usize>,
    pub fit: ModelFit,
    /// Extra fitted parameters (continuous and searched).
    pub k_extra: usize,
    /// Parameters that ended on the edge of their search range.
    pub at_bound: Vec<String>,
    pub evidence: Value,
}

pub fn with_outputs(base: &ModelFit, new: Vec<(usize, OutFit)>) -> ModelFit {
    let mut f = base.clone();
    for (o, of) in new {
        f.outs[o] = of;
    }
    f
}

//! The effects room: the candidate effects beyond the nominal and their
//! fits. The machine-file mode's (`effect_fit`: the `Evaluator`, grids and
//! `optim`; `placement`, `drift_family`), `diagnose fit`'s (`open_effects`
//! gathering `sensor_step`, `speed_law`, `candidate`) and the periodic
//! driver both modes test (`periodic`, `periodic_claim`).

mod candidate;
mod drift_family;
mod effect_fit;
pub(crate) mod lag_specific;
pub(crate) mod open_effects;
mod optim;
mod periodic;
pub(crate) mod periodic_claim;
pub(crate) mod placement;
mod sensor_step;
mod speed_law;

pub(crate) use drift_family::fit_alone;
pub(crate) use effect_fit::{
    fit_added, j_fit_of_raws, par_map, params_of, ActiveSet, Evaluator, FitResult, Projection,
    Stats,
};
pub(crate) use speed_law::STEEP_EXPONENTS;

//! The ident room: the nominal model `diagnose fit` identifies from the
//! runs themselves (`model.rs`: the modal network, its structure chosen by
//! BIC) and the least squares of one structure (`least_squares.rs`). The
//! fit mode, its effects and its reach all score against this nominal.

mod least_squares;
mod model;

pub use model::{ModelFit, OutFit, Problem, Structure, EXPONENTS, RIDGE, TAU_GRID};

//! `TCOMP_DIAG_TIMING`: whether the diagnosis prints where its time goes
//! (a leaf, read by `freedom.rs` and `knots.rs`).

/// `TCOMP_DIAG_TIMING` set: the diagnosis prints where its time goes.
pub(crate) fn timing() -> bool {
    std::env::var_os("TCOMP_DIAG_TIMING").is_some()
}

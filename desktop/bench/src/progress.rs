//! `bench-fit`'s progress bar on the terminal, as `tcomp fit` draws it: one
//! bar per stage of the fit (`tcomp_model` reports the stages and steps and
//! draws nothing).
//! Drawn on stderr, and only when stderr is a terminal (indicatif's rule).

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Mutex;
use tcomp_model::fit::progress::Progress;

/// The bar of the stage under way, if any.
#[derive(Default)]
pub struct Bar(Mutex<Option<ProgressBar>>);

impl Progress for Bar {
    fn begin(&self, stage: &str) {
        let pb = ProgressBar::new(1);
        if let Ok(style) =
            ProgressStyle::with_template("{msg:>18} [{bar:40}] {pos}/{len} {elapsed}")
        {
            pb.set_style(style.progress_chars("=> "));
        }
        pb.set_message(stage.to_string());
        if let Some(old) = self.lock().replace(pb) {
            old.finish_and_clear();
        }
    }

    fn step(&self) {
        if let Some(pb) = self.lock().as_ref() {
            pb.inc(1);
        }
    }

    fn end(&self) {
        if let Some(pb) = self.lock().take() {
            pb.finish_and_clear();
        }
    }
}

impl Bar {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<ProgressBar>> {
        // A panicking training thread leaves the bar usable.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

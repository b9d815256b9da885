//! The one app state every task of a board shares.

use crate::app::App;
use core::cell::RefCell;
use embassy_sync::blocking_mutex::Mutex;

/// The app state as the boards share it between their tasks: built once,
/// before the tasks start, and locked only between awaits.
pub type SharedApp<M, F> = Mutex<M, RefCell<App<F>>>;

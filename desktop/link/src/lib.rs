//! tcomp-link: the desktop's Modbus RTU master for the board (`board_link`:
//! `tcomp record` and `tcomp upload`; `commission`: `tcomp commission`).

pub mod board_link;
pub mod commission;

//! tcomp-link: the desktop's Modbus RTU master for the board (`board_link`:
//! `tcomp record` and `tcomp upload`).

pub mod board_link;

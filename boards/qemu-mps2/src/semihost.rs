//! Semihosting: the bench board's console, its command line, host files it
//! replays, and its exit status. Only the bench board uses it (a real board
//! halts on a BKPT without a debugger attached).
//!
//! cortex-m-semihosting exposes stdout/stderr and `debug::exit` (0/1 only),
//! so the file reads and SYS_EXIT_EXTENDED (any status code) are written here
//! on top of its `syscall!` macro.

use core::fmt::Write;

use cortex_m_semihosting::{hio, syscall};

/// Print a line on the host's stdout (the QEMU console). Never the Modbus UART.
pub fn log_args(args: core::fmt::Arguments) {
    if let Ok(mut out) = hio::hstdout() {
        let _ = out.write_fmt(args);
        let _ = out.write_str("\n");
    }
}

macro_rules! log {
    ($($arg:tt)*) => { $crate::semihost::log_args(format_args!($($arg)*)) };
}
/// `log!` by path (`use crate::semihost::log`), like any other item.
pub(crate) use log;

/// Stop QEMU with `code` as its process exit status (SYS_EXIT_EXTENDED with
/// ADP_Stopped_ApplicationExit, which QEMU maps to exit(code)).
pub fn exit(code: u32) -> ! {
    const ADP_STOPPED_APPLICATION_EXIT: usize = 0x20026;
    const SYS_EXIT_EXTENDED: usize = 0x20;
    let block = [ADP_STOPPED_APPLICATION_EXIT, code as usize];
    loop {
        // SAFETY: a semihosting call with a valid 2-word parameter block.
        unsafe { cortex_m_semihosting::syscall(SYS_EXIT_EXTENDED, &block) };
    }
}

/// The command line QEMU was given with `-append` (the program name first).
/// Returns the text in `buf`, or None when there is none or it does not fit.
pub fn command_line(buf: &mut [u8]) -> Option<&str> {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: SYS_GET_CMDLINE writes at most block[1] bytes into buf and
    // stores the length it wrote in block[1].
    let rc = unsafe {
        cortex_m_semihosting::syscall1(
            cortex_m_semihosting::nr::GET_CMDLINE,
            block.as_mut_ptr() as usize,
        )
    };
    if rc != 0 {
        return None;
    }
    let len = block[1].min(buf.len());
    core::str::from_utf8(buf.get(..len)?).ok()
}

/// A host file opened read-only through semihosting.
pub struct HostFile {
    handle: usize,
}

impl HostFile {
    /// `path_nul` must end with a NUL byte.
    pub fn open(path_nul: &[u8]) -> Option<HostFile> {
        if path_nul.last() != Some(&0) {
            return None;
        }
        const MODE_READ_BINARY: usize = 1; // "rb"
                                           // SAFETY: path is NUL-terminated; length excludes the NUL as the ABI asks.
        let rc = unsafe {
            syscall!(
                OPEN,
                path_nul.as_ptr(),
                MODE_READ_BINARY,
                path_nul.len() - 1
            )
        };
        if rc as isize == -1 {
            None
        } else {
            Some(HostFile { handle: rc })
        }
    }

    /// Read up to `buf.len()` bytes; returns how many were read (0 at the end).
    pub fn read(&mut self, buf: &mut [u8]) -> Result<usize, ()> {
        // SAFETY: READ writes at most buf.len() bytes into buf; it returns the
        // number of bytes NOT read.
        let not_read = unsafe { syscall!(READ, self.handle, buf.as_mut_ptr(), buf.len()) };
        if not_read > buf.len() {
            return Err(());
        }
        Ok(buf.len() - not_read)
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        // SAFETY: closes the handle we own.
        unsafe { syscall!(CLOSE, self.handle) };
    }
}

//! Files the bench board reads from the host over semihosting: run CSVs,
//! model images, golden vectors.

use static_cell::StaticCell;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;
use thermocomp_protocol::trace::TraceSample;

use crate::exit::exit_code;
use crate::host_trace;
use crate::semihost::{self, log};

/// Read a whole host file into `buf`; None (logged) when it cannot.
pub fn read_host_file<'a>(path: &str, buf: &'a mut [u8]) -> Option<&'a [u8]> {
    let mut path_nul = [0u8; 200];
    let dst = path_nul.get_mut(..path.len())?;
    dst.copy_from_slice(path.as_bytes());
    let Some(mut f) = semihost::HostFile::open(&path_nul[..=path.len()]) else {
        log!("cannot open {}", path);
        return None;
    };
    let mut n = 0;
    loop {
        let rest = buf.get_mut(n..)?;
        if rest.is_empty() {
            log!("{} is larger than {} bytes", path, n);
            return None;
        }
        match f.read(rest) {
            Ok(0) => return buf.get(..n),
            Ok(k) => n += k,
            Err(()) => {
                log!("cannot read {}", path);
                return None;
            }
        }
    }
}

/// Load and validate a model image from the host; a bad image is logged and
/// the board serves "no model".
pub fn load_model(path: &str) -> Option<Model> {
    static BUF: StaticCell<[u8; MAX_IMAGE_BYTES]> = StaticCell::new();
    let buf = BUF.try_init([0; MAX_IMAGE_BYTES])?;
    let bytes = read_host_file(path, buf)?;
    match Model::parse(bytes) {
        Ok(m) => {
            log!(
                "model {} loaded: version {}, crc {:#010x}, {} directions",
                path,
                m.model_version,
                m.crc,
                m.directions.len()
            );
            Some(m)
        }
        Err(e) => {
            log!("model {} refused: {:?}; serving no model", path, e);
            None
        }
    }
}

/// The next sample of a host trace; `None` at its end. A malformed line
/// ends the firmware with TRACE_ERROR (the host tests check the status).
pub fn next_sample_or_exit(trace: &mut host_trace::HostTrace) -> Option<TraceSample> {
    match trace.next_sample() {
        Ok(sample) => sample,
        Err(e) => {
            log!("trace error: {:?}", e);
            semihost::exit(exit_code::TRACE_ERROR)
        }
    }
}

pub fn open_trace(path: &str) -> host_trace::HostTrace {
    let mut path_nul = [0u8; 200];
    let Some(dst) = path_nul.get_mut(..path.len()) else {
        log!("trace path too long");
        semihost::exit(exit_code::BAD_COMMAND_LINE)
    };
    dst.copy_from_slice(path.as_bytes());
    match host_trace::HostTrace::open(&path_nul[..=path.len()]) {
        Ok(t) => t,
        Err(e) => {
            log!("cannot open trace {}: {:?}", path, e);
            semihost::exit(exit_code::TRACE_ERROR)
        }
    }
}

pub mod golden {
    use static_cell::StaticCell;

    /// Largest golden file the board reads.
    const MAX_GOLDEN_BYTES: usize = 256 * 1024;
    static BUF: StaticCell<[u8; MAX_GOLDEN_BYTES]> = StaticCell::new();

    /// The golden file's bytes (read once).
    pub fn load(path: &str) -> Option<&'static [u8]> {
        let buf = BUF.try_init([0; MAX_GOLDEN_BYTES])?;
        super::read_host_file(path, buf)
    }

    /// Run the math core's golden vectors from a host file; true when all pass.
    pub fn check_file(path: &str) -> bool {
        let Some(bytes) = load(path) else {
            return false;
        };
        match thermocomp_core::golden::check(bytes) {
            Ok(n) => {
                crate::semihost::log!(
                    "golden vectors {}: {} steps reproduced bit for bit: pass",
                    path,
                    n
                );
                true
            }
            Err(e) => {
                crate::semihost::log!("golden vectors {}: {:?}: FAIL", path, e);
                false
            }
        }
    }
}

//! The bench board's emulated sensors: a recorded run (run CSV on the host,
//! read through semihosting) replayed sample by sample.

use thermocomp_protocol::trace::{
    is_comment_or_blank, TraceError, TraceHeader, TraceSample, MAX_LINE,
};

use crate::semihost::HostFile;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplayError {
    /// The host file could not be opened or read.
    Host,
    /// A line longer than the parser accepts.
    LineTooLong,
    /// A line that is not valid UTF-8.
    NotText,
    /// The line number and what was wrong with it.
    Parse(u32, TraceError),
}

pub struct HostTrace {
    file: HostFile,
    buf: [u8; 1024],
    start: usize,
    end: usize,
    eof: bool,
    line_no: u32,
    header: TraceHeader,
}

impl HostTrace {
    /// Open `path_nul` (NUL-terminated) and read up to and including the header.
    pub fn open(path_nul: &[u8]) -> Result<HostTrace, ReplayError> {
        let file = HostFile::open(path_nul).ok_or(ReplayError::Host)?;
        let mut t = HostTrace {
            file,
            buf: [0; 1024],
            start: 0,
            end: 0,
            eof: false,
            line_no: 0,
            header: TraceHeader::parse("time_s").map_err(|e| ReplayError::Parse(0, e))?,
        };
        loop {
            let mut line = [0u8; MAX_LINE];
            let n = t
                .next_line(&mut line)?
                .ok_or(ReplayError::Parse(t.line_no, TraceError::NoTimeColumn))?;
            let text = core::str::from_utf8(&line[..n]).map_err(|_| ReplayError::NotText)?;
            if is_comment_or_blank(text) {
                continue;
            }
            t.header = TraceHeader::parse(text).map_err(|e| ReplayError::Parse(t.line_no, e))?;
            return Ok(t);
        }
    }

    pub fn header(&self) -> &TraceHeader {
        &self.header
    }

    /// The next sample, or None at the end of the file.
    pub fn next_sample(&mut self) -> Result<Option<TraceSample>, ReplayError> {
        loop {
            let mut line = [0u8; MAX_LINE];
            let Some(n) = self.next_line(&mut line)? else {
                return Ok(None);
            };
            let text = core::str::from_utf8(&line[..n]).map_err(|_| ReplayError::NotText)?;
            if is_comment_or_blank(text) {
                continue;
            }
            return TraceSample::parse(&self.header, text)
                .map(Some)
                .map_err(|e| ReplayError::Parse(self.line_no, e));
        }
    }

    /// Copy the next line (without the newline) into `out`.
    fn next_line(&mut self, out: &mut [u8; MAX_LINE]) -> Result<Option<usize>, ReplayError> {
        let mut len = 0usize;
        loop {
            if self.start == self.end {
                if self.eof {
                    return Ok(if len > 0 {
                        self.line_no += 1;
                        Some(len)
                    } else {
                        None
                    });
                }
                let n = self
                    .file
                    .read(&mut self.buf)
                    .map_err(|_| ReplayError::Host)?;
                self.start = 0;
                self.end = n;
                if n == 0 {
                    self.eof = true;
                }
                continue;
            }
            let b = self.buf[self.start];
            self.start += 1;
            match b {
                b'\n' => {
                    self.line_no += 1;
                    return Ok(Some(len));
                }
                b'\r' => {}
                _ => {
                    *out.get_mut(len).ok_or(ReplayError::LineTooLong)? = b;
                    len += 1;
                }
            }
        }
    }
}

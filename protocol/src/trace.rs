//! Replay of a recorded run (run CSV, `docs/formats/run-csv.md`) as sensor
//! input: the bench board's emulated sensors read a trace line by line and hand
//! out what the DS18B20s and the PLC would. Integer-only so the board and the
//! desktop quantise identically (bit-exact comparisons downstream).

use crate::MAX_CHANNELS;

/// Longest line the parser accepts (a 20-sensor row is about 250 bytes).
pub const MAX_LINE: usize = 512;
/// Most columns in a trace.
pub const MAX_COLUMNS: usize = 48;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TraceError {
    /// The header has no `time_s` column.
    NoTimeColumn,
    /// More columns than [`MAX_COLUMNS`].
    TooManyColumns,
    /// A row with a different number of fields than the header.
    FieldCount,
    /// A field that is not a decimal number (column index).
    BadNumber(u8),
    /// A value outside what the target type holds (column index).
    OutOfRange(u8),
    /// An empty `time_s` field.
    MissingTime,
}

/// One line for the desktop and the bench log; columns are counted from 1,
/// as a spreadsheet or `cut -f` would.
impl core::fmt::Display for TraceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            TraceError::NoTimeColumn => {
                write!(f, "the header has no `time_s` column")
            }
            TraceError::TooManyColumns => write!(f, "more than {MAX_COLUMNS} columns"),
            TraceError::FieldCount => write!(f, "the number of fields differs from the header's"),
            TraceError::BadNumber(c) => write!(
                f,
                "column {}: not a plain decimal number (e.g. 20.06; no exponent, no NaN)",
                u16::from(c) + 1
            ),
            TraceError::OutOfRange(c) => {
                write!(f, "column {}: value out of range", u16::from(c) + 1)
            }
            TraceError::MissingTime => write!(f, "`time_s` is empty"),
        }
    }
}

/// Which columns feed which input.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TraceHeader {
    columns: usize,
    /// Column index of `time_s` (the run format does not fix its place).
    time_column: u8,
    /// Column index of each temperature channel, in file order (`T_*`, `T01`).
    temperature_columns: heapless::Vec<u8, MAX_CHANNELS>,
    spindle_column: Option<u8>,
    /// Column of `dprobe_um`: the eddy-current probe's reading (µm), which
    /// the bench board's emulated probe gives (issue 28).
    probe_column: Option<u8>,
}

impl TraceHeader {
    pub fn parse(line: &str) -> Result<TraceHeader, TraceError> {
        let mut header = TraceHeader {
            columns: 0,
            time_column: 0,
            temperature_columns: heapless::Vec::new(),
            spindle_column: None,
            probe_column: None,
        };
        let mut time_seen = false;
        for (i, name) in line.trim_start_matches(BOM).trim().split(',').enumerate() {
            let name = name.trim();
            let idx = u8::try_from(i).map_err(|_| TraceError::TooManyColumns)?;
            if i >= MAX_COLUMNS {
                return Err(TraceError::TooManyColumns);
            }
            if name == "time_s" && !time_seen {
                header.time_column = idx;
                time_seen = true;
            } else if is_temperature_column(name) {
                // Channels beyond MAX_CHANNELS are ignored, as a board with 20
                // inputs would ignore a 21st sensor.
                let _ = header.temperature_columns.push(idx);
            } else if name == "spindle_rpm" {
                header.spindle_column = Some(idx);
            } else if name == "dprobe_um" {
                header.probe_column = Some(idx);
            }
            header.columns = i + 1;
        }
        if !time_seen {
            return Err(TraceError::NoTimeColumn);
        }
        Ok(header)
    }

    pub fn channels(&self) -> usize {
        self.temperature_columns.len()
    }

    /// The trace has a probe column (`dprobe_um`).
    pub fn has_probe(&self) -> bool {
        self.probe_column.is_some()
    }
}

/// The UTF-8 byte-order mark some spreadsheet exports put before the first
/// line of a file.
const BOM: char = '\u{feff}';

/// Whether a run-file line carries no row: blank, or `#` metadata (a
/// byte-order mark before it does not count).
pub fn is_comment_or_blank(line: &str) -> bool {
    let l = line.trim_start_matches(BOM);
    l.trim().is_empty() || l.starts_with('#')
}

/// `T_<name>` or `T<digits>`.
pub fn is_temperature_column(name: &str) -> bool {
    name.starts_with("T_")
        || name
            .strip_prefix('T')
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()))
}

/// One sample as the board's inputs see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraceSample {
    /// `time_s` in milliseconds.
    pub time_ms: u64,
    /// Temperatures in 1/16 °C (DS18B20 12-bit units), None where empty.
    pub temperatures: [Option<i32>; MAX_CHANNELS],
    /// Spindle speed in rpm, rounded; None where empty or absent.
    pub spindle_rpm: Option<i32>,
    /// Probe reading in 0.1 µm, rounded; None where empty or absent.
    pub probe_tenth_um: Option<i32>,
}

impl TraceSample {
    pub fn parse(header: &TraceHeader, line: &str) -> Result<TraceSample, TraceError> {
        let mut sample = TraceSample {
            time_ms: 0,
            temperatures: [None; MAX_CHANNELS],
            spindle_rpm: None,
            probe_tenth_um: None,
        };
        let mut fields = 0usize;
        let mut time_seen = false;
        for (i, field) in line.trim().split(',').enumerate() {
            fields = i + 1;
            if i >= header.columns {
                continue; // counted, rejected below
            }
            let field = field.trim();
            // i < columns <= MAX_COLUMNS < 256: never the error.
            let col = u8::try_from(i).map_err(|_| TraceError::TooManyColumns)?;
            if col == header.time_column {
                let ms = decimal_scaled(field, 1000, col)?.ok_or(TraceError::MissingTime)?;
                sample.time_ms = u64::try_from(ms).map_err(|_| TraceError::OutOfRange(col))?;
                time_seen = true;
            } else if let Some(slot) = header
                .temperature_columns
                .iter()
                .position(|&c| c == col)
                .and_then(|ch| sample.temperatures.get_mut(ch))
            {
                *slot = match decimal_scaled(field, 16, col)? {
                    Some(v) => Some(i32::try_from(v).map_err(|_| TraceError::OutOfRange(col))?),
                    None => None,
                };
            } else if header.spindle_column == Some(col) {
                sample.spindle_rpm = match decimal_scaled(field, 1, col)? {
                    Some(v) => Some(i32::try_from(v).map_err(|_| TraceError::OutOfRange(col))?),
                    None => None,
                };
            } else if header.probe_column == Some(col) {
                sample.probe_tenth_um = match decimal_scaled(field, 10, col)? {
                    Some(v) => Some(i32::try_from(v).map_err(|_| TraceError::OutOfRange(col))?),
                    None => None,
                };
            }
        }
        if fields != header.columns {
            return Err(TraceError::FieldCount);
        }
        if !time_seen {
            return Err(TraceError::MissingTime);
        }
        Ok(sample)
    }
}

/// Parse a plain decimal (`-12.3456`, `7`, `+0.5`) and return it times
/// `scale`, rounded to the nearest integer, ties away from zero, computed
/// exactly in integers. `Ok(None)` for an empty field. Exponents are refused:
/// the run format writes plain decimals.
pub fn decimal_scaled(field: &str, scale: i64, col: u8) -> Result<Option<i64>, TraceError> {
    if field.is_empty() {
        return Ok(None);
    }
    let bad = TraceError::BadNumber(col);
    let big = TraceError::OutOfRange(col);
    let (neg, digits) = if let Some(d) = field.strip_prefix('-') {
        (true, d)
    } else if let Some(d) = field.strip_prefix('+') {
        (false, d)
    } else {
        (false, field)
    };
    let (int_part, frac_part) = match digits.split_once('.') {
        Some((a, b)) => (a, b),
        None => (digits, ""),
    };
    if (int_part.is_empty() && frac_part.is_empty())
        || !int_part.bytes().all(|c| c.is_ascii_digit())
        || !frac_part.bytes().all(|c| c.is_ascii_digit())
    {
        return Err(bad);
    }
    // value = mantissa / 10^frac_digits; keep at most 9 fractional digits
    // (beyond that the rounding to 1/16 or 1 ms cannot change).
    let frac = frac_part.get(..9).unwrap_or(frac_part);
    let mut mantissa: i64 = 0;
    for c in int_part.bytes().chain(frac.bytes()) {
        mantissa = mantissa
            .checked_mul(10)
            .and_then(|m| m.checked_add(i64::from(c - b'0')))
            .ok_or(big)?;
    }
    let denom: i64 = frac.bytes().fold(1, |d, _| d * 10);
    let num = mantissa.checked_mul(scale).ok_or(big)?;
    // Round half away from zero on the magnitude, then apply the sign.
    let rounded = num.checked_add(denom / 2).ok_or(big)? / denom;
    Ok(Some(if neg { -rounded } else { rounded }))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn decimals_round_exactly_to_sixteenths() {
        assert_eq!(decimal_scaled("26.1909", 16, 1), Ok(Some(419))); // 419.05
        assert_eq!(decimal_scaled("-10.125", 16, 1), Ok(Some(-162)));
        assert_eq!(decimal_scaled("0.03125", 16, 1), Ok(Some(1))); // tie -> away
        assert_eq!(decimal_scaled("-0.03125", 16, 1), Ok(Some(-1)));
        assert_eq!(decimal_scaled("15", 1000, 0), Ok(Some(15000)));
        assert_eq!(decimal_scaled("", 16, 2), Ok(None));
        assert_eq!(decimal_scaled("1e3", 16, 2), Err(TraceError::BadNumber(2)));
        assert_eq!(decimal_scaled("-", 16, 2), Err(TraceError::BadNumber(2)));
        assert_eq!(
            decimal_scaled("99999999999999999999", 16, 2),
            Err(TraceError::OutOfRange(2))
        );
    }

    #[test]
    fn rows_map_temperature_columns_to_channels() {
        let h = TraceHeader::parse("time_s,spindle_rpm,T_t1,dch1_um,T02").unwrap();
        assert_eq!(h.channels(), 2);
        assert!(!h.has_probe());
        let p = TraceHeader::parse("time_s,T01,dprobe_um").unwrap();
        assert!(p.has_probe());
        assert_eq!(
            TraceSample::parse(&p, "1,20,-3.25").unwrap().probe_tenth_um,
            Some(-33)
        );
        assert_eq!(
            TraceSample::parse(&p, "1,20,").unwrap().probe_tenth_um,
            None
        );
        let s = TraceSample::parse(&h, "15,1250,-0.5,3.2,").unwrap();
        assert_eq!(s.time_ms, 15_000);
        assert_eq!(s.spindle_rpm, Some(1250));
        assert_eq!(s.temperatures[0], Some(-8));
        assert_eq!(s.temperatures[1], None);
        assert_eq!(
            TraceSample::parse(&h, "15,1250,1"),
            Err(TraceError::FieldCount)
        );
        assert_eq!(
            TraceSample::parse(&h, ",1,1,1,1"),
            Err(TraceError::MissingTime)
        );
        assert_eq!(TraceHeader::parse("t,T1"), Err(TraceError::NoTimeColumn));
    }

    #[test]
    fn a_spreadsheet_export_with_a_byte_order_mark_and_time_elsewhere_is_read() {
        // the run format fixes column names, not their order
        assert!(is_comment_or_blank("\u{feff}# machine: vmc"));
        assert!(!is_comment_or_blank("\u{feff}time_s,T_a"));
        let h = TraceHeader::parse("\u{feff}T_a,spindle_rpm,time_s,T_ambient").unwrap();
        assert_eq!(h.channels(), 2);
        let s = TraceSample::parse(&h, "20.5,3000,10,19.0").unwrap();
        assert_eq!(s.time_ms, 10_000);
        assert_eq!(s.temperatures[0], Some(328));
        assert_eq!(s.temperatures[1], Some(304));
        assert_eq!(s.spindle_rpm, Some(3000));
        assert_eq!(
            TraceSample::parse(&h, "20.5,3000,,19.0"),
            Err(TraceError::MissingTime)
        );
    }
}

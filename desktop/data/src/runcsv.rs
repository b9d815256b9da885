//! Run files: the CSV exchanged between the board, the desktop tools and users
//! (`docs/formats/run-csv.md`). Readers keep unknown columns; missing
//! values are empty fields; anything unparsable is reported by row and column.
//!
//! Values of the format's columns must be physically possible, so that a
//! typo or a corrupted export (a `1e300` °C cell) is refused by line and
//! column instead of poisoning a fit: see [`plausible_range`].

use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::Path;

use anyhow::{bail, Context, Result};

/// One run: metadata, the column names in file order, and the data by column.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Run {
    /// `# key: value` lines before the header, in file order.
    pub meta: Vec<(String, String)>,
    /// Column names in file order (including `time_s`).
    pub columns: Vec<String>,
    /// `data[c][r]`: value of column `c` in row `r`; `None` for an empty field.
    pub data: Vec<Vec<Option<f64>>>,
}

impl Run {
    /// Read a run file; errors name the file, the line and the column.
    pub fn read(path: &Path) -> Result<Run> {
        let file = std::fs::File::open(path)
            .with_context(|| format!("cannot open run file {}", path.display()))?;
        Run::from_reader(std::io::BufReader::new(file))
            .with_context(|| format!("in run file {}", path.display()))
    }

    pub fn from_reader<R: BufRead>(mut reader: R) -> Result<Run> {
        let mut run = Run::default();
        let (header, header_line) = read_head(&mut reader, &mut run.meta)?;
        let names = header_names(&header)?;
        // `time_s` may stand anywhere in the file; the run keeps it first
        // (the order every writer uses), the other columns in file order
        let Some(time_at) = names.iter().position(|c| c == "time_s") else {
            if let Some(why) = foreign_separator(&names) {
                bail!("{why}");
            }
            bail!(
                "header has no `time_s` column (columns: {})",
                names.join(",")
            );
        };
        let order: Vec<usize> = std::iter::once(time_at)
            .chain((0..names.len()).filter(|&i| i != time_at))
            .collect();
        run.columns = order.iter().map(|&i| names[i].clone()).collect();
        run.data = vec![Vec::new(); run.columns.len()];
        let ranges: Vec<_> = run.columns.iter().map(|c| plausible_range(c)).collect();
        // A newline appended to the input ends every row with one, so the
        // reader's line count after a row is always one past the row's last line.
        let mut rows = csv_rows(reader.chain(&b"\n"[..]));
        let mut record = csv::ByteRecord::new();
        while let Some(n) = next_row(&mut rows, &mut record, header_line, &names)? {
            // UTF-8 checked by `next_row`
            let in_file: Vec<&str> = record
                .iter()
                .map(|f| std::str::from_utf8(f).unwrap_or_default())
                .collect();
            if in_file.len() != run.columns.len() {
                // `20,5` for 20.5 splits a value in two
                let hint = if in_file.len() > run.columns.len() {
                    " (decimal commas? the format writes numbers with a decimal point, 20.5, and separates fields with commas: export it so)"
                } else {
                    ""
                };
                bail!(
                    "line {}: {} fields, header has {} columns{hint}",
                    n,
                    in_file.len(),
                    run.columns.len()
                );
            }
            for (c, &i) in order.iter().enumerate() {
                let f = field_value(in_file[i]);
                let v = if f.is_empty() {
                    None
                } else {
                    let v: f64 = f.parse().map_err(|_| {
                        let hint = if f.replacen(',', ".", 1).parse::<f64>().is_ok() {
                            " (a decimal comma: the format writes 20.5, not 20,5; export the file with decimal points)"
                        } else {
                            ""
                        };
                        anyhow::anyhow!(
                            "line {}, column `{}`: cannot parse `{}` as a number{hint}",
                            n,
                            run.columns[c],
                            f
                        )
                    })?;
                    if !v.is_finite() {
                        bail!(
                            "line {}, column `{}`: `{}` is not a finite number (a missing value is an empty field)",
                            n,
                            run.columns[c],
                            f
                        );
                    }
                    if let Some((lo, hi, unit)) = ranges[c] {
                        if !(lo..=hi).contains(&v) {
                            let hint = if unit == "°C" && (250.0..=400.0).contains(&v) {
                                " (kelvin? the format's temperatures are °C: subtract 273.15)"
                            } else {
                                ""
                            };
                            bail!(
                                "line {}, column `{}`: {f} {unit} is outside the possible {lo}..={hi} {unit}{hint}",
                                n,
                                run.columns[c],
                            );
                        }
                    }
                    Some(v)
                };
                run.data[c].push(v);
            }
            let r = run.data[0].len() - 1;
            match run.data[0][r] {
                None => bail!("line {}: `time_s` is empty", n),
                Some(t) if r > 0 && run.data[0][r - 1].is_some_and(|p| t <= p) => {
                    bail!("line {}: `time_s` {} is not after the previous row", n, t)
                }
                _ => {}
            }
        }
        if run.rows() == 0 {
            bail!("no data rows (only a header)");
        }
        Ok(run)
    }

    /// Refuse a run without temperature columns: the tools that model or
    /// compensate temperatures have nothing to work on.
    pub fn require_temperatures(&self) -> Result<()> {
        if self.temperature_columns().is_empty() {
            bail!(
                "no temperature columns (T_<name>) among {}",
                self.columns.join(",")
            );
        }
        Ok(())
    }

    /// [`Run::read`] and [`Run::require_temperatures`], errors naming the file.
    pub fn read_with_temperatures(path: &Path) -> Result<Run> {
        let run = Run::read(path)?;
        run.require_temperatures()
            .with_context(|| format!("in run file {}", path.display()))?;
        Ok(run)
    }

    pub fn rows(&self) -> usize {
        self.data.first().map_or(0, Vec::len)
    }

    pub fn col_index(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// The column's values, `None` where the field is empty.
    pub fn col(&self, name: &str) -> Option<&[Option<f64>]> {
        self.col_index(name).map(|i| self.data[i].as_slice())
    }

    /// `time_s` of row `r` (NaN where missing or past the end), without
    /// copying the column (for loops over rows).
    pub fn time_at(&self, r: usize) -> f64 {
        self.data
            .first()
            .and_then(|c| c.get(r).copied().flatten())
            .unwrap_or(f64::NAN)
    }

    /// `time_s` as plain numbers (never empty, checked by the reader).
    pub fn time_s(&self) -> Vec<f64> {
        self.data[0].iter().map(|v| v.unwrap_or(f64::NAN)).collect()
    }

    /// Names of the temperature columns (`T_...` or `T01`...), in file order.
    pub fn temperature_columns(&self) -> Vec<&str> {
        self.columns
            .iter()
            .filter(|c| is_temperature_column(c))
            .map(String::as_str)
            .collect()
    }

    /// Names of the measured thermal-error columns (`d<name>_um`), in file order.
    pub fn error_columns(&self) -> Vec<&str> {
        self.columns
            .iter()
            .filter(|c| is_error_column(c))
            .map(String::as_str)
            .collect()
    }

    /// The format's error reference: error columns are rises from the run's
    /// first sample unless the metadata says `error_reference: absolute`.
    /// For such a run, subtract each error column's first valid sample (the
    /// format's rule for tools that need rises) and return a one-line note
    /// saying so; `None` when the run is already relative. The metadata is
    /// rewritten to `relative`, so a second call changes nothing.
    pub fn errors_as_rises(&mut self, label: &str) -> Option<String> {
        if self.meta("error_reference") != Some("absolute") {
            return None;
        }
        let mut zeroed = Vec::new();
        for (c, name) in self.columns.iter().enumerate() {
            if !is_error_column(name) {
                continue;
            }
            let col = &mut self.data[c];
            let Some(first) = col.iter().flatten().copied().next() else {
                continue;
            };
            for v in col.iter_mut().flatten() {
                *v -= first;
            }
            zeroed.push(format!("{name} {first:+} µm"));
        }
        self.set_meta("error_reference", "relative");
        Some(format!(
            "{label}: error_reference is absolute; error columns taken as rises from their first valid samples ({})",
            if zeroed.is_empty() {
                "no error column".to_string()
            } else {
                zeroed.join(", ")
            }
        ))
    }

    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The 1-Wire ROM code each temperature column was recorded from
    /// (`# rom.T_<name>: 28FF4C1A0216035E`, written by `tcomp record`): 16
    /// hex digits, bytes in bus order (family code first, CRC-8 last).
    /// Columns without such a key are absent; a malformed or CRC-failing
    /// code, or one given for two columns, is an error naming its key.
    pub fn sensor_roms(&self) -> Result<BTreeMap<String, [u8; 8]>> {
        let mut out: BTreeMap<String, [u8; 8]> = BTreeMap::new();
        for (k, v) in &self.meta {
            let Some(column) = k.strip_prefix(ROM_KEY_PREFIX) else {
                continue;
            };
            let rom = parse_rom(v).with_context(|| format!("metadata `{k}`"))?;
            if let Some((other, _)) = out.iter().find(|(_, r)| **r == rom) {
                bail!("metadata `{k}`: the same ROM code as `{ROM_KEY_PREFIX}{other}`");
            }
            out.insert(column.to_string(), rom);
        }
        Ok(out)
    }

    /// Record the ROM code of temperature column `column` (`T_…`).
    pub fn set_sensor_rom(&mut self, column: &str, rom: &[u8; 8]) {
        self.set_meta(&format!("{ROM_KEY_PREFIX}{column}"), &format_rom(rom));
    }

    pub fn set_meta(&mut self, key: &str, value: &str) {
        match self.meta.iter_mut().find(|(k, _)| k == key) {
            Some(kv) => kv.1 = value.to_string(),
            None => self.meta.push((key.to_string(), value.to_string())),
        }
    }

    /// Append a column; its length must match the rows already present.
    pub fn push_column(&mut self, name: &str, values: Vec<Option<f64>>) -> Result<()> {
        if self.col_index(name).is_some() {
            bail!("column `{name}` exists already");
        }
        if !self.data.is_empty() && values.len() != self.rows() {
            bail!(
                "column `{name}` has {} values, run has {} rows",
                values.len(),
                self.rows()
            );
        }
        self.columns.push(name.to_string());
        self.data.push(values);
        Ok(())
    }

    /// Rows `[start, end)` as a new run with the same metadata and columns.
    pub fn slice_rows(&self, start: usize, end: usize) -> Run {
        let end = end.min(self.rows());
        let start = start.min(end);
        Run {
            meta: self.meta.clone(),
            columns: self.columns.clone(),
            data: self.data.iter().map(|c| c[start..end].to_vec()).collect(),
        }
    }

    /// The run without the temperature columns not named in `keep`.
    pub fn keep_temperatures(self, keep: &[String]) -> Run {
        let (mut columns, mut data) = (Vec::new(), Vec::new());
        for (c, d) in self.columns.into_iter().zip(self.data) {
            if !is_temperature_column(&c) || keep.contains(&c) {
                columns.push(c);
                data.push(d);
            }
        }
        Run {
            meta: self.meta,
            columns,
            data,
        }
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        self.write_to(&mut w)?;
        w.flush()?;
        Ok(())
    }

    pub fn write_to<W: Write>(&self, w: &mut W) -> Result<()> {
        for (k, v) in &self.meta {
            writeln!(w, "# {k}: {v}")?;
        }
        writeln!(w, "{}", self.columns.join(","))?;
        let mut line = String::new();
        for r in 0..self.rows() {
            line.clear();
            for (c, col) in self.data.iter().enumerate() {
                if c > 0 {
                    line.push(',');
                }
                if let Some(v) = col[r] {
                    // Shortest representation that round-trips exactly.
                    line.push_str(&format!("{v}"));
                }
            }
            writeln!(w, "{line}")?;
        }
        Ok(())
    }

    /// Metadata as a map (for JSON reports).
    pub fn meta_map(&self) -> BTreeMap<String, String> {
        self.meta.iter().cloned().collect()
    }
}

/// Metadata key prefix naming a temperature column's sensor by ROM code.
pub const ROM_KEY_PREFIX: &str = "rom.";

/// A ROM code as 16 hex digits, bytes in bus order (`28FF4C1A0216035E`).
pub fn format_rom(rom: &[u8; 8]) -> String {
    rom.iter().map(|b| format!("{b:02X}")).collect()
}

/// 16 hex digits (bus order) into a ROM code whose CRC-8 checks.
pub fn parse_rom(text: &str) -> Result<[u8; 8]> {
    let t = text.trim();
    if t.len() != 16 || !t.bytes().all(|c| c.is_ascii_hexdigit()) {
        bail!("ROM code `{t}` is not 16 hex digits");
    }
    let mut rom = [0u8; 8];
    for (i, b) in rom.iter_mut().enumerate() {
        *b = u8::from_str_radix(&t[2 * i..2 * i + 2], 16)?;
    }
    if rom == [0; 8] || thermocomp_core::image::rom_crc8(&rom[..7]) != rom[7] {
        bail!("ROM code `{t}` fails its CRC-8 (last byte)");
    }
    Ok(rom)
}

/// Coldest and hottest temperature a run may hold, °C: beyond any machine
/// shop (and the DS18B20's −55…125 °C), short of what a unit mix-up gives.
pub const TEMPERATURE_RANGE_C: (f64, f64) = (-60.0, 200.0);
/// Fastest spindle, rpm (high-speed spindles reach about 60 000).
pub const MAX_SPINDLE_RPM: f64 = 100_000.0;
/// Largest thermal error or probe reading, µm (0.1 m; real ones are < 1 mm).
pub const MAX_ERROR_UM: f64 = 100_000.0;
/// Largest axis position, mm or degrees.
pub const MAX_POSITION: f64 = 1.0e6;
/// Longest run, s (30 years).
pub const MAX_TIME_S: f64 = 1.0e9;

/// The values a column of the run format can physically hold (inclusive)
/// and their unit; `None` for columns the format does not define (kept as
/// they are, only required to be finite).
pub fn plausible_range(column: &str) -> Option<(f64, f64, &'static str)> {
    let (lo, hi) = TEMPERATURE_RANGE_C;
    if column == "time_s" {
        Some((0.0, MAX_TIME_S, "s"))
    } else if column == "spindle_rpm" {
        Some((0.0, MAX_SPINDLE_RPM, "rpm"))
    } else if column == "feed_activity" || column == "coolant_on" {
        Some((0.0, 1.0, ""))
    } else if is_temperature_column(column) {
        Some((lo, hi, "°C"))
    } else if is_error_column(column) {
        Some((-MAX_ERROR_UM, MAX_ERROR_UM, "µm"))
    } else if column.starts_with("pos_") {
        Some((-MAX_POSITION, MAX_POSITION, "mm or °"))
    } else {
        None
    }
}

/// `d<name>_um`: a measured thermal error.
pub fn is_error_column(name: &str) -> bool {
    name.starts_with('d') && name.ends_with("_um") && name.len() > 4
}

/// `T_<name>` or `T<digits>` (the format's two spellings of a temperature column).
pub fn is_temperature_column(name: &str) -> bool {
    name.starts_with("T_")
        || (name.len() > 1
            && name.starts_with('T')
            && name[1..].bytes().all(|b| b.is_ascii_digit()))
}

/// The `# key: value` lines before the header into `meta`, then the header
/// line (trimmed, without a byte-order mark) and its line number. Read line
/// by line here: csv would skip the metadata as comments, and it is kept.
fn read_head<R: BufRead>(
    reader: &mut R,
    meta: &mut Vec<(String, String)>,
) -> Result<(String, usize)> {
    let mut line = String::new();
    let mut header_line = 0usize;
    let header = loop {
        line.clear();
        header_line += 1;
        let n = header_line;
        let read = reader
            .read_line(&mut line)
            .with_context(|| format!("line {n}: not UTF-8 text"))?;
        if read == 0 {
            bail!("no header row (file is empty or only metadata)");
        }
        // a spreadsheet's UTF-8 export starts with a byte-order mark
        let t = if n == 1 {
            line.trim_start_matches('\u{feff}').trim()
        } else {
            line.trim()
        };
        if t.is_empty() {
            continue;
        }
        if let Some(m) = t.strip_prefix('#') {
            if let Some((k, v)) = m.split_once(':') {
                meta.push((k.trim().to_string(), v.trim().to_string()));
            }
            continue;
        }
        break t.to_string();
    };
    Ok((header, header_line))
}

/// Why a header without `time_s` is not the format's: a semicolon or tab
/// separated export (a spreadsheet in a locale with decimal commas).
fn foreign_separator(names: &[String]) -> Option<String> {
    let joined = names.join(",");
    for (sep, name) in [(';', "';'"), ('\t', "a tab")] {
        if joined.split(sep).any(|c| c.trim() == "time_s")
            || (names.len() == 1 && joined.contains(sep))
        {
            return Some(format!(
                "this file uses {name} as separator; export it as comma-separated, numbers with a decimal point (docs/formats/run-csv.md)"
            ));
        }
    }
    None
}

/// The header's column names, in file order, checked.
fn header_names(header: &str) -> Result<Vec<String>> {
    // names as written, spreadsheet quotes removed; the header is one
    // line, so a quote left open cannot run into the rows
    let mut header_fields = csv::StringRecord::new();
    csv_rows(header.as_bytes()).read_record(&mut header_fields)?;
    let names: Vec<String> = header_fields
        .iter()
        .map(|f| field_value(f).to_string())
        .collect();
    let mut seen = std::collections::HashSet::new();
    for c in &names {
        if !seen.insert(c) {
            bail!("header: column `{c}` appears twice");
        }
        // written back unquoted, such a name would split into two
        if c.contains(',') {
            bail!(
                "header: column `{c}` has a comma in its name (the format has none inside fields)"
            );
        }
    }
    Ok(names)
}

/// Read the next data row from `rows` (the input after the header, with a
/// newline appended) into `record` (fields as written, UTF-8, not
/// trimmed) and return its first line in the file; `None` at the end. Blank and comment lines are skipped,
/// a row not valid UTF-8 or with a quote left open is an error.
fn next_row<R: std::io::Read>(
    rows: &mut csv::Reader<R>,
    record: &mut csv::ByteRecord,
    header_line: usize,
    names: &[String],
) -> Result<Option<usize>> {
    loop {
        let more = rows.read_byte_record(record).map_err(|e| {
            let n = header_line as u64 + rows.position().line();
            match e.into_kind() {
                csv::ErrorKind::Io(io) => {
                    anyhow::Error::new(io).context(format!("line {n}: not UTF-8 text"))
                }
                _ => anyhow::anyhow!("line {n}: not readable as CSV"),
            }
        })?;
        if !more {
            return Ok(None);
        }
        // Line breaks inside a row only come from a quoted field whose
        // closing quote is missing or on a later line; the row is named
        // by its first line.
        let breaks = record.as_slice().iter().filter(|&&b| b == b'\n').count();
        let mut n = header_line + rows.position().line() as usize - 1 - breaks;
        if breaks > 0 {
            // A quote left open to the end took the appended newline
            // too: nothing is left to read and the count is one short.
            let line_after = rows.position().line();
            let mut rest = csv::ByteRecord::new();
            let _ = rows.read_byte_record(&mut rest);
            if rows.position().line() == line_after {
                n += 1;
            }
        }
        let mut in_file: Vec<&str> = Vec::with_capacity(record.len());
        for f in record.iter() {
            let Ok(f) = std::str::from_utf8(f) else {
                // the same words as for the lines read before the header
                return Err(anyhow::Error::new(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    "stream did not contain valid UTF-8",
                ))
                .context(format!("line {n}: not UTF-8 text")));
            };
            in_file.push(f);
        }
        if let Some(i) = in_file.iter().position(|f| f.contains('\n')) {
            let at = match names.get(i) {
                Some(c) => format!("line {n}, column `{c}`"),
                None => format!("line {n}"),
            };
            bail!(
                "{at}: a quoted field does not end on its line (a `\"` without its closing quote)"
            );
        }
        // Blank lines and comments, also the ones csv keeps: blanks only
        // (a CRLF's `\r` among them) or a `#` after blanks. An empty
        // field alone is a quoted `""`, not a blank line.
        let first = in_file.first().copied().unwrap_or_default();
        let blank = in_file.len() == 1 && !first.is_empty() && first.trim().is_empty();
        if !(blank || first.trim_start().starts_with('#')) {
            break Ok(Some(n));
        }
    }
}

/// The csv reader for a run's header and rows: double quotes as spreadsheets
/// write them, rows of any length (the run reader names the line of a
/// short or long one), lines starting with `#` skipped. Rows end at `\n`
/// only, as lines did before (a `\r` of CRLF is blank trimmed with the
/// field); fields are trimmed by [`field_value`].
fn csv_rows<R: std::io::Read>(input: R) -> csv::Reader<R> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::None)
        .comment(Some(b'#'))
        .terminator(csv::Terminator::Any(b'\n'))
        .from_reader(input)
}

/// A csv field as the run reader takes it: without surrounding blanks, and
/// without the quotes csv leaves in place when blanks stand before them
/// (`0, "20.5"`: csv takes a quote only at a field's very start).
fn field_value(field: &str) -> &str {
    if field.starts_with(char::is_whitespace) {
        unquote(field)
    } else {
        field.trim()
    }
}

/// A field without surrounding blanks and without the double quotes a
/// spreadsheet may put around it (the format has no commas inside fields).
pub fn unquote(field: &str) -> &str {
    let t = field.trim();
    t.strip_prefix('"')
        .and_then(|u| u.strip_suffix('"'))
        .map_or(t, str::trim)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = "# machine: turning-center-g200\n# run: warmup-4500rpm-a\n# source: simulated\ntime_s,spindle_rpm,coolant_on,T01,T02,T16,dx_um,extra\n0,4500,1,20.06,20.00,19.94,0.0,7\n10,4500,1,20.31,,19.94,-0.4,8\n";

    #[test]
    fn reads_the_format_example_and_keeps_unknown_columns() {
        let run = Run::from_reader(EXAMPLE.as_bytes()).unwrap();
        assert_eq!(run.meta("machine"), Some("turning-center-g200"));
        assert_eq!(run.rows(), 2);
        assert_eq!(run.temperature_columns(), vec!["T01", "T02", "T16"]);
        assert_eq!(run.error_columns(), vec!["dx_um"]);
        assert_eq!(run.col("T02").unwrap()[1], None);
        assert_eq!(run.col("extra").unwrap()[1], Some(8.0));
        let mut out = Vec::new();
        run.write_to(&mut out).unwrap();
        let again = Run::from_reader(out.as_slice()).unwrap();
        assert_eq!(again, run);
    }

    #[test]
    fn reads_a_spreadsheet_export_with_a_bom_quotes_crlf_and_time_s_not_first() {
        let text =
            "\u{feff}# run: excel\r\n\"T_01\",\"time_s\",dx_um\r\n\"20.5\",0,1\r\n20.75,10,\r\n";
        let run = Run::from_reader(text.as_bytes()).unwrap();
        assert_eq!(run.meta("run"), Some("excel"));
        assert_eq!(run.columns, vec!["time_s", "T_01", "dx_um"]);
        assert_eq!(run.time_s(), vec![0.0, 10.0]);
        assert_eq!(run.col("T_01").unwrap(), &[Some(20.5), Some(20.75)][..]);
        assert_eq!(run.col("dx_um").unwrap()[1], None);
        let err = format!(
            "{:#}",
            Run::from_reader("T_01,dx_um\n1,2\n".as_bytes()).unwrap_err()
        );
        assert!(
            err.contains("no `time_s` column") && err.contains("T_01,dx_um"),
            "{err}"
        );
        let err = format!(
            "{:#}",
            Run::from_reader("time_s,T_01\n0,abc\n".as_bytes()).unwrap_err()
        );
        assert!(err.contains("cannot parse `abc`"), "{err}");
    }

    #[test]
    fn csv_quoting_keeps_line_numbers_and_one_line_errors() {
        let err = |text: &str| format!("{:#}", Run::from_reader(text.as_bytes()).unwrap_err());
        // lines are counted over blank, comment and indented comment lines
        let e = err("# a: b\ntime_s,T01\n\n0,20\n# c\n  # d, e\r\n\r\n1,abc\n");
        assert!(
            e.contains("line 8, column `T01`: cannot parse `abc`"),
            "{e}"
        );
        // a quoted comma stays in its field
        let e = err("time_s,T01\n0,\"20,5\"\n");
        assert!(
            e.contains("line 2, column `T01`: cannot parse `20,5`"),
            "{e}"
        );
        // a quote left open is named by the line it opens on, in one line
        for (text, line) in [
            ("time_s,T01\n0,\"20\n1,21\n2,22\n", "line 2,"),
            ("time_s,T01\n0,20\n1,\"21", "line 3,"),
            ("time_s,T01\n0,20\n1,\"21\n", "line 3,"),
        ] {
            let e = err(text);
            assert!(e.contains(line) && e.contains("closing quote"), "{e}");
            assert!(!e.contains('\n'), "{e}");
        }
        // a quote after blanks, and blanks after a closing quote
        let run = Run::from_reader("time_s, \"T01\"\n0, \"20\" \n".as_bytes()).unwrap();
        assert_eq!(run.col("T01").unwrap(), &[Some(20.0)][..]);
        // a name with a comma would not survive writing
        assert!(err("\"a,b\",time_s\n1,0\n").contains("comma"));
        // a lone CR does not end a line, as before
        assert!(err("time_s,T01\n0,20\r1,21\n").contains("line 2: 3 fields"));
    }

    #[test]
    fn reports_row_and_column_of_bad_values() {
        let bad = "time_s,T01\n0,20\n1,abc\n";
        let err = format!("{:#}", Run::from_reader(bad.as_bytes()).unwrap_err());
        assert!(err.contains("line 3") && err.contains("T01"), "{err}");
        let nan = "time_s,T01\n0,NaN\n";
        assert!(Run::from_reader(nan.as_bytes()).is_err());
        let back = "time_s,T01\n5,1\n5,2\n";
        assert!(
            format!("{:#}", Run::from_reader(back.as_bytes()).unwrap_err()).contains("not after")
        );
        let short = "time_s,T01\n0\n";
        assert!(Run::from_reader(short.as_bytes()).is_err());
    }

    #[test]
    fn refuses_impossible_values_of_the_format_columns_only() {
        let err = |text: &str| format!("{:#}", Run::from_reader(text.as_bytes()).unwrap_err());
        for (text, col) in [
            ("time_s,T_a\n0,20\n1,1e300\n", "T_a"),
            ("time_s,T_a\n0,-61\n", "T_a"),
            ("time_s,T07\n0,200.5\n", "T07"),
            ("time_s,spindle_rpm\n0,-3000\n", "spindle_rpm"),
            ("time_s,spindle_rpm\n0,1e6\n", "spindle_rpm"),
            ("time_s,coolant_on\n0,2\n", "coolant_on"),
            ("time_s,feed_activity\n0,-0.1\n", "feed_activity"),
            ("time_s,dx_um\n0,2e5\n", "dx_um"),
            ("time_s,pos_x\n0,-1e7\n", "pos_x"),
            ("time_s,T_a\n-5,20\n", "time_s"),
        ] {
            let e = err(text);
            assert!(
                e.contains(&format!("column `{col}`")) && e.contains("outside"),
                "{e}"
            );
        }
        assert!(err("time_s,T_a\n0,20\n1,1e300\n").contains("line 3"));
        assert!(err("time_s,T_a\n0,inf\n").contains("not a finite number"));
        // The limits themselves, and unknown columns, are accepted.
        let ok = "time_s,T_a,spindle_rpm,coolant_on,dch5_um,pos_c,state\n0,-60,0,0,-100000,-1e6,1e300\n1,200,100000,1,100000,1e6,-1e300\n";
        let run = Run::from_reader(ok.as_bytes()).unwrap();
        assert_eq!(run.col("state").unwrap()[0], Some(1e300));
    }
}

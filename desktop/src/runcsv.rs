//! Run files: the CSV exchanged between the board, the desktop tools and users
//! (`../shared/formats/run-csv.md`). Readers keep unknown columns; missing
//! values are empty fields; anything unparsable is reported by row and column.

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

    pub fn from_reader<R: BufRead>(reader: R) -> Result<Run> {
        let mut run = Run::default();
        let mut lines = reader.lines().enumerate();
        // Metadata lines, then the header.
        let header = loop {
            let Some((n, line)) = lines.next() else {
                bail!("no header row (file is empty or only metadata)");
            };
            let line = line.with_context(|| format!("line {}: not UTF-8 text", n + 1))?;
            let t = line.trim();
            if t.is_empty() {
                continue;
            }
            if let Some(m) = t.strip_prefix('#') {
                if let Some((k, v)) = m.split_once(':') {
                    run.meta.push((k.trim().to_string(), v.trim().to_string()));
                }
                continue;
            }
            break t.to_string();
        };
        run.columns = header.split(',').map(|s| s.trim().to_string()).collect();
        if run.columns.first().map(String::as_str) != Some("time_s") {
            bail!(
                "line with header: first column must be `time_s`, found {:?}",
                run.columns.first()
            );
        }
        let mut seen = std::collections::HashSet::new();
        for c in &run.columns {
            if !seen.insert(c) {
                bail!("header: column `{c}` appears twice");
            }
        }
        run.data = vec![Vec::new(); run.columns.len()];
        for (n, line) in lines {
            let line = line.with_context(|| format!("line {}: not UTF-8 text", n + 1))?;
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = t.split(',').collect();
            if fields.len() != run.columns.len() {
                bail!(
                    "line {}: {} fields, header has {} columns",
                    n + 1,
                    fields.len(),
                    run.columns.len()
                );
            }
            for (c, f) in fields.iter().enumerate() {
                let f = f.trim();
                let v = if f.is_empty() {
                    None
                } else {
                    let v: f64 = f.parse().map_err(|_| {
                        anyhow::anyhow!(
                            "line {}, column `{}`: cannot parse {:?} as a number",
                            n + 1,
                            run.columns[c],
                            f
                        )
                    })?;
                    if !v.is_finite() {
                        bail!(
                            "line {}, column `{}`: {:?} is not a finite number",
                            n + 1,
                            run.columns[c],
                            f
                        );
                    }
                    Some(v)
                };
                run.data[c].push(v);
            }
            let r = run.data[0].len() - 1;
            match run.data[0][r] {
                None => bail!("line {}: `time_s` is empty", n + 1),
                Some(t) if r > 0 && run.data[0][r - 1].is_some_and(|p| t <= p) => {
                    bail!(
                        "line {}: `time_s` {} is not after the previous row",
                        n + 1,
                        t
                    )
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
            .filter(|c| c.starts_with('d') && c.ends_with("_um") && c.len() > 4)
            .map(String::as_str)
            .collect()
    }

    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
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

/// `T_<name>` or `T<digits>` (the format's two spellings of a temperature column).
pub fn is_temperature_column(name: &str) -> bool {
    name.starts_with("T_")
        || (name.len() > 1
            && name.starts_with('T')
            && name[1..].bytes().all(|b| b.is_ascii_digit()))
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
}

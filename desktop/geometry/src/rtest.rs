//! R-test files (docs/formats/rtest.md): reading and writing.
//!
//! Robust like the line and run readers: a byte-order mark and spreadsheet
//! quotes are accepted, columns are found by name in any order, and every
//! refusal is one line naming the file, the line and the column. Rows are
//! split by the `csv` crate (quotes as spreadsheets write them); the
//! metadata lines before the header are read here because csv would skip
//! them as comments.

use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::path::Path;

use super::rotary::model::rtcp_position;

/// The machine structure the format describes (spaces and case ignored).
pub const STRUCTURE: &str = "XYZ-A(x)-C(z) table";

/// The columns every file has.
pub const REQUIRED: [&str; 8] = [
    "pos_x", "pos_y", "pos_z", "a_deg", "c_deg", "dx_um", "dy_um", "dz_um",
];

/// How far a commanded position may sit from where the metadata's nominal
/// geometry puts the sphere at the row's angles [mm] (a CNC rounds to 1 µm;
/// a wrong sign of an angle or a wrong pivot is millimetres off).
pub const POSITION_TOLERANCE_MM: f64 = 0.01;

/// Largest reading [µm], angle [°], position [mm]; temperatures as run files.
const MAX_READING_UM: f64 = 1.0e5;
const MAX_ANGLE_DEG: f64 = 1.0e4;
const MAX_POSITION_MM: f64 = 1.0e6;
const TEMPERATURE_RANGE_C: (f64, f64) = tcomp_data::runcsv::TEMPERATURE_RANGE_C;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Simulated,
    Measured,
}

/// One pose of the cycle.
#[derive(Clone, Debug, PartialEq)]
pub struct RTestRow {
    pub pos_mm: [f64; 3],
    pub a_deg: f64,
    pub c_deg: f64,
    /// Sphere minus nest, workpiece frame, relative to the first row [µm].
    pub d_um: [f64; 3],
    pub time_s: Option<f64>,
    /// Sensor temperatures, in the order of [`RTestFile::sensors`] [°C].
    pub temps: Vec<f64>,
}

/// One R-test file.
#[derive(Clone, Debug, PartialEq)]
pub struct RTestFile {
    /// How errors and reports name the file.
    pub name: String,
    pub pivot_a_mm: [f64; 3],
    pub offset_c_mm: [f64; 3],
    pub nest_mm: [f64; 3],
    pub tool_mm: [f64; 3],
    pub source: Source,
    pub sensors_ppm_per_k: Option<f64>,
    /// Metadata the format does not define, kept in file order.
    pub other_meta: Vec<(String, String)>,
    /// Temperature columns without `T_`, in file order.
    pub sensors: Vec<String>,
    pub rows: Vec<RTestRow>,
}

fn number(p: &str, at: &str, what: &str, v: &str) -> Result<f64> {
    v.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| anyhow::anyhow!("{p}:{at}: {what}: `{v}` is not a number"))
}

fn triple(p: &str, line: usize, key: &str, v: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = v.split(',').map(tcomp_data::runcsv::unquote).collect();
    if parts.len() != 3 {
        bail!("{p}:{line}: {key} needs three comma-separated numbers (mm), got `{v}`");
    }
    let mut out = [0.0; 3];
    for (o, s) in out.iter_mut().zip(&parts) {
        *o = number(p, &line.to_string(), key, s)?;
        if o.abs() > MAX_POSITION_MM {
            bail!("{p}:{line}: {key}: {s} mm is beyond any machine");
        }
    }
    Ok(out)
}

/// `# key: value` lines before the header (with their line numbers), the
/// header's line number and the text from the header on.
type Head<'t> = (Vec<(usize, String, String)>, usize, &'t str);

fn head<'t>(text: &'t str, p: &str) -> Result<Head<'t>> {
    let mut meta = Vec::new();
    let mut offset = 0usize;
    for (i, raw) in text.split_inclusive('\n').enumerate() {
        let l = raw.trim();
        if l.is_empty() {
            offset += raw.len();
            continue;
        }
        if let Some(m) = l.strip_prefix('#') {
            if let Some((k, v)) = m.split_once(':') {
                let key = k.trim().to_string();
                if meta
                    .iter()
                    .any(|(_, mk, _): &(usize, String, String)| *mk == key)
                {
                    bail!("{p}:{}: metadata `{key}` given twice", i + 1);
                }
                meta.push((i + 1, key, v.trim().to_string()));
            }
            offset += raw.len();
            continue;
        }
        return Ok((meta, i + 1, &text[offset..]));
    }
    bail!("{p}: no column header (pos_x,pos_y,pos_z,a_deg,c_deg,dx_um,dy_um,dz_um)")
}

fn csv_reader(input: &[u8]) -> csv::Reader<&[u8]> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(input)
}

/// Where each column the reader uses stands in the header.
struct Columns {
    names: Vec<String>,
    required: [usize; 8],
    time: Option<usize>,
    temps: Vec<(usize, String)>,
}

fn columns(p: &str, hn: usize, header: &csv::StringRecord) -> Result<Columns> {
    let names: Vec<String> = header
        .iter()
        .map(|c| tcomp_data::runcsv::unquote(c).to_string())
        .collect();
    for (i, c) in names.iter().enumerate() {
        if names[..i].contains(c) {
            bail!("{p}:{hn}: column `{c}` appears twice");
        }
        if c == "T_" {
            bail!("{p}:{hn}: temperature column `T_` has no sensor name");
        }
    }
    let find = |n: &str| names.iter().position(|c| c == n);
    let mut required = [0usize; 8];
    for (slot, n) in required.iter_mut().zip(REQUIRED) {
        *slot = find(n).ok_or_else(|| {
            anyhow::anyhow!(
                "{p}:{hn}: missing column `{n}` (columns: {})",
                names.join(",")
            )
        })?;
    }
    let temps = (names.iter().enumerate())
        .filter_map(|(i, c)| c.strip_prefix("T_").map(|s| (i, s.to_string())))
        .collect();
    Ok(Columns {
        required,
        time: find("time_s"),
        temps,
        names,
    })
}

impl RTestFile {
    pub fn read(path: &Path) -> Result<RTestFile> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let text = String::from_utf8(bytes)
            .map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parse the text of an R-test file; `name` names it in errors.
    pub fn parse(text: &str, name: &str) -> Result<RTestFile> {
        let p = name;
        // a spreadsheet's UTF-8 export starts with a byte-order mark
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let (meta, hn, rest) = head(text, p)?;
        let get = |k: &str| -> Result<(usize, &str)> {
            meta.iter()
                .find(|(_, mk, _)| mk == k)
                .map(|(n, _, v)| (*n, v.as_str()))
                .ok_or_else(|| anyhow::anyhow!("{p}: missing metadata '# {k}: …'"))
        };
        let (n, s) = get("structure")?;
        let norm = |s: &str| -> String {
            s.chars()
                .filter(|c| !c.is_whitespace())
                .collect::<String>()
                .to_lowercase()
        };
        if norm(s) != norm(STRUCTURE) {
            bail!("{p}:{n}: structure `{s}` is not the format's `{STRUCTURE}`");
        }
        let tri = |k: &str| -> Result<[f64; 3]> {
            let (n, v) = get(k)?;
            triple(p, n, k, v)
        };
        let (pivot_a_mm, offset_c_mm, nest_mm, tool_mm) = (
            tri("pivot_a_mm")?,
            tri("offset_c_mm")?,
            tri("nest_mm")?,
            tri("tool_mm")?,
        );
        let (n, s) = get("source")?;
        let source = match s {
            "simulated" => Source::Simulated,
            "measured" => Source::Measured,
            _ => bail!("{p}:{n}: source must be 'simulated' or 'measured', got `{s}`"),
        };
        let sensors_ppm_per_k = match meta.iter().find(|(_, k, _)| k == "sensors_ppm_per_k") {
            Some((n, k, v)) => Some(number(p, &n.to_string(), k, v)?),
            None => None,
        };
        const KNOWN: [&str; 7] = [
            "structure",
            "pivot_a_mm",
            "offset_c_mm",
            "nest_mm",
            "tool_mm",
            "source",
            "sensors_ppm_per_k",
        ];
        let other_meta = (meta.iter())
            .filter(|(_, k, _)| !KNOWN.contains(&k.as_str()))
            .map(|(_, k, v)| (k.clone(), v.clone()))
            .collect();

        let mut rdr = csv_reader(rest.as_bytes());
        let mut header = csv::StringRecord::new();
        rdr.read_record(&mut header)
            .map_err(|_| anyhow::anyhow!("{p}:{hn}: the header is not readable as CSV"))?;
        let cols = columns(p, hn, &header)?;
        let mut f = RTestFile {
            name: name.to_string(),
            pivot_a_mm,
            offset_c_mm,
            nest_mm,
            tool_mm,
            source,
            sensors_ppm_per_k,
            other_meta,
            sensors: cols.temps.iter().map(|(_, s)| s.clone()).collect(),
            rows: Vec::new(),
        };
        let mut rec = csv::StringRecord::new();
        loop {
            let more = rdr.read_record(&mut rec).map_err(|e| {
                let line = e.position().map_or(hn, |q| hn + q.line() as usize - 1);
                anyhow::anyhow!("{p}:{line}: not readable as CSV text")
            })?;
            if !more {
                break;
            }
            let line = hn + rec.position().map_or(1, |q| q.line() as usize) - 1;
            if rec.len() == 1 && rec.get(0).is_some_and(|s| s.is_empty()) {
                continue; // a line of blanks
            }
            f.rows.push(row(p, line, &cols, &rec, &f)?);
        }
        f.check_rows()?;
        Ok(f)
    }

    fn check_rows(&self) -> Result<()> {
        let p = &self.name;
        let Some(first) = self.rows.first() else {
            bail!("{p}: no data rows");
        };
        if self.rows.len() < 2 {
            bail!("{p}: one row only; a cycle needs the zeroing row and at least one more");
        }
        if first.d_um.iter().any(|v| v.abs() > 5e-4) {
            bail!(
                "{p}: the first row reads {},{},{} µm; readings are zeroed there, so it must be 0,0,0",
                first.d_um[0], first.d_um[1], first.d_um[2]
            );
        }
        Ok(())
    }

    /// The file as text, in the format (metadata, header, rows).
    pub fn to_text(&self) -> String {
        let t = |v: [f64; 3]| format!("{},{},{}", fmt(v[0]), fmt(v[1]), fmt(v[2]));
        let mut out = String::new();
        let _ = writeln!(out, "# structure: {STRUCTURE}");
        let _ = writeln!(out, "# pivot_a_mm: {}", t(self.pivot_a_mm));
        let _ = writeln!(out, "# offset_c_mm: {}", t(self.offset_c_mm));
        let _ = writeln!(out, "# nest_mm: {}", t(self.nest_mm));
        let _ = writeln!(out, "# tool_mm: {}", t(self.tool_mm));
        let src = match self.source {
            Source::Simulated => "simulated",
            Source::Measured => "measured",
        };
        let _ = writeln!(out, "# source: {src}");
        if let Some(v) = self.sensors_ppm_per_k {
            let _ = writeln!(out, "# sensors_ppm_per_k: {}", fmt(v));
        }
        for (k, v) in &self.other_meta {
            let _ = writeln!(out, "# {k}: {v}");
        }
        let has_time = self.rows.iter().any(|r| r.time_s.is_some());
        let mut header = REQUIRED.join(",");
        if has_time {
            header.push_str(",time_s");
        }
        for s in &self.sensors {
            header.push_str(",T_");
            header.push_str(s);
        }
        let _ = writeln!(out, "{header}");
        for r in &self.rows {
            let _ = write!(
                out,
                "{:.6},{:.6},{:.6},{:.4},{:.4},{:.4},{:.4},{:.4}",
                r.pos_mm[0],
                r.pos_mm[1],
                r.pos_mm[2],
                r.a_deg,
                r.c_deg,
                r.d_um[0],
                r.d_um[1],
                r.d_um[2]
            );
            if has_time {
                let _ = write!(out, ",{:.1}", r.time_s.unwrap_or(0.0));
            }
            for v in &r.temps {
                let _ = write!(out, ",{v:.3}");
            }
            out.push('\n');
        }
        // "-0.0000" reads back as 0; keep the text tidy anyway
        out.replace(",-0.0000", ",0.0000")
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_text()).with_context(|| format!("writing {}", path.display()))
    }
}

/// One data row, checked.
fn row(
    p: &str,
    line: usize,
    cols: &Columns,
    rec: &csv::StringRecord,
    f: &RTestFile,
) -> Result<RTestRow> {
    if rec.len() != cols.names.len() {
        bail!(
            "{p}:{line}: {} fields, the header has {}",
            rec.len(),
            cols.names.len()
        );
    }
    let cell = |i: usize| -> Result<f64> {
        let raw = rec.get(i).unwrap_or_default();
        let v = tcomp_data::runcsv::unquote(raw);
        let at = format!("{line}, column `{}`", cols.names[i]);
        if v.contains('\n') {
            bail!("{p}:{at}: a quoted field does not end on its line");
        }
        if v.is_empty() {
            bail!("{p}:{at}: empty field (every pose needs every value)");
        }
        number(p, &at, "value", v).map_err(|_| anyhow::anyhow!("{p}:{at}: `{v}` is not a number"))
    };
    let bounded = |i: usize, lim: f64, unit: &str| -> Result<f64> {
        let v = cell(i)?;
        if v.abs() > lim {
            bail!(
                "{p}:{line}, column `{}`: {v} {unit} is beyond ±{lim} {unit}",
                cols.names[i]
            );
        }
        Ok(v)
    };
    let r = &cols.required;
    let pos_mm = [
        bounded(r[0], MAX_POSITION_MM, "mm")?,
        bounded(r[1], MAX_POSITION_MM, "mm")?,
        bounded(r[2], MAX_POSITION_MM, "mm")?,
    ];
    let a_deg = bounded(r[3], MAX_ANGLE_DEG, "°")?;
    let c_deg = bounded(r[4], MAX_ANGLE_DEG, "°")?;
    let d_um = [
        bounded(r[5], MAX_READING_UM, "µm")?,
        bounded(r[6], MAX_READING_UM, "µm")?,
        bounded(r[7], MAX_READING_UM, "µm")?,
    ];
    let expect = rtcp_position(
        f.pivot_a_mm,
        f.offset_c_mm,
        f.nest_mm,
        f.tool_mm,
        a_deg,
        c_deg,
    );
    for k in 0..3 {
        if (pos_mm[k] - expect[k]).abs() > POSITION_TOLERANCE_MM {
            bail!(
                "{p}:{line}, column `{}`: {} mm is not where A = {a_deg}°, C = {c_deg}° put the nest ({:.3} mm from the metadata's pivot, offset, nest and tool)",
                cols.names[r[k]], pos_mm[k], expect[k]
            );
        }
    }
    let time_s = match cols.time {
        Some(i) => {
            let t = bounded(i, tcomp_data::runcsv::MAX_TIME_S, "s")?;
            if let Some(prev) = f.rows.last().and_then(|r| r.time_s) {
                if !(t > prev) {
                    bail!("{p}:{line}, column `time_s`: {t} s is not after the previous row ({prev} s)");
                }
            }
            Some(t)
        }
        None => None,
    };
    let mut temps = Vec::with_capacity(cols.temps.len());
    for (i, _) in &cols.temps {
        let t = cell(*i)?;
        let (lo, hi) = TEMPERATURE_RANGE_C;
        if !(lo..=hi).contains(&t) {
            bail!(
                "{p}:{line}, column `{}`: {t} °C is outside the possible {lo}..={hi} °C",
                cols.names[*i]
            );
        }
        temps.push(t);
    }
    Ok(RTestRow {
        pos_mm,
        a_deg,
        c_deg,
        d_um,
        time_s,
        temps,
    })
}

/// Shortest decimal that reads back to the same f64.
fn fmt(v: f64) -> String {
    let s = format!("{v}");
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

#[cfg(test)]
#[path = "rtest_tests.rs"]
mod tests;

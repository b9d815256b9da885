//! Displacement-line files (docs/formats/displacement-lines.md): reading,
//! writing, and the measurement plan of 14 lines (docs/geometry.md).

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use super::identify::{LineKind, LineObs, Observation};
use super::kinematics::Structure;

/// Forward or backward run of a line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Run {
    Forward,
    Backward,
    /// The writer averaged both directions (or measured one and said nothing).
    Single,
}

/// A line of the plan: where it runs and where the reflector sits.
#[derive(Clone, Debug, PartialEq)]
pub struct LineSpec {
    pub id: String,
    pub start_mm: [f64; 3],
    /// Unit vector of travel.
    pub direction: [f64; 3],
    pub length_mm: f64,
    pub tool_offset_mm: [f64; 3],
    /// What the line is for (docs, `tcomp geometry plan`).
    pub purpose: String,
    /// What the instrument reads: displacement along the travel (laser
    /// interferometer) or straightness along `sense`.
    pub kind: LineKind,
    /// Unit vector the reading is along (`direction` for displacement).
    pub sense: [f64; 3],
}

impl LineSpec {
    /// Target positions along the line: `n_targets` equally spaced, both ends included.
    pub fn targets(&self, n_targets: usize) -> Vec<(f64, [f64; 3])> {
        let n = n_targets.max(2);
        (0..n)
            .map(|i| {
                let s = self.length_mm * i as f64 / (n - 1) as f64;
                let p = [0, 1, 2].map(|k| self.start_mm[k] + s * self.direction[k]);
                (s, p)
            })
            .collect()
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / n)
}

fn line(id: usize, from: [f64; 3], to: [f64; 3], tool: [f64; 3], purpose: &str) -> LineSpec {
    let d = [to[0] - from[0], to[1] - from[1], to[2] - from[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    LineSpec {
        id: format!("L{id:02}"),
        start_mm: from,
        direction: unit(d),
        length_mm: len,
        tool_offset_mm: tool,
        purpose: purpose.to_string(),
        kind: LineKind::Displacement,
        sense: unit(d),
    }
}

/// The 14 lines in the working volume [0, X]×[0, Y]×[0, Z] (docs/geometry.md).
/// Ends sit on the 3×3×3 grid of stroke halves; the set was chosen by a
/// D-optimal search (examples/geo_plan_search.rs) for the default model
/// degrees (`identify::Degrees::default()`). `tool_mm` is the reflector's
/// length below the spindle gauge point, `side_mm` its lateral offset on
/// the lines that need one (the only Abbe arm for the angles of the last
/// axis in the chain), and a few lines use a long extension (2.5 × tool_mm).
pub fn plan14(stroke_mm: [f64; 3], tool_mm: f64, side_mm: f64) -> Vec<LineSpec> {
    let at = |h: [u8; 3]| [0, 1, 2].map(|k| stroke_mm[k] * h[k] as f64 / 2.0);
    let t_x = [side_mm, 0.0, tool_mm];
    let t_y = [0.0, side_mm, tool_mm];
    let t_xy = [side_mm, side_mm, tool_mm];
    let t_long = [0.0, 0.0, 2.5 * tool_mm];
    let t_mx = [-side_mm, 0.0, tool_mm];
    let l = |id, a, b, t, why| line(id, at(a), at(b), t, why);
    vec![
        l(1, [0, 0, 0], [2, 2, 2], t_x, "body diagonal"),
        l(2, [2, 0, 0], [0, 2, 2], t_xy, "body diagonal"),
        l(3, [0, 2, 0], [2, 0, 2], t_xy, "body diagonal"),
        l(4, [2, 2, 0], [0, 0, 2], t_long, "body diagonal"),
        l(5, [2, 0, 0], [1, 2, 2], t_long, "half-body diagonal"),
        l(6, [0, 0, 0], [2, 2, 0], t_y, "XY face diagonal, bottom"),
        l(7, [2, 0, 2], [0, 2, 2], t_mx, "XY face diagonal, top"),
        l(8, [0, 2, 0], [2, 2, 2], t_long, "XZ face diagonal, back"),
        l(9, [2, 0, 0], [0, 0, 2], t_mx, "XZ face diagonal, front"),
        l(10, [2, 0, 0], [2, 2, 2], t_mx, "YZ face diagonal, right"),
        l(11, [2, 2, 0], [2, 0, 2], t_mx, "YZ face diagonal, right"),
        l(
            12,
            [0, 0, 0],
            [0, 2, 0],
            t_x,
            "Y axis, reflector offset in x",
        ),
        l(
            13,
            [2, 0, 2],
            [2, 2, 2],
            t_long,
            "Y axis, top right, long reflector",
        ),
        l(
            14,
            [0, 0, 0],
            [0, 0, 2],
            t_xy,
            "Z axis, reflector offset in x and y",
        ),
    ]
}

/// One line file.
#[derive(Clone, Debug)]
pub struct LineFile {
    pub spec: LineSpec,
    pub structure: Structure,
    pub run: Run,
    pub temperature_state: Option<String>,
    pub source: String,
    pub s_mm: Vec<f64>,
    pub pos_mm: Vec<[f64; 3]>,
    pub disp_um: Vec<f64>,
    /// Temperature columns (name without `T_`, values per target).
    pub temps: Vec<(String, Vec<f64>)>,
}

fn triple(path: &Path, lineno: usize, key: &str, v: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = v.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!(
            "{}:{lineno}: {key} needs three comma-separated numbers, got `{v}`",
            path.display()
        );
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| {
                anyhow::anyhow!("{}:{lineno}: {key}: `{p}` is not a number", path.display())
            })?;
    }
    Ok(out)
}

/// A line file's metadata, column header and data lines, numbered.
type Sections<'t> = (
    BTreeMap<String, (usize, String)>,
    Option<(usize, Vec<String>)>,
    Vec<(usize, &'t str)>,
);

/// Metadata (`# key: value`, with line numbers), the column header and
/// the data lines (with line numbers) of a line file's text.
fn sections<'t>(text: &'t str, path: &Path) -> Result<Sections<'t>> {
    let p = path.display();
    let mut meta: BTreeMap<String, (usize, String)> = BTreeMap::new();
    let mut header: Option<(usize, Vec<String>)> = None;
    let mut data: Vec<(usize, &str)> = Vec::new();
    // a spreadsheet's UTF-8 export starts with a byte-order mark
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    for (i, raw) in text.lines().enumerate() {
        let lineno = i + 1;
        let l = raw.trim();
        if l.is_empty() {
            continue;
        }
        if let Some(m) = l.strip_prefix('#') {
            if header.is_some() {
                continue; // comments after the header are allowed and ignored
            }
            let Some((k, v)) = m.split_once(':') else {
                bail!("{p}:{lineno}: metadata line must be '# key: value', got `{l}`");
            };
            meta.insert(k.trim().to_string(), (lineno, v.trim().to_string()));
        } else if header.is_none() {
            header = Some((
                lineno,
                l.split(',')
                    .map(|c| tcomp_data::runcsv::unquote(c).to_string())
                    .collect(),
            ));
        } else {
            data.push((lineno, l));
        }
    }
    Ok((meta, header, data))
}

impl LineFile {
    pub fn read(path: &Path) -> Result<LineFile> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text, path)
    }

    /// Parse the text of a line file; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<LineFile> {
        let p = path.display();
        let (meta, header, data) = sections(text, path)?;
        let get = |k: &str| -> Result<(usize, &str)> {
            meta.get(k)
                .map(|(n, v)| (*n, v.as_str()))
                .ok_or_else(|| anyhow::anyhow!("{p}: missing metadata '# {k}: …'"))
        };
        let (_, id) = get("line")?;
        let (n, v) = get("start_mm")?;
        let start_mm = triple(path, n, "start_mm", v)?;
        let (n, v) = get("direction")?;
        let dir = triple(path, n, "direction", v)?;
        let norm = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        if !((norm - 1.0).abs() < 1e-3) {
            bail!("{p}:{n}: direction `{v}` is not a unit vector (length {norm:.4})");
        }
        let direction = dir.map(|c| c / norm);
        let (n, v) = get("tool_offset_mm")?;
        let tool_offset_mm = triple(path, n, "tool_offset_mm", v)?;
        let (n, v) = get("structure")?;
        let structure = Structure::parse(v).with_context(|| format!("{p}:{n}"))?;
        let (n, source) = get("source")?;
        if source != "measured" && source != "simulated" {
            bail!("{p}:{n}: source must be 'measured' or 'simulated', got `{source}`");
        }
        let run = match meta.get("run") {
            None => Run::Single,
            Some((_, r)) if r == "forward" => Run::Forward,
            Some((_, r)) if r == "backward" => Run::Backward,
            Some((n, r)) => bail!("{p}:{n}: run must be 'forward' or 'backward', got `{r}`"),
        };
        let temperature_state = meta.get("temperature_state").map(|(_, v)| v.clone());
        let (kind, sense) = measures(&meta, path, direction)?;

        let Some((hn, cols)) = header else {
            bail!("{p}: no column header (s_mm,pos_x,pos_y,pos_z,disp_um)");
        };
        let col = |name: &str| -> Result<usize> {
            cols.iter()
                .position(|c| c == name)
                .ok_or_else(|| anyhow::anyhow!("{p}:{hn}: missing column {name}"))
        };
        let (cs, cx, cy, cz, cd) = (
            col("s_mm")?,
            col("pos_x")?,
            col("pos_y")?,
            col("pos_z")?,
            col("disp_um")?,
        );
        let tcols: Vec<(usize, String)> = cols
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.strip_prefix("T_").map(|n| (i, n.to_string())))
            .collect();
        let mut f = LineFile {
            spec: LineSpec {
                id: id.to_string(),
                start_mm,
                direction,
                length_mm: 0.0,
                tool_offset_mm,
                purpose: String::new(),
                kind,
                sense,
            },
            structure,
            run,
            temperature_state,
            source: source.to_string(),
            s_mm: Vec::new(),
            pos_mm: Vec::new(),
            disp_um: Vec::new(),
            temps: tcols.iter().map(|(_, n)| (n.clone(), Vec::new())).collect(),
        };
        for (lineno, l) in data {
            let cells: Vec<&str> = l.split(',').map(tcomp_data::runcsv::unquote).collect();
            if cells.len() != cols.len() {
                bail!(
                    "{p}:{lineno}: {} fields, the header has {}",
                    cells.len(),
                    cols.len()
                );
            }
            let num = |i: usize| -> Result<f64> {
                cells[i]
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        anyhow::anyhow!("{p}:{lineno}: {}: `{}` is not a number", cols[i], cells[i])
                    })
            };
            let s = num(cs)?;
            let pos = [num(cx)?, num(cy)?, num(cz)?];
            // The commanded positions must lie on the line the metadata names.
            for k in 0..3 {
                let expect = start_mm[k] + s * direction[k];
                if (pos[k] - expect).abs() > 0.01 + 1e-6 * s.abs() {
                    bail!(
                        "{p}:{lineno}: pos_{} = {} is off the line (start + s·direction = {expect:.3})",
                        ['x', 'y', 'z'][k],
                        pos[k]
                    );
                }
            }
            // A backward run may list its targets in travel order (s falling).
            if f.s_mm.len() >= 2 {
                let rising = f.s_mm[1] > f.s_mm[0];
                let last = f.s_mm[f.s_mm.len() - 1];
                if (rising && !(s > last)) || (!rising && !(s < last)) {
                    bail!("{p}:{lineno}: s_mm must rise or fall steadily along the file ({s} after {last})");
                }
            } else if let Some(&last) = f.s_mm.last() {
                if s == last {
                    bail!("{p}:{lineno}: s_mm repeats {s}");
                }
            }
            f.s_mm.push(s);
            f.pos_mm.push(pos);
            f.disp_um.push(num(cd)?);
            for (j, (i, _)) in tcols.iter().enumerate() {
                let t = num(*i)?;
                f.temps[j].1.push(t);
            }
        }
        if f.s_mm.len() >= 2 && f.s_mm[1] < f.s_mm[0] {
            f.s_mm.reverse();
            f.pos_mm.reverse();
            f.disp_um.reverse();
            f.temps.iter_mut().for_each(|(_, v)| v.reverse());
        }
        if f.s_mm.len() < 3 {
            bail!("{p}: {} targets; a line needs at least 3", f.s_mm.len());
        }
        f.spec.length_mm = f.s_mm.last().copied().unwrap_or(0.0);
        Ok(f)
    }

    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let t = |v: [f64; 3]| format!("{},{},{}", fmt(v[0]), fmt(v[1]), fmt(v[2]));
        let _ = writeln!(out, "# line: {}", self.spec.id);
        let _ = writeln!(out, "# start_mm: {}", t(self.spec.start_mm));
        let _ = writeln!(out, "# direction: {}", t(self.spec.direction));
        let _ = writeln!(out, "# tool_offset_mm: {}", t(self.spec.tool_offset_mm));
        let _ = writeln!(out, "# structure: {}", self.structure);
        if self.spec.kind == LineKind::Straightness {
            let _ = writeln!(out, "# measures: straightness");
            let _ = writeln!(out, "# sense: {}", t(self.spec.sense));
        }
        match self.run {
            Run::Forward => {
                let _ = writeln!(out, "# run: forward");
            }
            Run::Backward => {
                let _ = writeln!(out, "# run: backward");
            }
            Run::Single => {}
        }
        if let Some(ts) = &self.temperature_state {
            let _ = writeln!(out, "# temperature_state: {ts}");
        }
        let _ = writeln!(out, "# source: {}", self.source);
        let mut header = "s_mm,pos_x,pos_y,pos_z,disp_um".to_string();
        for (n, _) in &self.temps {
            header.push_str(",T_");
            header.push_str(n);
        }
        let _ = writeln!(out, "{header}");
        for i in 0..self.s_mm.len() {
            let p = self.pos_mm[i];
            let _ = write!(
                out,
                "{:.3},{:.3},{:.3},{:.3},{:.3}",
                self.s_mm[i], p[0], p[1], p[2], self.disp_um[i]
            );
            for (_, v) in &self.temps {
                let _ = write!(out, ",{:.3}", v[i]);
            }
            out.push('\n');
        }
        out
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_text()).with_context(|| format!("writing {}", path.display()))
    }
}

/// The line's `measures` and `sense` metadata: displacement (sense = the
/// travel) unless `measures: straightness`, whose `sense` is a unit vector
/// perpendicular to the travel.
fn measures(
    meta: &BTreeMap<String, (usize, String)>,
    path: &Path,
    direction: [f64; 3],
) -> Result<(LineKind, [f64; 3])> {
    let p = path.display();
    let kind = match meta.get("measures") {
        None => LineKind::Displacement,
        Some((_, v)) if v == "displacement" => LineKind::Displacement,
        Some((_, v)) if v == "straightness" => LineKind::Straightness,
        Some((n, v)) => {
            bail!("{p}:{n}: measures must be 'displacement' or 'straightness', got `{v}`")
        }
    };
    match (kind, meta.get("sense")) {
        (LineKind::Displacement, None) => Ok((kind, direction)),
        (LineKind::Displacement, Some((n, _))) => {
            bail!("{p}:{n}: sense is for a straightness line; add '# measures: straightness' or remove it")
        }
        (LineKind::Straightness, None) => {
            bail!("{p}: a straightness line needs '# sense: x,y,z' (the unit vector its reading is along)")
        }
        (LineKind::Straightness, Some((n, v))) => {
            let s = triple(path, *n, "sense", v)?;
            let norm = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
            if !((norm - 1.0).abs() < 1e-6) {
                bail!("{p}:{n}: sense `{v}` is not a unit vector (length {norm:.7})");
            }
            let dot: f64 = (0..3).map(|k| s[k] * direction[k]).sum();
            if !(dot.abs() < 1e-6) {
                bail!(
                    "{p}:{n}: sense `{v}` is not perpendicular to the direction (cosine {dot:.2e})"
                );
            }
            Ok((kind, s.map(|c| c / norm)))
        }
    }
}

/// Shortest decimal that reads back to the same f64 (unit vectors like 0.6247…).
fn fmt(v: f64) -> String {
    let s = format!("{v}");
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// The lines of a set of files, forward and backward runs of the same line
/// (and temperature state) averaged target by target.
#[derive(Clone, Debug)]
pub struct Averaged {
    pub obs: LineObs,
    pub temperature_state: Option<String>,
    /// Mean of forward − backward over the targets [µm], when both ran.
    pub reversal_um: Option<f64>,
    /// Per temperature column, its mean over the line's targets (and runs).
    pub temps: Vec<(String, f64)>,
}

pub fn average_runs(files: &[LineFile]) -> Result<Vec<Averaged>> {
    let mut groups: BTreeMap<(String, String), Vec<&LineFile>> = BTreeMap::new();
    for f in files {
        let key = (
            f.temperature_state.clone().unwrap_or_default(),
            f.spec.id.clone(),
        );
        groups.entry(key).or_default().push(f);
    }
    let mut out = Vec::new();
    for ((state, id), fs) in groups {
        let first = fs[0];
        for f in &fs[1..] {
            if f.s_mm.len() != first.s_mm.len()
                || f.s_mm
                    .iter()
                    .zip(&first.s_mm)
                    .any(|(a, b)| (a - b).abs() > 1e-6)
            {
                bail!("line {id}: its runs have different targets; cannot average them");
            }
            if f.spec.direction != first.spec.direction
                || f.spec.tool_offset_mm != first.spec.tool_offset_mm
            {
                bail!("line {id}: its runs differ in direction or tool offset");
            }
            if f.spec.kind != first.spec.kind || f.spec.sense != first.spec.sense {
                bail!("line {id}: its runs differ in what they measure (measures, sense)");
            }
        }
        if fs.len() > 1 && fs.iter().any(|f| f.run == Run::Single) {
            bail!(
                "line {id}{}: {} files for it, one of them without `run` metadata; a file without `run` is the whole line (both runs averaged), so give either that file alone or `run: forward` and `run: backward`",
                if state.is_empty() {
                    String::new()
                } else {
                    format!(" in state {state}")
                },
                fs.len()
            );
        }
        let mut runs: Vec<Run> = fs.iter().map(|f| f.run).collect();
        runs.sort();
        runs.dedup();
        if runs.len() != fs.len() {
            bail!(
                "line {id}{}: {} files for it; give each run (forward, backward) once",
                if state.is_empty() {
                    String::new()
                } else {
                    format!(" in state {state}")
                },
                fs.len()
            );
        }
        let n = first.s_mm.len();
        let mean = |i: usize| fs.iter().map(|f| f.disp_um[i]).sum::<f64>() / fs.len() as f64;
        let fwd = fs.iter().find(|f| f.run == Run::Forward);
        let bwd = fs.iter().find(|f| f.run == Run::Backward);
        let reversal_um = match (fwd, bwd) {
            (Some(a), Some(b)) => {
                Some((0..n).map(|i| a.disp_um[i] - b.disp_um[i]).sum::<f64>() / n as f64)
            }
            _ => None,
        };
        let temps = first
            .temps
            .iter()
            .map(|(name, _)| {
                let vals: Vec<f64> = fs
                    .iter()
                    .filter_map(|f| f.temps.iter().find(|(n, _)| n == name))
                    .flat_map(|(_, v)| v.iter().copied())
                    .collect();
                (
                    name.clone(),
                    vals.iter().sum::<f64>() / vals.len().max(1) as f64,
                )
            })
            .collect();
        out.push(Averaged {
            obs: LineObs {
                id: id.clone(),
                direction: first.spec.direction,
                sense: first.spec.sense,
                kind: first.spec.kind,
                tool_offset_mm: first.spec.tool_offset_mm,
                points: (0..n)
                    .map(|i| Observation {
                        pos_mm: first.pos_mm[i],
                        disp_um: mean(i),
                    })
                    .collect(),
            },
            temperature_state: first.temperature_state.clone(),
            reversal_um,
            temps,
        });
    }
    Ok(out)
}

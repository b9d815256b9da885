//! `tcomp select`: temperature-sensitive points (seed 000). K-means++
//! clustering of the sensors' standardized temperature series into m groups,
//! Pearson correlation of each sensor with each error direction (|r| summed
//! over directions), the best-scoring sensor of each group.

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use serde::Serialize;

use tcomp_data::runcsv::Run;
use tcomp_numerics::rng::Rng;
use tcomp_numerics::stats::pearson;

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// K-means++ (seeded, `restarts` runs, best inertia kept). Returns the label
/// of each point and the inertia. Labels are renumbered in order of first
/// appearance, so equal partitions give equal labels.
pub fn kmeans_pp(points: &[Vec<f64>], k: usize, restarts: usize, seed: u64) -> (Vec<usize>, f64) {
    let n = points.len();
    if n == 0 || k == 0 {
        return (vec![0; n], 0.0);
    }
    let k = k.min(n);
    let mut rng = Rng::new(seed);
    let mut best: (Vec<usize>, f64) = (vec![0; n], f64::INFINITY);
    for _ in 0..restarts.max(1) {
        // k-means++ seeding.
        let mut centers: Vec<Vec<f64>> = vec![points[rng.below(n)].clone()];
        while centers.len() < k {
            let d: Vec<f64> = points
                .iter()
                .map(|p| {
                    centers
                        .iter()
                        .map(|c| dist2(p, c))
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let total: f64 = d.iter().sum();
            let pick = if total <= 0.0 {
                rng.below(n)
            } else {
                let mut u = rng.uniform() * total;
                let mut idx = n - 1;
                for (i, di) in d.iter().enumerate() {
                    if u < *di {
                        idx = i;
                        break;
                    }
                    u -= di;
                }
                idx
            };
            centers.push(points[pick].clone());
        }
        // Lloyd iterations.
        let mut labels = vec![0usize; n];
        for _ in 0..100 {
            let mut changed = false;
            for (i, p) in points.iter().enumerate() {
                let l = (0..k)
                    .min_by(|&a, &b| dist2(p, &centers[a]).total_cmp(&dist2(p, &centers[b])))
                    .unwrap_or(0);
                if l != labels[i] {
                    labels[i] = l;
                    changed = true;
                }
            }
            for (c, center) in centers.iter_mut().enumerate() {
                let members: Vec<&Vec<f64>> = points
                    .iter()
                    .zip(&labels)
                    .filter(|(_, &l)| l == c)
                    .map(|(p, _)| p)
                    .collect();
                if members.is_empty() {
                    continue;
                }
                for (d, v) in center.iter_mut().enumerate() {
                    *v = members.iter().map(|m| m[d]).sum::<f64>() / members.len() as f64;
                }
            }
            if !changed {
                break;
            }
        }
        let inertia: f64 = points
            .iter()
            .zip(&labels)
            .map(|(p, &l)| dist2(p, &centers[l]))
            .sum();
        if inertia < best.1 - 1e-12 {
            best = (labels, inertia);
        }
    }
    // Canonical numbering.
    let mut map: BTreeMap<usize, usize> = BTreeMap::new();
    let labels = best
        .0
        .iter()
        .map(|l| {
            let next = map.len();
            *map.entry(*l).or_insert(next)
        })
        .collect();
    (labels, best.1)
}

/// Result of `select`.
#[derive(Clone, Debug, Serialize)]
pub struct Selection {
    pub sensors: Vec<String>,
    pub directions: Vec<String>,
    /// Groups of sensor names, in order of their first member.
    pub clusters: Vec<Vec<String>>,
    /// Summed |r| over the error directions, per sensor.
    pub scores: BTreeMap<String, f64>,
    /// r per sensor and direction.
    pub correlations: BTreeMap<String, BTreeMap<String, f64>>,
    /// Best-scoring sensor of each group (same order as `clusters`).
    pub chosen: Vec<String>,
    pub inertia: f64,
    /// Sensors left out of the grouping, with why (a dead or unplugged
    /// sensor, or one that never changes, carries nothing to select).
    pub left_out: BTreeMap<String, String>,
    /// What the selection had to adapt, in words (empty when nothing).
    pub notes: Vec<String>,
}

/// Select sensors over one or more runs (series concatenated; temperatures as
/// rises from each run's first row, so runs with different ambient combine).
pub fn select(runs: &[Run], groups: usize, seed: u64) -> Result<Selection> {
    let (sensors, directions) = checked_columns(runs, groups)?;
    let left_out = unusable_sensors(runs, &sensors);
    let sensors: Vec<String> = sensors
        .into_iter()
        .filter(|n| !left_out.contains_key(n))
        .collect();
    let mut notes = Vec::new();
    if sensors.is_empty() {
        bail!("select: no temperature sensor reads in at least half the rows of every run and changes");
    }
    let groups = if groups > sensors.len() {
        notes.push(format!(
            "{groups} groups asked, {} usable sensors: {} groups",
            sensors.len(),
            sensors.len()
        ));
        sensors.len()
    } else {
        groups
    };
    let (temp, err) = concatenated_series(runs, &sensors, &directions);
    let (labels, inertia) = kmeans_pp(&cluster_points(&temp), groups, 10, seed);
    let (scores, correlations) = correlate(&sensors, &directions, &temp, &err);
    let clusters = clusters_of(&sensors, &labels);
    let chosen = clusters
        .iter()
        .map(|g| {
            g.iter()
                .max_by(|a, b| scores[*a].total_cmp(&scores[*b]))
                .cloned()
                .unwrap_or_default()
        })
        .collect();
    Ok(Selection {
        sensors,
        directions,
        clusters,
        scores,
        correlations,
        chosen,
        inertia,
        left_out,
        notes,
    })
}

/// The first run's temperature and error columns, checked against `groups`
/// and against every run.
fn checked_columns(runs: &[Run], groups: usize) -> Result<(Vec<String>, Vec<String>)> {
    let Some(first) = runs.first() else {
        bail!("select: no runs given")
    };
    let sensors: Vec<String> = first
        .temperature_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    let directions: Vec<String> = first
        .error_columns()
        .iter()
        .map(|s| s.to_string())
        .collect();
    if sensors.is_empty() {
        bail!("select: the run has no temperature columns (T_...)");
    }
    if directions.is_empty() {
        bail!("select: the run has no error columns (d<name>_um)");
    }
    if groups == 0 || groups > sensors.len() {
        bail!(
            "select: --groups must be 1..={} (number of sensors), got {groups}",
            sensors.len()
        );
    }
    for (i, r) in runs.iter().enumerate() {
        for c in sensors.iter().chain(&directions) {
            if r.col(c).is_none() {
                bail!("select: run {} has no column `{c}`", i + 1);
            }
        }
    }
    Ok((sensors, directions))
}

/// Sensors left out, with why. A sensor must read in at least half the rows
/// of every run and change at all: otherwise its gap-filled series would be
/// a constant that K-means puts in a group of its own and "chooses".
fn unusable_sensors(runs: &[Run], sensors: &[String]) -> BTreeMap<String, String> {
    let mut left_out = BTreeMap::new();
    for name in sensors {
        let cols: Vec<&[Option<f64>]> = runs.iter().map(|r| r.col(name).unwrap_or(&[])).collect();
        let sparse = cols.iter().enumerate().find_map(|(i, col)| {
            let valid = col.iter().flatten().count();
            (valid * 2 < col.len())
                .then(|| format!("reads in {valid} of {} rows of run {}", col.len(), i + 1))
        });
        let mut values = cols.iter().flat_map(|c| c.iter().flatten());
        let first = values.next();
        let why = sparse.or_else(|| {
            values
                .all(|v| Some(v) == first)
                .then(|| "never changes".to_string())
        });
        if let Some(why) = why {
            left_out.insert(name.clone(), why);
        }
    }
    left_out
}

/// Series with gaps kept as `None`.
type Series = Vec<Vec<Option<f64>>>;

/// Concatenated rise series per sensor and error series per direction.
fn concatenated_series(
    runs: &[Run],
    sensors: &[String],
    directions: &[String],
) -> (Series, Series) {
    let mut temp: Series = vec![Vec::new(); sensors.len()];
    let mut err: Series = vec![Vec::new(); directions.len()];
    for r in runs {
        for (s, name) in sensors.iter().enumerate() {
            let col = r.col(name).unwrap_or(&[]);
            let t0 = col.iter().flatten().next().copied().unwrap_or(0.0);
            temp[s].extend(col.iter().map(|v| v.map(|t| t - t0)));
        }
        for (d, name) in directions.iter().enumerate() {
            err[d].extend_from_slice(r.col(name).unwrap_or(&[]));
        }
    }
    (temp, err)
}

/// Standardized, gap-filled, strided series for clustering.
fn cluster_points(temp: &Series) -> Vec<Vec<f64>> {
    let n = temp[0].len();
    let stride = n.div_ceil(4000).max(1);
    temp.iter()
        .map(|col| {
            let vals: Vec<f64> = col.iter().flatten().copied().collect();
            let m = vals.iter().sum::<f64>() / vals.len().max(1) as f64;
            let sd = (vals.iter().map(|v| (v - m) * (v - m)).sum::<f64>()
                / vals.len().max(1) as f64)
                .sqrt();
            let sd = if sd > 0.0 { sd } else { 1.0 };
            let mut last = m;
            col.iter()
                .map(|v| {
                    if let Some(v) = v {
                        last = *v;
                    }
                    (last - m) / sd
                })
                .step_by(stride)
                .collect()
        })
        .collect()
}

/// Correlations per sensor and direction.
type Correlations = BTreeMap<String, BTreeMap<String, f64>>;

/// Per sensor: the summed |r| over the directions, and r per direction.
fn correlate(
    sensors: &[String],
    directions: &[String],
    temp: &Series,
    err: &Series,
) -> (BTreeMap<String, f64>, Correlations) {
    let mut correlations = BTreeMap::new();
    let mut scores = BTreeMap::new();
    for (s, name) in sensors.iter().enumerate() {
        let rs: BTreeMap<String, f64> = directions
            .iter()
            .enumerate()
            .map(|(d, dn)| (dn.clone(), pearson(&temp[s], &err[d])))
            .collect();
        scores.insert(name.clone(), rs.values().map(|r| r.abs()).sum::<f64>());
        correlations.insert(name.clone(), rs);
    }
    (scores, correlations)
}

/// Sensor names per group label, in label order.
fn clusters_of(sensors: &[String], labels: &[usize]) -> Vec<Vec<String>> {
    let k = labels.iter().max().map_or(0, |m| m + 1);
    (0..k)
        .map(|c| {
            sensors
                .iter()
                .zip(labels)
                .filter(|(_, &l)| l == c)
                .map(|(s, _)| s.clone())
                .collect()
        })
        .collect()
}

/// Human-readable report.
pub fn print_selection(s: &Selection) {
    println!(
        "sensors: {}  directions: {}",
        s.sensors.len(),
        s.directions.join(",")
    );
    println!(
        "score: summed |r| of the sensor's rise with each error column (r: Pearson correlation, no unit; 0 to {} over {} column(s))",
        s.directions.len(),
        s.directions.len()
    );
    for (i, g) in s.clusters.iter().enumerate() {
        let members: Vec<String> = g
            .iter()
            .map(|n| format!("{n} (score {:.3})", s.scores[n]))
            .collect();
        println!(
            "group {}: {}  -> {}",
            i + 1,
            members.join(", "),
            s.chosen[i]
        );
    }
    println!("chosen: {}", s.chosen.join(","));
    for (n, why) in &s.left_out {
        println!("left out: {n} ({why})");
    }
    for n in &s.notes {
        println!("note: {n}");
    }
}

//! Chooses 14 lines from a pool (segments between points of a 3×3×3 grid in
//! the working volume, three reflector offsets) by greedy + exchange
//! D-optimal design on the identification's design matrix.
//!
//! `cargo run -p tcomp-bench --release --example geo_plan_search -- [DEG]
//! [all|search] [RESTARTS]` (straightness and roll degrees and the lines
//! kept from `plan14` also from the environment: `SD`, `RD`, `FIXED`).
use nalgebra::DMatrix;
use tcomp_geometry::identify::Basis;
use tcomp_geometry::lines::LineSpec;
use tcomp_geometry::*;

fn block(b: &Basis, st: &Structure, l: &LineSpec) -> Vec<Vec<f64>> {
    let mut rows: Vec<Vec<f64>> = l
        .targets(21)
        .iter()
        .map(|(_, p)| b.row(st, l.direction, *p, l.tool_offset_mm))
        .collect();
    let n = rows[0].len();
    for j in 0..n {
        let m = rows.iter().map(|r| r[j]).sum::<f64>() / rows.len() as f64;
        rows.iter_mut().for_each(|r| r[j] -= m);
    }
    rows
}

fn info(b: &[Vec<f64>], n: usize) -> DMatrix<f64> {
    let mut m = DMatrix::<f64>::zeros(n, n);
    for r in b.iter() {
        for i in 0..n {
            if r[i] == 0.0 {
                continue;
            }
            for j in 0..n {
                m[(i, j)] += r[i] * r[j];
            }
        }
    }
    m
}
fn score(blocks: &[&DMatrix<f64>], n: usize) -> (usize, f64) {
    let mut m = DMatrix::<f64>::zeros(n, n);
    for b in blocks {
        m += *b;
    }
    let ev = m.symmetric_eigenvalues();
    let max = ev.iter().cloned().fold(0.0, f64::max);
    let nz: Vec<f64> = ev.iter().cloned().filter(|e| *e > 1e-12 * max).collect();
    (nz.len(), nz.iter().map(|e| e.ln()).sum())
}

/// The command line (clap: `--help` lists every argument).
#[derive(clap::Parser)]
#[command(
    name = "geo_plan_search",
    about = "Chooses 14 lines from a pool by greedy + exchange D-optimal design on the identification's design matrix"
)]
struct Args {
    /// Degree of the main error terms.
    #[arg(default_value_t = 3)]
    deg: usize,
    /// `all`: only the rank of the whole pool; any other word (e.g. `search`): the search.
    mode: Option<String>,
    /// Restarts of the search (each after the first from a random extra line).
    #[arg(default_value_t = 1)]
    restarts: usize,
    /// Degree of the straightness terms.
    #[arg(long = "straightness-degree", env = "SD", default_value_t = 2)]
    sd: usize,
    /// Degree of the roll terms.
    #[arg(long = "roll-degree", env = "RD", default_value_t = 2)]
    rd: usize,
    /// Lines of `plan14` always kept (its first N).
    #[arg(long, env = "FIXED", default_value_t = 9)]
    fixed: usize,
}

fn main() {
    let args = match tcomp_bench::cli::parse::<Args>() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1)
        }
    };
    let (deg, sd, rd, fixed) = (args.deg, args.sd, args.rd, args.fixed);
    let degs = tcomp_geometry::identify::Degrees {
        main: deg,
        straightness: sd,
        roll: rd,
    };
    let stroke = [800.0, 500.0, 400.0];
    let st = Structure::parse("XY/Z").unwrap();
    let b = Basis::new(degs, stroke);
    let n = b.columns.len();
    let g: Vec<[f64; 3]> = (0..27)
        .map(|i| {
            [
                stroke[0] * (i % 3) as f64 / 2.0,
                stroke[1] * ((i / 3) % 3) as f64 / 2.0,
                stroke[2] * (i / 9) as f64 / 2.0,
            ]
        })
        .collect();
    let tools = [
        [0.0, 0.0, 100.0],
        [100.0, 0.0, 100.0],
        [0.0, 100.0, 100.0],
        [100.0, 100.0, 100.0],
        [0.0, 0.0, 250.0],
        [-100.0, 0.0, 100.0],
    ];
    let mut pool: Vec<LineSpec> = tcomp_geometry::lines::plan14(stroke, 100.0, 100.0)[..9].to_vec();
    for i in 0..27 {
        for j in i + 1..27 {
            for (k, t) in tools.iter().enumerate() {
                let (a, c) = (g[i], g[j]);
                let d = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                // Only lines at least half the smallest stroke long.
                if len < 200.0 {
                    continue;
                }
                pool.push(LineSpec {
                    id: format!("{i}-{j}-t{k}"),
                    start_mm: a,
                    direction: d.map(|x| x / len),
                    length_mm: len,
                    tool_offset_mm: *t,
                    purpose: String::new(),
                    kind: Default::default(),
                    sense: d.map(|x| x / len),
                });
            }
        }
    }
    let blocks: Vec<DMatrix<f64>> = pool.iter().map(|l| info(&block(&b, &st, l), n)).collect();
    eprintln!("pool {} lines, {} unknowns", pool.len(), n);
    if args.mode.as_deref() == Some("all") {
        let obs: Vec<tcomp_geometry::identify::LineObs> = pool
            .iter()
            .map(|l| tcomp_geometry::identify::LineObs {
                id: l.id.clone(),
                direction: l.direction,
                sense: l.sense,
                kind: l.kind,
                tool_offset_mm: l.tool_offset_mm,
                points: l
                    .targets(21)
                    .iter()
                    .map(|(_, p)| tcomp_geometry::identify::Observation {
                        pos_mm: *p,
                        disp_um: 0.0,
                    })
                    .collect(),
            })
            .collect();
        let id = tcomp_geometry::identify::identify(&st, &obs, degs, stroke).unwrap();
        println!("ALL: rank {}/{}", id.rank, n);
        for u in &id.unobservable {
            println!("  null {:?}", u.combination);
        }
        return;
    }
    let restarts = args.restarts;
    let mut best_overall: (Vec<usize>, (usize, f64)) = (Vec::new(), (0, f64::NEG_INFINITY));
    let mut rng = tcomp_numerics::rng::Rng::new(3);
    for restart in 0..restarts {
        let mut chosen: Vec<usize> = (0..fixed).collect();
        if restart > 0 {
            chosen.push(fixed + rng.below(pool.len() - fixed));
        }
        while chosen.len() < 14 {
            let best = (fixed..pool.len())
                .filter(|i| !chosen.contains(i))
                .map(|i| {
                    let mut s: Vec<&DMatrix<f64>> = chosen.iter().map(|&c| &blocks[c]).collect();
                    s.push(&blocks[i]);
                    (i, score(&s, n))
                })
                .max_by(|a, b| a.1 .0.cmp(&b.1 .0).then(a.1 .1.total_cmp(&b.1 .1)))
                .unwrap();
            chosen.push(best.0);
        }
        for pass in 0..3 {
            let mut improved = false;
            for k in fixed..14 {
                let cur = score(&chosen.iter().map(|&c| &blocks[c]).collect::<Vec<_>>(), n);
                let mut best = (chosen[k], cur);
                for i in 0..pool.len() {
                    if chosen.contains(&i) || i < fixed {
                        continue;
                    }
                    let mut c2 = chosen.clone();
                    c2[k] = i;
                    let s = score(&c2.iter().map(|&c| &blocks[c]).collect::<Vec<_>>(), n);
                    if (s.0, s.1) > (best.1 .0, best.1 .1)
                        && (s.0 > best.1 .0 || s.1 > best.1 .1 + 1e-9)
                    {
                        best = (i, s);
                    }
                }
                if best.0 != chosen[k] {
                    chosen[k] = best.0;
                    improved = true;
                }
            }
            let s = score(&chosen.iter().map(|&c| &blocks[c]).collect::<Vec<_>>(), n);
            eprintln!("pass {pass}: rank {} logdet {:.2}", s.0, s.1);
            if !improved {
                break;
            }
        }
        let s = score(&chosen.iter().map(|&c| &blocks[c]).collect::<Vec<_>>(), n);
        if (s.0, s.1) > best_overall.1 {
            best_overall = (chosen.clone(), s);
        }
    }
    let chosen = best_overall.0;
    eprintln!(
        "best: rank {} logdet {:.2}",
        best_overall.1 .0, best_overall.1 .1
    );
    let obs: Vec<tcomp_geometry::identify::LineObs> = chosen
        .iter()
        .map(|&c| {
            let l = &pool[c];
            tcomp_geometry::identify::LineObs {
                id: l.id.clone(),
                direction: l.direction,
                sense: l.sense,
                kind: l.kind,
                tool_offset_mm: l.tool_offset_mm,
                points: l
                    .targets(21)
                    .iter()
                    .map(|(_, p)| tcomp_geometry::identify::Observation {
                        pos_mm: *p,
                        disp_um: 0.0,
                    })
                    .collect(),
            }
        })
        .collect();
    let id = tcomp_geometry::identify::identify(&st, &obs, degs, stroke).unwrap();
    println!(
        "rank {}/{} sv tail {:?}",
        id.rank,
        n,
        &id.singular_values[id.singular_values.len().saturating_sub(4)..]
    );
    for u in &id.unobservable {
        println!("  null {:?}", u.combination);
    }
    for &c in &chosen {
        let l = &pool[c];
        println!(
            "{} {:?} dir {:?} len {:.0} tool {:?}",
            l.id,
            l.start_mm,
            l.direction.map(|x| (x * 1000.0).round() / 1000.0),
            l.length_mm,
            l.tool_offset_mm
        );
    }
}

//! How much of the 18 error functions the 14-line plan can see (issue 29):
//! for a uniform Legendre degree d per function, the number of exact null
//! directions of the line design (singular values at machine precision),
//! and the largest weights of each at d ≤ 5. Any combination in the null
//! space changes no reading of the 14 lines, whatever the identifier.
//! `cargo run -p tcomp-geometry --release --example null_probe`

use nalgebra::{DMatrix, Vector3};
use tcomp_geometry::lines::plan14;
use tcomp_geometry::smooth::basis_monomials;
use tcomp_geometry::{sensitivity, Structure, Term};

fn main() {
    let st = Structure::parse("XY/Z").unwrap();
    let stroke = [800.0, 500.0, 400.0];
    let plan = plan14(stroke, 100.0, 100.0);
    for deg in 2..=12usize {
        let mut cols = Vec::new();
        for t in Term::all() {
            let first = if t.is_straightness() { 2 } else { 1 };
            for j in first..=deg {
                cols.push((Some(t), j));
            }
        }
        for i in 0..3 {
            cols.push((None, i));
        }
        let n = cols.len();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        for l in &plan {
            let tg = l.targets(41);
            let d = Vector3::from(l.direction);
            let first = rows.len();
            for (_, p) in &tg {
                let s = sensitivity(&st, *p, l.tool_offset_mm);
                let r: Vec<f64> = cols
                    .iter()
                    .map(|(t, j)| match t {
                        Some(t) => {
                            let u = p[t.axis.index()] / stroke[t.axis.index()];
                            let m = basis_monomials(t.is_straightness(), *j);
                            let v = m.iter().rev().fold(0.0, |a, c| a * u + c) * u;
                            d.dot(&s.terms[t.axis.index()][t.component.index()]) * v
                        }
                        None => d.dot(&s.squareness[*j]),
                    })
                    .collect();
                rows.push(r);
            }
            let k = rows.len() - first;
            for c in 0..n {
                let mean = rows[first..].iter().map(|r| r[c]).sum::<f64>() / k as f64;
                rows[first..].iter_mut().for_each(|r| r[c] -= mean);
            }
        }
        let a = DMatrix::from_fn(rows.len(), n, |i, j| rows[i][j]);
        let mut an = a.clone();
        for j in 0..n {
            let nn = an.column(j).norm();
            an.column_mut(j).scale_mut(1.0 / nn);
        }
        let svd = an.clone().svd(false, true);
        let mut sv: Vec<(f64, usize)> = svd
            .singular_values
            .iter()
            .copied()
            .enumerate()
            .map(|(i, s)| (s, i))
            .collect();
        sv.sort_by(|a, b| b.0.total_cmp(&a.0));
        let smax = sv[0].0;
        let c6 = sv.iter().filter(|s| s.0 < 1e-8 * smax).count();
        let c3 = sv.iter().filter(|s| s.0 < 1e-3 * smax).count();
        println!(
            "deg {deg}: n {n}, null(<1e-8) {c6}, weak(<1e-3) {c3}, smallest {:?}",
            sv.iter()
                .rev()
                .take(4)
                .map(|s| s.0 / smax)
                .collect::<Vec<_>>()
        );
        if deg <= 5 {
            let vt = svd.v_t.unwrap();
            for (s, i) in sv.iter().rev().take(c6.max(1)) {
                let v = vt.row(*i);
                let mut w: Vec<(String, f64)> = cols
                    .iter()
                    .zip(v.iter())
                    .filter(|(_, x)| x.abs() > 0.05)
                    .map(|((t, j), x)| {
                        (
                            match t {
                                Some(t) => format!("{}{}", t.name(), j),
                                None => format!("sq{j}"),
                            },
                            *x,
                        )
                    })
                    .collect();
                w.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
                println!(
                    "   {:.1e}: {:?}",
                    s / smax,
                    w.iter()
                        .take(10)
                        .map(|(n, x)| format!("{n}:{x:.2}"))
                        .collect::<Vec<_>>()
                );
            }
        }
    }
}

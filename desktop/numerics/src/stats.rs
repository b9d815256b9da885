//! Statistics shared by fitting and diagnosis: Pearson correlation and the
//! one block-average decimator.

/// Pearson correlation over the rows where both series have a value; 0 when
/// fewer than two such rows or either series is constant.
pub fn pearson(a: &[Option<f64>], b: &[Option<f64>]) -> f64 {
    let pairs: Vec<(f64, f64)> = a
        .iter()
        .zip(b)
        .filter_map(|(x, y)| Some(((*x)?, (*y)?)))
        .collect();
    let n = pairs.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let (mx, my) = pairs.iter().fold((0.0, 0.0), |s, p| (s.0 + p.0, s.1 + p.1));
    let (mx, my) = (mx / n, my / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in &pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return 0.0;
    }
    sxy / (sxx * syy).sqrt()
}

/// Mean of the finite values (NaN marks a missing reading); NaN when none.
pub fn mean_finite(v: impl IntoIterator<Item = f64>) -> f64 {
    let (s, n) = v
        .into_iter()
        .filter(|x| x.is_finite())
        .fold((0.0, 0usize), |a, x| (a.0 + x, a.1 + 1));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Decimate by `f`: the mean of each block of `f` rows (the last block may be
/// shorter), over the block's finite values; NaN for a block without one.
/// Block `i` starts at row `i·f`, so the decimated grid is `(0..n).step_by(f)`.
pub fn block_means(v: &[f64], f: usize) -> Vec<f64> {
    let f = f.max(1);
    (0..v.len())
        .step_by(f)
        .map(|s| {
            let e = (s + f).min(v.len());
            mean_finite(v[s..e].iter().copied())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_means_short_tail_and_gaps() {
        let v = [1.0, 3.0, f64::NAN, 5.0, f64::NAN, f64::NAN, 7.0];
        let m = block_means(&v, 2);
        assert_eq!(m[0], 2.0);
        assert_eq!(m[1], 5.0);
        assert!(m[2].is_nan());
        assert_eq!(m[3], 7.0);
        assert_eq!(block_means(&v[..2], 1), vec![1.0, 3.0]);
    }
}

//! CPU time of this process from `/proc/self/stat` (0 where there is none):
//! its own (user + system, every thread) and, apart, that of the children
//! it has waited for (a `python3` scorer and the `tcomp` it runs).

/// The fields after the command name: (utime, stime, cutime, cstime) in
/// clock ticks.
fn ticks() -> Option<[f64; 4]> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = s.get(s.rfind(')')? + 2..)?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let mut out = [0.0; 4];
    for (i, o) in out.iter_mut().enumerate() {
        *o = f.get(11 + i)?.parse().ok()?;
    }
    Some(out)
}

/// CPU seconds (user + system, all threads) of this process so far.
pub fn own_s() -> f64 {
    ticks().map_or(0.0, |t| (t[0] + t[1]) / 100.0)
}

/// CPU seconds of the children waited for so far (their own children
/// included when they waited for them).
pub fn children_s() -> f64 {
    ticks().map_or(0.0, |t| (t[2] + t[3]) / 100.0)
}

//! How the desktop programs end on an error: one line, `error: what: because`,
//! exit status 1 — never anyhow's Debug form with a stack trace, whatever
//! `RUST_BACKTRACE` says (a bad argument to a benchmark is no crash).

/// The error and its causes on one line, `outer: inner: root`; line breaks
/// inside a message (some parsers' snippets) become spaces.
pub fn one_line(e: &anyhow::Error) -> String {
    let text = format!("{e:#}");
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    lines.join(" ")
}

/// Runs a benchmark's body and reports its error as one line.
pub fn run_main(body: impl FnOnce() -> anyhow::Result<()>) -> std::process::ExitCode {
    // anyhow decides at the first error whether to capture a backtrace:
    // none is printed, so none is captured
    std::env::set_var("RUST_LIB_BACKTRACE", "0");
    match body() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// Refuses an argument list with an unknown option or an option missing its
/// value, naming the options there are (`flags` stand alone, `valued` take
/// the next argument); a benchmark must not run an hour on a typo.
pub fn check_args(args: &[String], flags: &[&str], valued: &[&str]) -> anyhow::Result<()> {
    let usage = || {
        flags
            .iter()
            .map(|f| f.to_string())
            .chain(valued.iter().map(|v| format!("{v} VALUE")))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if valued.contains(&a.as_str()) {
            if it.next().is_none() {
                anyhow::bail!("{a} needs a value ({})", usage());
            }
        } else if !flags.contains(&a.as_str()) {
            anyhow::bail!("unknown argument `{a}` ({})", usage());
        }
    }
    Ok(())
}

//! The bench binaries' command lines (`bench-onewire`, `bench-flash-wear`):
//! clap's parse, with a bad argument reported on one line (`error:
//! unexpected argument '--x' found`, exit status 1) as the desktop benches
//! report theirs, and `--help` printed as clap prints it (exit status 0).

/// The arguments of this process; on a bad one, its one-line error and exit.
pub fn parse_or_exit<A: clap::Parser>() -> A {
    A::try_parse().unwrap_or_else(|e| {
        if matches!(
            e.kind(),
            clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
        ) {
            e.exit()
        }
        let text = e.to_string();
        let line = text.lines().next().unwrap_or("error: bad arguments");
        eprintln!("{line}");
        std::process::exit(1)
    })
}

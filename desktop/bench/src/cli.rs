//! What the bench binaries share on their command line: clap's parse with
//! a bad argument reported as every other error of theirs, on one line
//! (`error: unexpected argument '--x' found`, exit status 1), and `--help`
//! printed as clap prints it (exit status 0).

/// The arguments of this process, or clap's one-line complaint.
pub fn parse<A: clap::Parser>() -> anyhow::Result<A> {
    A::try_parse().map_err(|e| {
        if matches!(
            e.kind(),
            clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
        ) {
            e.exit()
        }
        anyhow::anyhow!(
            "{}",
            e.to_string()
                .lines()
                .next()
                .unwrap_or("bad arguments")
                .trim_start_matches("error: ")
        )
    })
}

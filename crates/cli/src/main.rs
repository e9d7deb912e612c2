//! `mfm`: generate and inspect signals on your own triangle meshes.
//!
//! Thin by design: it parses arguments and calls the library crates. Every
//! failure ends with a non-zero exit status and a one-line reason on stderr.

#[cfg(feature = "network")]
mod arbitrary;
mod commands;
mod dataset;
mod eval;
#[cfg(feature = "network")]
mod flow;
mod mesh_arg;
#[cfg(feature = "network")]
mod net;
mod output;
mod pictures;
mod remesh;
mod spectral;
#[cfg(not(feature = "network"))]
mod unavailable;

use clap::Parser;

#[derive(Parser)]
#[command(
    name = "mfm",
    version,
    about = "Triangulation-agnostic signals on triangle meshes: reports, operators, noise, flow matching",
    after_help = "MESH is a file (.obj .off .ply .gltf .glb) or a built-in mesh: builtin:icosphere[:SUBDIV], builtin:blob[:SUBDIV], \
builtin:uv-sphere, builtin:torus, builtin:capsule, builtin:grid[:N]."
)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

fn main() {
    // Keeps freed tensor memory for reuse (large speed-up for training on
    // glibc); harmless for the commands that do not use libtorch.
    #[cfg(feature = "network")]
    mfm_net::runtime::tune_allocator();
    let cli = parse();
    if let Err(e) = commands::run(cli.command) {
        eprintln!("mfm: error: {}", printable(&one_line(&e)));
        std::process::exit(1);
    }
}

/// Parses the command line, reading `--tau -1` as the value `-1` of `--tau`
/// (every subcommand accepts negative numbers as values; the commands then
/// reject out-of-range ones by name) instead of clap's suggestion to write
/// `-- -1`.
fn parse() -> Cli {
    use clap::{CommandFactory, FromArgMatches};
    fn negatives(cmd: clap::Command) -> clap::Command {
        cmd.allow_negative_numbers(true).mut_subcommands(negatives)
    }
    let matches = negatives(Cli::command()).get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

/// `text` with control characters (escape sequences, carriage returns,
/// NUL...) shown as escapes, so a message quoting a file's content cannot
/// drive the terminal.
fn printable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// The error and its causes on one line, `outer: inner: ...`, leaving out a
/// cause whose text an outer message already contains (library errors such
/// as `path: io error` both show and return their source).
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::{one_line, printable};

    #[test]
    fn control_characters_are_escaped() {
        assert_eq!(
            printable("bad token \u{1b}[2J here\r\n"),
            "bad token \\u{1b}[2J here\\r\\n"
        );
        assert_eq!(printable("plain · text"), "plain · text");
    }

    #[test]
    fn a_cause_already_in_its_wrapper_is_printed_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        let e = anyhow::Error::new(mfm_data::DataError::io("/d/manifest.json", io))
            .context("loading the dataset");
        assert_eq!(
            one_line(&e),
            "loading the dataset: /d/manifest.json: No such file"
        );
        // causes that are not repeated all appear, outermost first
        let e = anyhow::anyhow!("inner").context("middle").context("outer");
        assert_eq!(one_line(&e), "outer: middle: inner");
    }
}

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
#[cfg(feature = "network")]
mod interrupt;
mod mesh;
#[cfg(feature = "network")]
mod net;
#[cfg(feature = "network")]
mod official;
mod openmp;
mod output;
mod preinit;
#[cfg(feature = "network")]
mod sample;
mod spectral;
#[cfg(feature = "network")]
mod train;
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
        let line = mfm_files::text::error_line(e.as_ref());
        eprintln!("mfm: error: {}", mfm_files::text::printable(&line));
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

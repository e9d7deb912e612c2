//! `mfm`: generate and inspect signals on your own triangle meshes.
//!
//! Thin by design: it parses arguments and calls the library crates. Every
//! failure ends with a non-zero exit status and a one-line reason on stderr.

mod commands;
mod flow;
mod mesh_arg;
mod net;
mod output;
mod remesh;
mod spectral;

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
    mfm_net::runtime::tune_allocator();
    let cli = Cli::parse();
    if let Err(e) = commands::run(cli.command) {
        eprintln!("mfm: error: {e:#}");
        std::process::exit(1);
    }
}

//! `mfm-reproduce COMMAND`: the reproductions of [`mfm_reproduce`]
//! (`demo`, `pretrain`, `time-to-quality`, `reproduce-figures`), the same
//! commands as `cargo xtask COMMAND`.

use clap::Parser;

#[derive(Parser)]
#[command(
    name = "mfm-reproduce",
    about = "The paper's experiments and the demo of mfm, reproduced"
)]
struct Cli {
    #[command(subcommand)]
    command: mfm_reproduce::Command,
}

fn main() -> anyhow::Result<()> {
    mfm_reproduce::run(Cli::parse().command)
}

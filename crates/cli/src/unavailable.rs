//! The network commands in an `mfm` built without the `network` feature:
//! they parse anything and say how to get them.

use anyhow::{Result, bail};

/// Whatever arguments were given to a command this build does not have.
#[derive(clap::Args)]
pub struct Unavailable {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    args: Vec<String>,
}

/// The error of `mfm COMMAND` without the network feature.
pub fn fail(command: &str) -> Result<()> {
    bail!(
        "`mfm {command}` runs PoissonNet, and this mfm was built without libtorch (`--no-default-features`); \
build it with the default `network` feature (`cargo build --release -p mfm-cli`, after `eval \"$(cargo xtask setup)\"`) \
or use `cargo xtask mfm -- {command} ...`"
    )
}

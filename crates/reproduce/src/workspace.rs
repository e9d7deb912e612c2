//! The workspace as the tools see it: its root folder, cargo's target
//! folder, and `cargo` and other programs run from it (what xtask and the
//! reproduction commands share).

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::pyenv::PyEnv;

/// The workspace root (two folders above this crate's).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Cargo's target folder: `CARGO_TARGET_DIR` (relative to the workspace root)
/// or `target/` in the workspace root.
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => root().join(dir),
        None => root().join("target"),
    }
}

/// A `cargo` command in the workspace root with the environment applied.
pub fn cargo(env: &PyEnv) -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned()));
    cmd.current_dir(root());
    for (k, v) in env.cargo_env() {
        cmd.env(k, v);
    }
    cmd
}

/// Runs a command, failing with its status.
///
/// # Errors
/// When it cannot start or exits unsuccessfully.
pub fn run(cmd: &mut Command) -> Result<()> {
    let status = cmd
        .status()
        .with_context(|| format!("cannot run {cmd:?}"))?;
    if !status.success() {
        bail!("command failed ({status}): {cmd:?}");
    }
    Ok(())
}

/// `path` if absolute, else relative to the workspace root.
pub fn in_root(path: &Path) -> PathBuf {
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        root().join(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_root_is_the_workspace() {
        let root = root();
        assert!(root.join("Cargo.toml").is_file(), "{}", root.display());
        assert!(root.join("crates/reproduce/Cargo.toml").is_file());
        assert_eq!(in_root(Path::new("out/x")), root.join("out/x"));
        assert_eq!(in_root(Path::new("/tmp/x")), PathBuf::from("/tmp/x"));
    }
}

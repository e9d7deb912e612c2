//! `cargo xtask no-network`: the check that `mfm` built without its `network`
//! feature needs no libtorch: it is built (in the test profile, so only the
//! cli crate itself compiles again after `cargo test`), its dynamic dependencies are listed
//! with `ldd`, and it runs `mfm info` with an empty environment, while
//! `mfm train` says how to get the network commands.

use anyhow::{Context, Result, bail};
use std::process::Command;

/// Builds the libtorch-free `mfm` (test profile, no `network` feature) and
/// returns its path.
pub fn build() -> Result<std::path::PathBuf> {
    let mut build = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned()));
    build.current_dir(mfm_reproduce::workspace::root()).args([
        "build",
        "--profile",
        "test",
        "--quiet",
        "-p",
        "mfm-cli",
        "--no-default-features",
    ]);
    // no LIBTORCH: nothing in this build may need it
    build
        .env_remove("LIBTORCH")
        .env_remove("LIBTORCH_USE_PYTORCH");
    mfm_reproduce::workspace::run(&mut build)?;
    Ok(mfm_reproduce::workspace::target_dir()
        .join("debug")
        .join("mfm"))
}

/// Builds and checks the libtorch-free `mfm`.
pub fn check() -> Result<()> {
    println!("== mfm without the network feature (no libtorch)");
    let exe = build()?;
    let ldd = Command::new("ldd")
        .arg(&exe)
        .output()
        .with_context(|| format!("cannot run ldd on {}", exe.display()))?;
    let libs = String::from_utf8_lossy(&ldd.stdout);
    let torch: Vec<&str> = libs
        .lines()
        .filter(|l| l.contains("torch") || l.contains("libc10") || l.contains("cuda"))
        .collect();
    if !torch.is_empty() {
        bail!(
            "{} built without the network feature links libtorch:\n{}",
            exe.display(),
            torch.join("\n")
        );
    }
    let info = Command::new(&exe)
        .env_clear()
        .args(["info", "builtin:icosphere:1"])
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    if !info.status.success() || !String::from_utf8_lossy(&info.stdout).contains("vertices") {
        bail!(
            "`mfm info` without libtorch failed: {}",
            String::from_utf8_lossy(&info.stderr)
        );
    }
    let train = Command::new(&exe)
        .env_clear()
        .args(["train", "--preset", "cpu", "--out", "nowhere"])
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    let says = String::from_utf8_lossy(&train.stderr);
    if train.status.success() || !says.contains("network") {
        bail!("`mfm train` without the network feature should say how to get it, said: {says}");
    }
    println!(
        "ok: {} links no libtorch ({} libraries), runs `mfm info`, and `mfm train` says: {}",
        exe.display(),
        libs.lines().count(),
        says.trim()
    );
    Ok(())
}

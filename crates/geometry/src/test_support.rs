//! Helpers shared by the test suites of the mfm crates (not public API).
//!
//! Tests that need the shared meshes (`../shared/meshes` next to the project
//! root) skip themselves with a printed reason when those are missing, so a
//! fresh clone without `../shared` passes. Tests that need the Python oracle
//! environment skip the same way, unless `MFM_REQUIRE_ORACLES=1` is set (as
//! `cargo xtask test` does, after installing it): then a missing oracle is a
//! test failure.

use std::path::PathBuf;

/// Root of the workspace (two levels above this crate's manifest).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap_or_else(|_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.."))
}

/// Whether missing oracles/meshes must fail the test instead of skipping it.
pub fn oracles_required() -> bool {
    std::env::var("MFM_REQUIRE_ORACLES").is_ok_and(|v| v == "1")
}

fn skip_or_fail(reason: &str) {
    if oracles_required() {
        panic!("{reason} (MFM_REQUIRE_ORACLES=1, so this is a failure)");
    }
    eprintln!("SKIPPED: {reason}");
}

/// Folder of a shared real sequence (`$MFM_SHARED_DATA/NAME` or
/// `<root>/../shared/data/NAME`, holding `template.obj` and `frames.npy`),
/// or `None` with a printed skip reason when it is missing.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("MFM_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/data"))
        .join(name);
    if dir.join("frames.npy").is_file() {
        Some(dir)
    } else {
        eprintln!("SKIPPED: shared sequence {} not found", dir.display());
        None
    }
}

/// Path of a shared test mesh (`$MFM_SHARED_MESHES` or `<root>/../shared/meshes`),
/// or `None` with a printed skip reason when it is missing.
pub fn shared_mesh(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("MFM_SHARED_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/meshes"));
    let path = dir.join(name);
    if path.is_file() {
        Some(path)
    } else {
        eprintln!("SKIPPED: shared mesh {} not found", path.display());
        None
    }
}

/// The Python interpreter of the oracle environment (`$MFM_PYTHON`, set by
/// `cargo xtask`), or `None` with a printed skip reason.
pub fn python_oracle() -> Option<PathBuf> {
    match std::env::var_os("MFM_PYTHON").map(PathBuf::from) {
        Some(p) if p.exists() => Some(p),
        _ => {
            skip_or_fail(
                "MFM_PYTHON is not set to the oracle environment (run through `cargo xtask test`)",
            );
            None
        }
    }
}

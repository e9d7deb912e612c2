//! The `mfm` Python package (`crates/python`): `cargo xtask wheel` builds its
//! abi3 wheel, and `cargo xtask test` (or `cargo xtask pytest` alone) tests
//! it from Python:
//!
//! 1. the wheel is built with maturin (from the pinned environment) in the
//!    `dev` profile, which shares the dependencies `cargo test` compiled;
//! 2. it is installed with `pip install --no-deps --target` into a folder
//!    of its own under the target folder, put on `PYTHONPATH` for the
//!    pinned interpreter (numpy, scipy, libigl and torch are the oracles),
//!    and `crates/python/tests` runs under pytest with `MFM_CLI` naming the
//!    libtorch-free `mfm` binary the bit-identity tests compare with;
//! 3. a fresh virtual environment gets the wheel with plain `pip install`
//!    (numpy and scipy from the package index), and a script run in an
//!    empty folder with an empty environment (no cargo, no libtorch, no
//!    checkout on the path) writes a mesh file, reads it back and samples
//!    Matérn noise on it.

use crate::pyenv::PyEnv;
use anyhow::{Context, Result, bail};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The package's folder (its `pyproject.toml` and `Cargo.toml`).
fn package_dir() -> PathBuf {
    crate::root().join("crates/python")
}

/// Builds the wheel with `profile` (`dev` or `release`) into `out` (emptied
/// of earlier `mfm-*.whl` first) and returns its path.
pub fn build_wheel(env: &PyEnv, profile: &str, out: &Path) -> Result<PathBuf> {
    fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    for old in wheels_in(out)? {
        fs::remove_file(&old).with_context(|| format!("cannot remove {}", old.display()))?;
    }
    let maturin = env
        .python
        .parent()
        .map(|bin| bin.join("maturin"))
        .context("the environment's interpreter has no folder")?;
    crate::run(
        Command::new(&maturin)
            .current_dir(package_dir())
            .args(["build", "--quiet", "--profile", profile, "--out"])
            .arg(out)
            // the wheel links no libtorch; keep cargo's view of the
            // environment the same as `cargo test`'s so that the shared
            // dependencies are not rebuilt
            .env("CARGO_TARGET_DIR", crate::target_dir()),
    )?;
    match wheels_in(out)?.as_slice() {
        [one] => Ok(one.clone()),
        found => bail!(
            "maturin left {} wheels in {} (expected one)",
            found.len(),
            out.display()
        ),
    }
}

fn wheels_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    for entry in fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let path = entry?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if name.is_some_and(|n| n.starts_with("mfm-") && n.ends_with(".whl")) {
            found.push(path);
        }
    }
    Ok(found)
}

/// `cargo xtask wheel`: the release wheel in `target/wheels/`.
pub fn wheel(env: &PyEnv) -> Result<()> {
    let out = crate::target_dir().join("wheels");
    let wheel = build_wheel(env, "release", &out)?;
    let size = fs::metadata(&wheel).map(|m| m.len()).unwrap_or(0);
    println!(
        "built {} ({:.1} MB); install it with `pip install {}`",
        wheel.display(),
        size as f64 / 1e6,
        wheel.display()
    );
    Ok(())
}

/// Builds the dev wheel and installs it into a folder of its own; returns
/// the wheel and the folder to put on `PYTHONPATH`.
fn install_for_tests(env: &PyEnv) -> Result<(PathBuf, PathBuf)> {
    let base = crate::target_dir().join("python");
    let wheel = build_wheel(env, "dev", &base.join("wheel"))?;
    let site = base.join("site");
    if site.exists() {
        fs::remove_dir_all(&site).with_context(|| format!("cannot remove {}", site.display()))?;
    }
    crate::run(
        Command::new(&env.python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
            ])
            .args(["--no-deps", "--target"])
            .arg(&site)
            .arg(&wheel),
    )?;
    Ok((wheel, site))
}

/// Runs the pytest suite against a freshly built wheel (`args` go to
/// pytest), then the fresh-venv check unless `args` select tests.
pub fn check(env: &PyEnv, args: &[String]) -> Result<()> {
    println!("== the mfm Python package (pytest)");
    let cli = crate::no_network::build()?;
    let (wheel, site) = install_for_tests(env)?;
    crate::run(
        Command::new(&env.python)
            .current_dir(package_dir().join("tests"))
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            .args(args)
            .env("PYTHONPATH", &site)
            .env("MFM_CLI", &cli)
            .env("MFM_REQUIRE_ORACLES", "1"),
    )?;
    if args.is_empty() {
        fresh_venv(&wheel)?;
    }
    Ok(())
}

/// The acceptance check: `pip install WHEEL` into a new virtual
/// environment, then noise on a mesh file from a script that sees neither
/// the checkout, nor cargo, nor libtorch.
fn fresh_venv(wheel: &Path) -> Result<()> {
    let venv = crate::target_dir().join("python/fresh-venv");
    if venv.exists() {
        fs::remove_dir_all(&venv).with_context(|| format!("cannot remove {}", venv.display()))?;
    }
    crate::run(
        Command::new(crate::pyenv::base_python())
            .args(["-m", "venv"])
            .arg(&venv),
    )?;
    let python = venv.join("bin/python");
    crate::run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
            ])
            .arg(wheel),
    )?;
    // an empty folder outside the checkout's source tree
    let work = crate::target_dir().join("python/fresh-run");
    if work.exists() {
        fs::remove_dir_all(&work).with_context(|| format!("cannot remove {}", work.display()))?;
    }
    fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
    let script = r#"
import os, sys, numpy as np, mfm
assert "crates" not in mfm.__file__ and mfm.__file__.startswith(sys.prefix), mfm.__file__
# an octahedron, as a user's OBJ file
open("octa.obj", "w").write(
    "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
    "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")
V, F = mfm.read_mesh("octa.obj")
mfm.write_mesh("fine.ply", *mfm.read_mesh("builtin:icosphere:4"))
V, F = mfm.read_mesh("fine.ply")
x = mfm.MaternNoise(V, F, tau=100.0).sample(8, channels=3, seed=1)
assert x.shape == (8, V.shape[0], 3) and x.dtype == np.float32 and np.isfinite(x).all()
print(f"mfm {mfm.__version__} from {os.path.dirname(mfm.__file__)}: {x.shape[0]} samples of Matern noise on {V.shape[0]} vertices, std {x.std():.3g}")
"#;
    let out = Command::new(&python)
        .current_dir(&work)
        .env_clear()
        .env("PATH", "/usr/bin:/bin")
        .env("HOME", &work)
        .args(["-c", script])
        .output()
        .with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        bail!(
            "the wheel installed in a fresh venv failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    print!("ok (fresh venv): {}", String::from_utf8_lossy(&out.stdout));
    Ok(())
}

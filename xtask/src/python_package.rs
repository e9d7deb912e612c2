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
//!
//! `cargo xtask bench python` times the wheel against the command line and
//! the Python sparse Cholesky stack (`xtask/python/bench_python.py`).

use anyhow::{Context, Result, bail};
use mfm_reproduce::pyenv::PyEnv;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The package's folder (its `pyproject.toml` and `Cargo.toml`).
fn package_dir() -> PathBuf {
    mfm_reproduce::workspace::root().join("crates/python")
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
    mfm_reproduce::workspace::run(
        Command::new(&maturin)
            .current_dir(package_dir())
            .args(["build", "--quiet", "--profile", profile, "--out"])
            .arg(out)
            // the wheel links no libtorch; keep cargo's view of the
            // environment the same as `cargo test`'s so that the shared
            // dependencies are not rebuilt
            .env("CARGO_TARGET_DIR", mfm_reproduce::workspace::target_dir()),
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
    let out = mfm_reproduce::workspace::target_dir().join("wheels");
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
    let base = mfm_reproduce::workspace::target_dir().join("python");
    let wheel = build_wheel(env, "dev", &base.join("wheel"))?;
    let site = install_into(&env.python, &wheel, &base.join("site"))?;
    Ok((wheel, site))
}

/// `pip install --no-deps --target SITE WHEEL` with `python` (the folder
/// emptied first); returns `site`, to put on `PYTHONPATH`.
fn install_into(python: &Path, wheel: &Path, site: &Path) -> Result<PathBuf> {
    if site.exists() {
        fs::remove_dir_all(site).with_context(|| format!("cannot remove {}", site.display()))?;
    }
    mfm_reproduce::workspace::run(
        Command::new(python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
            ])
            .args(["--no-deps", "--target"])
            .arg(site)
            .arg(wheel),
    )?;
    Ok(site.to_path_buf())
}

/// Runs the pytest suite against a freshly built wheel (`args` go to
/// pytest), then the fresh-venv check unless `args` select tests.
pub fn check(env: &PyEnv, args: &[String]) -> Result<()> {
    println!("== the mfm Python package (pytest)");
    let cli = crate::no_network::build()?;
    let (wheel, site) = install_for_tests(env)?;
    mfm_reproduce::workspace::run(
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
    let venv = mfm_reproduce::workspace::target_dir().join("python/fresh-venv");
    if venv.exists() {
        fs::remove_dir_all(&venv).with_context(|| format!("cannot remove {}", venv.display()))?;
    }
    mfm_reproduce::workspace::run(
        Command::new(mfm_reproduce::pyenv::base_python())
            .args(["-m", "venv"])
            .arg(&venv),
    )?;
    let python = venv.join("bin/python");
    mfm_reproduce::workspace::run(
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
    let work = mfm_reproduce::workspace::target_dir().join("python/fresh-run");
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

/// Options of `cargo xtask bench python`.
pub struct PythonBench<'a> {
    /// Mesh file (subdivided `subdiv` times).
    pub mesh: &'a Path,
    /// Midpoint subdivisions.
    pub subdiv: u32,
    /// Samples per batch.
    pub batch: usize,
    /// Screening weight.
    pub tau: f64,
    /// Timed rounds after the warm-up.
    pub runs: usize,
}

/// `cargo xtask bench python`: the release wheel, the release `mfm` and the
/// peers timed in one process; prints the table and keeps the JSON in
/// `<target>/bench-python/report.json`.
pub fn bench(env: &PyEnv, opts: &PythonBench) -> Result<()> {
    if !opts.mesh.is_file() {
        bail!(
            "{}: mesh file not found (pass --mesh PATH; the default needs ../shared/meshes)",
            opts.mesh.display()
        );
    }
    if !(opts.tau.is_finite() && opts.tau > 0.0) || opts.batch == 0 || opts.runs == 0 {
        bail!("--tau must be positive, --batch and --runs at least 1");
    }
    let peers = crate::bench_noise::ensure_peers()?;
    let dir = mfm_reproduce::workspace::target_dir().join("bench-python");
    let wheel = build_wheel(env, "release", &dir.join("wheel"))?;
    let site = install_into(&peers, &wheel, &dir.join("site"))?;
    let cli = mfm_reproduce::mfm::build_release(env)?;
    let scripts = mfm_reproduce::workspace::root().join("xtask/python");
    let path = std::env::join_paths([site.as_path(), scripts.as_path()])?;
    let out = Command::new(&peers)
        .arg(scripts.join("bench_python.py"))
        .args([
            "--subdiv",
            &opts.subdiv.to_string(),
            "--runs",
            &opts.runs.to_string(),
        ])
        .args([
            "--batch",
            &opts.batch.to_string(),
            "--tau",
            &opts.tau.to_string(),
        ])
        .arg("--work")
        .arg(dir.join("work"))
        .arg("--cli")
        .arg(&cli)
        .arg(opts.mesh)
        .env("PYTHONPATH", path)
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("cannot run bench_python.py")?;
    if !out.status.success() {
        bail!("bench_python.py failed ({})", out.status);
    }
    let report: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("bench_python.py did not print JSON")?;
    let json = dir.join("report.json");
    fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    print_bench(&report, &json)
}

fn print_bench(r: &serde_json::Value, json: &Path) -> Result<()> {
    let t = &r["timings"];
    let ms = |k: &str, s: &str| t[k][s].as_f64().unwrap_or(f64::NAN);
    println!(
        "{}; {} vertices, {} faces, batch {}, tau {}; fastest of {} rounds (medians in {})",
        r["tool"].as_str().unwrap_or("?"),
        r["vertices"],
        r["faces"],
        r["batch"],
        r["tau"],
        r["runs"],
        json.display()
    );
    println!(
        "| pipeline (factor + {} samples) | fastest s | median s | vs mfm (Python, f64) |",
        r["batch"]
    );
    println!("|---|---|---|---|");
    let ours = ms("mfm_py_f64", "min_ms");
    let rows = [
        ("mfm, Python, float64 (arrays in memory)", "mfm_py_f64"),
        ("mfm, Python, float32", "mfm_py_f32"),
        ("mfm, Python, read_mesh + float64", "mfm_py_file"),
        ("`mfm noise` (read, sample, write the .npy)", "cli"),
        ("libigl + CHOLMOD (scikit-sparse)", "cholmod"),
        ("libigl + cholespy", "cholespy"),
    ];
    for (label, key) in rows {
        println!(
            "| {label} | {:.2} | {:.2} | {:.2}x |",
            ms(key, "min_ms") / 1e3,
            ms(key, "median_ms") / 1e3,
            ms(key, "min_ms") / ours
        );
    }
    let best_peer = ms("cholmod", "min_ms").min(ms("cholespy", "min_ms"));
    println!(
        "Python (read_mesh + f64) / CLI = {:.2} (goal <= 1.2); Python f64 / best peer = {:.2} (goal <= 0.5); float64 samples equal the CLI's file: {}; f64 result {} MB, peak RSS after the mfm rounds {} MB",
        ms("mfm_py_file", "min_ms") / ms("cli", "min_ms"),
        ours / best_peer,
        r["max_abs_difference_python_vs_cli"].as_f64() == Some(0.0),
        r["f64_result_mb"],
        r["peak_rss_mb_after_mfm_rounds"]
    );
    Ok(())
}

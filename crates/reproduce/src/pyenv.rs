//! The project's Python environment: pinned torch (whose libtorch `tch` links
//! against), the oracles used by tests (libigl, scipy, numpy, pyvista), and
//! maturin and pytest, which build and test the `mfm` Python package.
//!
//! It lives in a per-user cache folder keyed by the pinned versions, so every
//! clone and every CI run on one machine shares one 4.7 GB install:
//! `$MFM_CACHE_DIR` or `$XDG_CACHE_HOME/mfm` or `~/.cache/mfm`, then
//! `py<XY>-torch<ver>-igl<ver>-...`. `$MFM_PYENV` names the folder outright.
//! A finished install leaves a marker file; a run that finds it does nothing.
//! A lock file serializes concurrent installs.

use anyhow::{Context, Result, bail};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Pinned packages: (pip requirement, short tag for the folder name).
const PINNED: &[(&str, &str)] = &[
    ("torch==2.13.0", "torch2.13.0"),
    ("libigl==2.6.3", "igl2.6.3"),
    ("scipy==1.17.1", "scipy1.17.1"),
    ("numpy==2.4.6", "np2.4.6"),
    ("pyvista==0.49.1", "pv0.49.1"),
    // the Python package: its build backend and its test runner
    ("maturin==1.16.0", "maturin1.16.0"),
    ("pytest==9.2.0", "pytest9.2.0"),
];

const MARKER: &str = ".mfm-env-complete";

/// A ready environment.
#[derive(Clone, Debug)]
pub struct PyEnv {
    /// The venv's interpreter.
    pub python: PathBuf,
    /// The libtorch folder `tch` builds against (has `include/` and `lib/`).
    pub libtorch: PathBuf,
}

impl PyEnv {
    /// Environment variables that make cargo build `tch` against this
    /// libtorch and let tests find the oracle interpreter.
    pub fn cargo_env(&self) -> Vec<(&'static str, PathBuf)> {
        vec![
            ("LIBTORCH", self.libtorch.clone()),
            ("MFM_PYTHON", self.python.clone()),
        ]
    }
}

fn cache_root() -> Result<PathBuf> {
    if let Some(d) = std::env::var_os("MFM_CACHE_DIR") {
        return Ok(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Ok(PathBuf::from(d).join("mfm"));
    }
    let home = std::env::var_os("HOME")
        .context("neither MFM_CACHE_DIR, XDG_CACHE_HOME nor HOME is set")?;
    Ok(PathBuf::from(home).join(".cache/mfm"))
}

/// The interpreter environments are created with (`$MFM_BASE_PYTHON` or `python3`).
pub fn base_python() -> String {
    std::env::var("MFM_BASE_PYTHON").unwrap_or_else(|_| "python3".to_owned())
}

/// `311` for Python 3.11.
///
/// # Errors
/// When `python` cannot run or fails.
pub fn python_tag(python: &str) -> Result<String> {
    let out = Command::new(python)
        .args([
            "-c",
            "import sys; print(f'{sys.version_info[0]}{sys.version_info[1]}')",
        ])
        .output()
        .with_context(|| {
            format!("cannot run `{python}`: a Python 3 interpreter is needed (set MFM_BASE_PYTHON)")
        })?;
    if !out.status.success() {
        bail!(
            "`{python}` failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

/// The folder of the environment, created or not.
///
/// # Errors
/// When the base interpreter cannot tell its version, or no cache folder
/// is known.
pub fn env_dir() -> Result<PathBuf> {
    if let Some(d) = std::env::var_os("MFM_PYENV") {
        return Ok(PathBuf::from(d));
    }
    let tag = python_tag(&base_python())?;
    let mut name = format!("py{tag}");
    for (_, short) in PINNED {
        name.push('-');
        name.push_str(short);
    }
    Ok(cache_root()?.join(name))
}

fn run(cmd: &mut Command) -> Result<()> {
    let status = cmd
        .status()
        .with_context(|| format!("cannot run {cmd:?}"))?;
    if !status.success() {
        bail!("{cmd:?} failed with {status}");
    }
    Ok(())
}

/// Finds or creates the environment. Installing takes about a minute and
/// 4.7 GB; a second call returns at once.
///
/// # Errors
/// When the install fails, or its libtorch folder has no `lib/`.
pub fn ensure() -> Result<PyEnv> {
    let dir = env_dir()?;
    let python = dir.join("bin/python");
    let marker = dir.join(MARKER);
    if !marker.is_file() {
        let parent = dir.parent().unwrap_or(Path::new("."));
        fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
        let mut lock_name = dir.file_name().unwrap_or_default().to_os_string();
        lock_name.push(".lock");
        let lock_path = dir.with_file_name(lock_name);
        let lock = fs::File::create(&lock_path)
            .with_context(|| format!("cannot create lock file {}", lock_path.display()))?;
        if lock.try_lock().is_err() {
            eprintln!(
                "xtask: another process is installing the environment; waiting for {}",
                lock_path.display()
            );
            lock.lock()
                .with_context(|| format!("cannot lock {}", lock_path.display()))?;
        }
        // another process may have finished while we waited
        if !marker.is_file() {
            install(&dir)?;
        }
    }
    let libtorch = match std::env::var_os("LIBTORCH") {
        Some(l) => PathBuf::from(l),
        None => PathBuf::from(fs::read_to_string(&marker)?.trim()),
    };
    if !libtorch.join("lib").is_dir() {
        bail!(
            "libtorch folder {} has no lib/ (set LIBTORCH to a libtorch 2.13 install, or delete {} to reinstall)",
            libtorch.display(),
            dir.display()
        );
    }
    Ok(PyEnv { python, libtorch })
}

fn install(dir: &Path) -> Result<()> {
    let start = std::time::Instant::now();
    eprintln!(
        "xtask: creating the Python environment {} (pinned torch, libigl, scipy, numpy, pyvista, maturin, pytest; ~4.7 GB, about a minute)",
        dir.display()
    );
    let python = dir.join("bin/python");
    if !python.exists() {
        run(Command::new(base_python()).args(["-m", "venv"]).arg(dir))?;
    }
    run(Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--disable-pip-version-check",
            "--progress-bar",
            "off",
            "-q",
        ])
        .args(PINNED.iter().map(|(req, _)| *req)))?;
    let out = Command::new(&python)
        .args([
            "-c",
            "import os, torch; print(os.path.dirname(torch.__file__))",
        ])
        .output()
        .context("cannot ask the environment where torch is")?;
    if !out.status.success() {
        bail!(
            "importing torch failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let libtorch = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    let marker = dir.join(MARKER);
    let tmp = dir.join(format!("{MARKER}.tmp"));
    fs::write(&tmp, format!("{libtorch}\n"))?;
    fs::rename(&tmp, &marker)?;
    eprintln!(
        "xtask: environment ready in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

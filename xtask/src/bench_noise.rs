//! `cargo xtask bench noise`: Matérn noise sampling, mfm-noise against the
//! Python sparse Cholesky stack (CHOLMOD through scikit-sparse, cholespy),
//! in one run on the same vertex and face arrays.
//!
//! The Python peers are not part of the pinned test environment: they get
//! their own virtual environment next to it in the cache folder
//! (`<cache>/bench-peers-py<XY>-<pins>`, see [`mfm_reproduce::pyenv`]), created on
//! the first run and reused afterwards (a marker file records a finished
//! install; a lock file serializes concurrent installs). scikit-sparse
//! 0.4.16 is built from source against the system SuiteSparse; when
//! `cholmod.h` is missing, `apt-get install -y libsuitesparse-dev` is run
//! (printed first).
//!
//! The levels are timed one after the other, each by the Python script and
//! then by mfm-noise's `sampling_timings` example on the OFF file the script
//! wrote, so that the two sides of a row run minutes apart under similar
//! load. The table shows the fastest of the timed runs (the least disturbed
//! by other work on a shared machine); the raw JSON, with medians, is kept
//! in `<target>/bench-noise/`.

use anyhow::{Context, Result, bail};
use mfm_reproduce::pyenv;
use serde_json::Value;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Pinned peer packages: (pip requirement, short tag for the folder name).
/// scikit-sparse 0.5 does not build against Debian 12's SuiteSparse 5.12;
/// 0.4.16 does, from source (no wheel), with [`BUILD_CONSTRAINTS`].
const PEERS: &[(&str, &str)] = &[
    ("numpy==2.4.6", "np2.4.6"),
    ("scipy==1.17.1", "scipy1.17.1"),
    ("libigl==2.6.3", "igl2.6.3"),
    ("scikit-sparse==0.4.16", "sksparse0.4.16"),
    ("cholespy==2.2.0", "cholespy2.2.0"),
];

/// Versions for scikit-sparse 0.4.16's isolated build environment (its
/// `pyproject.toml` asks for `Cython>=0.22`, `numpy>=2.0`, setuptools and
/// wheel, unpinned): the set that built it here, passed to pip as
/// `PIP_CONSTRAINT` so that a later Cython or numpy cannot break the build.
const BUILD_CONSTRAINTS: &str =
    "Cython==3.3.1\nnumpy==2.4.6\nsetuptools==84.2.1\nwheel==0.48.0\npackaging==26.4\n";

const MARKER: &str = ".mfm-env-complete";

/// Header that scikit-sparse's build needs.
const CHOLMOD_HEADER: &str = "/usr/include/suitesparse/cholmod.h";

/// Options of the benchmark.
pub struct NoiseBench<'a> {
    /// Mesh file (its midpoint subdivisions are timed too).
    pub mesh: &'a Path,
    /// Comma-separated subdivision levels.
    pub levels: &'a str,
    /// Samples per batch.
    pub batch: usize,
    /// Screening weight `tau`.
    pub tau: f64,
    /// Timed runs per measurement, after one warm-up run (the table shows the
    /// fastest; the JSON has the median too).
    pub runs: usize,
}

/// Runs the benchmark and prints the table.
pub fn noise(opts: &NoiseBench) -> Result<()> {
    if !opts.mesh.is_file() {
        bail!(
            "{}: mesh file not found (pass --mesh PATH; the default needs ../shared/meshes)",
            opts.mesh.display()
        );
    }
    if !(opts.tau.is_finite() && opts.tau > 0.0) {
        bail!("--tau must be a positive number, got {}", opts.tau);
    }
    let python = ensure_peers()?;
    let dir = mfm_reproduce::workspace::target_dir().join("bench-noise");
    fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let script = mfm_reproduce::workspace::root().join("xtask/python/bench_noise.py");
    let (batch, tau, runs) = (
        opts.batch.to_string(),
        opts.tau.to_string(),
        opts.runs.to_string(),
    );
    // the Rust example first: it is built (minutes on a cold cache) before
    // any timing starts, so the build does not overlap the Python timings
    eprintln!("xtask: building the mfm-noise sampling_timings example (release)");
    mfm_reproduce::workspace::run(cargo().args([
        "build",
        "--quiet",
        "--release",
        "-p",
        "mfm-noise",
        "--example",
        "sampling_timings",
    ]))?;
    let levels: Vec<u32> = opts
        .levels
        .split(',')
        .map(|l| {
            l.trim()
                .parse::<u32>()
                .with_context(|| format!("--levels {:?}: not a list of integers", opts.levels))
        })
        .collect::<Result<_>>()?;
    let stem = opts
        .mesh
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "mesh".to_owned());
    let load_before = load_average();
    // level by level, the peers then mfm, so that both sides of a row are
    // timed minutes apart under similar load
    let mut peers = Value::Null;
    let mut ours = Value::Null;
    let mut peer_results = Vec::new();
    let mut our_results = Vec::new();
    for level in levels {
        eprintln!(
            "xtask: level {level}: timing CHOLMOD and cholespy on {} subdivided {level} times",
            opts.mesh.display()
        );
        peers = capture(
            Command::new(&python)
                .arg(&script)
                .args(["--subdiv", &level.to_string(), "--runs", &runs])
                .args(["--batch", &batch, "--tau", &tau, "--write-off"])
                .arg(&dir)
                .arg(opts.mesh),
        )?;
        let file = dir.join(format!("{stem}_s{level}.off"));
        eprintln!("xtask: level {level}: timing mfm-noise on the same arrays");
        ours = capture(
            cargo()
                .args([
                    "run",
                    "--quiet",
                    "--release",
                    "-p",
                    "mfm-noise",
                    "--example",
                    "sampling_timings",
                    "--",
                ])
                .args(["--runs", &runs, "--batch", &batch, "--tau", &tau])
                .arg(&file),
        )?;
        for (json, all) in [(&peers, &mut peer_results), (&ours, &mut our_results)] {
            if let Some(r) = json["results"].as_array() {
                all.extend(r.iter().cloned());
            }
        }
    }
    peers["results"] = Value::Array(peer_results);
    ours["results"] = Value::Array(our_results);
    let load_after = load_average();
    for (name, json) in [("python.json", &peers), ("mfm.json", &ours)] {
        let path = dir.join(name);
        fs::write(&path, serde_json::to_string_pretty(json)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    println!("peers: {}", peers["tool"].as_str().unwrap_or("?"));
    println!(
        "CHOLMOD/BLAS libraries loaded: {}",
        peers["blas"]
            .as_array()
            .map(|a| a
                .iter()
                .filter_map(Value::as_str)
                .filter_map(|p| Path::new(p).file_name())
                .map(|p| p.to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(", "))
            .unwrap_or_default()
    );
    println!(
        "mfm: {} rayon threads; load average before {load_before}, after {load_after}; raw JSON in {}",
        ours["threads"],
        dir.display()
    );
    print_table(&peers, &ours, opts.batch)
}

/// A `cargo` command in the workspace root. mfm-noise does not link
/// libtorch, so the pinned environment's variables are not needed.
fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned()));
    cmd.current_dir(mfm_reproduce::workspace::root());
    cmd
}

/// The 1, 5 and 15 minute load averages (`/proc/loadavg`), or `?`.
fn load_average() -> String {
    fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "?".to_owned())
}

/// Runs `cmd`, returning its stdout parsed as JSON.
fn capture(cmd: &mut Command) -> Result<Value> {
    let out = cmd
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("cannot run {cmd:?}"))?;
    if !out.status.success() {
        bail!("command failed ({}): {cmd:?}", out.status);
    }
    serde_json::from_slice(&out.stdout).with_context(|| format!("{cmd:?} did not print JSON"))
}

/// The fastest of the timed runs, in milliseconds (`NaN` if missing).
fn ms(v: &Value, key: &str) -> f64 {
    v["min_ms"][key].as_f64().unwrap_or(f64::NAN)
}

fn print_table(peers: &Value, ours: &Value, batch: usize) -> Result<()> {
    let empty = Vec::new();
    let a = peers["results"].as_array().unwrap_or(&empty);
    let b = ours["results"].as_array().unwrap_or(&empty);
    if a.len() != b.len() || a.is_empty() {
        bail!(
            "the two runs timed different meshes ({} vs {})",
            a.len(),
            b.len()
        );
    }
    let n = batch as f64;
    println!(
        "fastest of {} runs (medians in the JSON); per-sample = batch of {batch} / {batch}; ratio = best of CHOLMOD and cholespy / mfm (> 1: mfm faster)",
        ours["runs"]
    );
    println!(
        "| {:>7} | {:<18} | {:>9} | {:>9} | {:>9} | {:>9} | {:>9} | {:>9} |",
        "V", "ms", "CHOLMOD", "cholespy", "mfm f64", "mfm f32", "ratio f64", "ratio f32"
    );
    println!(
        "|{:->9}|{:-<20}|{:->11}|{:->11}|{:->11}|{:->11}|{:->11}|{:->11}|",
        "", "", "", "", "", "", "", ""
    );
    let mut summary = Vec::new();
    for (p, o) in a.iter().zip(b) {
        if p["vertices"] != o["vertices"] || p["faces"] != o["faces"] {
            bail!("mesh sizes differ between the runs: {p} vs {o}");
        }
        let v = o["vertices"].as_u64().unwrap_or(0);
        let rows = [
            (
                "factor",
                ms(p, "cholmod_factor"),
                ms(p, "cholespy_factor"),
                ms(o, "factor"),
                f64::NAN,
            ),
            (
                "setup (ops+factor)",
                ms(p, "operators") + ms(p, "cholmod_factor"),
                ms(p, "operators") + ms(p, "cholespy_factor"),
                ms(o, "setup"),
                f64::NAN,
            ),
            (
                "sample, per sample",
                ms(p, "cholmod_sample") / n,
                ms(p, "cholespy_sample") / n,
                ms(o, "sample_f64") / n,
                ms(o, "sample_f32") / n,
            ),
            (
                "solve, per sample",
                ms(p, "cholmod_solve") / n,
                ms(p, "cholespy_solve") / n,
                ms(o, "solve_f64") / n,
                ms(o, "solve_f32") / n,
            ),
        ];
        for (name, cholmod, cholespy, f64_ms, f32_ms) in rows {
            let best = cholmod.min(cholespy);
            println!(
                "| {:>7} | {:<18} | {} | {} | {} | {} | {} | {} |",
                v,
                name,
                cell(cholmod),
                cell(cholespy),
                cell(f64_ms),
                cell(f32_ms),
                cell(best / f64_ms),
                cell(best / f32_ms)
            );
        }
        let factor_ok = ms(o, "factor") <= ms(p, "cholmod_factor");
        let best_sample = ms(p, "cholmod_sample").min(ms(p, "cholespy_sample"));
        let sample_ok = ms(o, "sample_f64") < best_sample;
        summary.push(format!(
            "V = {v}: factor {} CHOLMOD, f64 sampling {} the best peer, {:.2} ms per sample (f32 {:.2} ms)",
            if factor_ok { "no slower than" } else { "SLOWER than" },
            if sample_ok { "faster than" } else { "NOT faster than" },
            ms(o, "sample_f64") / n,
            ms(o, "sample_f32") / n,
        ));
    }
    println!();
    println!(
        "goals (factor <= CHOLMOD; batch per-sample < best peer; stretch <= 5 ms/sample at ~700k-900k):"
    );
    for s in summary {
        println!("  {s}");
    }
    Ok(())
}

fn cell(x: f64) -> String {
    if !x.is_finite() {
        format!("{:>9}", "-")
    } else if x >= 100.0 {
        format!("{x:>9.1}")
    } else if x >= 1.0 {
        format!("{x:>9.2}")
    } else {
        format!("{x:>9.4}")
    }
}

/// The peers' environment folder, next to the pinned one.
fn peers_dir() -> Result<PathBuf> {
    let pinned = mfm_reproduce::pyenv::env_dir()?;
    let cache = pinned.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut name = format!(
        "bench-peers-py{}",
        pyenv::python_tag(&pyenv::base_python())?
    );
    for (_, short) in PEERS {
        name.push('-');
        name.push_str(short);
    }
    Ok(cache.join(name))
}

/// Finds or creates the peers' environment; returns its interpreter.
pub(crate) fn ensure_peers() -> Result<PathBuf> {
    let dir = peers_dir()?;
    let python = dir.join("bin/python");
    let marker = dir.join(MARKER);
    if marker.is_file() {
        return Ok(python);
    }
    let parent = dir.parent().unwrap_or(Path::new("."));
    fs::create_dir_all(parent).with_context(|| format!("cannot create {}", parent.display()))?;
    let mut lock_name = dir.file_name().unwrap_or_default().to_os_string();
    lock_name.push(".lock");
    let lock_path = dir.with_file_name(lock_name);
    let lock = fs::File::create(&lock_path)
        .with_context(|| format!("cannot create lock file {}", lock_path.display()))?;
    if lock.try_lock().is_err() {
        eprintln!(
            "xtask: another process is installing the benchmark peers; waiting for {}",
            lock_path.display()
        );
        lock.lock()
            .with_context(|| format!("cannot lock {}", lock_path.display()))?;
    }
    if !marker.is_file() {
        install_peers(&dir)?;
    }
    Ok(python)
}

fn install_peers(dir: &Path) -> Result<()> {
    let start = std::time::Instant::now();
    ensure_suitesparse()?;
    eprintln!(
        "xtask: creating the benchmark peers' environment {} ({}; building scikit-sparse takes a minute or two)",
        dir.display(),
        PEERS.iter().map(|(r, _)| *r).collect::<Vec<_>>().join(" ")
    );
    let python = dir.join("bin/python");
    if !python.exists() {
        mfm_reproduce::workspace::run(
            Command::new(pyenv::base_python())
                .args(["-m", "venv"])
                .arg(dir),
        )?;
    }
    let constraints = dir.join("build-constraints.txt");
    fs::write(&constraints, BUILD_CONSTRAINTS)
        .with_context(|| format!("cannot write {}", constraints.display()))?;
    mfm_reproduce::workspace::run(
        Command::new(&python)
            .env("PIP_CONSTRAINT", &constraints)
            .args([
                "-m",
                "pip",
                "install",
                "--disable-pip-version-check",
                "--progress-bar",
                "off",
                "-q",
            ])
            .args(PEERS.iter().map(|(req, _)| *req)),
    )?;
    mfm_reproduce::workspace::run(
        Command::new(&python).args(["-c", "import sksparse.cholmod, cholespy, igl, scipy.sparse"]),
    )
    .context("the peers' environment was installed but does not import")?;
    let tmp = dir.join(format!("{MARKER}.tmp"));
    fs::write(&tmp, "complete\n")?;
    fs::rename(&tmp, dir.join(MARKER))?;
    eprintln!(
        "xtask: benchmark peers ready in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Installs SuiteSparse's headers with apt-get when `cholmod.h` is missing.
fn ensure_suitesparse() -> Result<()> {
    if Path::new(CHOLMOD_HEADER).is_file() {
        return Ok(());
    }
    let apt = Command::new("apt-get")
        .arg("--version")
        .stdout(Stdio::null())
        .status();
    if !matches!(apt, Ok(s) if s.success()) {
        bail!(
            "{CHOLMOD_HEADER} is missing and apt-get is not available: install SuiteSparse's \
             development files (Debian/Ubuntu: libsuitesparse-dev) so that scikit-sparse 0.4.16 can build"
        );
    }
    eprintln!(
        "xtask: {CHOLMOD_HEADER} is missing; running `apt-get update` and `apt-get install -y libsuitesparse-dev` (scikit-sparse builds against it)"
    );
    mfm_reproduce::workspace::run(Command::new("apt-get").arg("update"))
        .context("apt-get update failed (SuiteSparse headers are needed; are you root?)")?;
    mfm_reproduce::workspace::run(
        Command::new("apt-get")
            .args(["install", "-y", "libsuitesparse-dev"])
            .env("DEBIAN_FRONTEND", "noninteractive"),
    )
    .context("apt-get install libsuitesparse-dev failed (are you root?)")?;
    if !Path::new(CHOLMOD_HEADER).is_file() {
        bail!("libsuitesparse-dev is installed but {CHOLMOD_HEADER} is still missing");
    }
    Ok(())
}

//! `cargo xtask bench ...`: benchmarks that compare mfm with the Python
//! reference stack in one run, on the same vertex and face arrays.

use anyhow::{Context, Result, bail};
use mfm_reproduce::pyenv::PyEnv;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Operator names in the order they are printed.
const OPERATORS: [&str; 6] = [
    "face_areas",
    "lumped_mass",
    "cotangent_laplacian",
    "intrinsic_gradient",
    "laplacian_and_mass",
    "operators_new",
];

/// Times operator assembly with libigl (through its Python bindings) and with
/// `mfm-geometry`, on `mesh` and its midpoint subdivisions at `levels`, and
/// prints one table with both medians and their ratio.
///
/// libigl subdivides and writes each level as an OFF file; the Rust example
/// then reads exactly those files, so both time identical arrays in the same
/// vertex order.
pub fn operators(env: &PyEnv, mesh: &Path, levels: &str, runs: u32) -> Result<()> {
    if !mesh.is_file() {
        bail!(
            "{}: mesh file not found (pass --mesh PATH; the default needs ../shared/meshes)",
            mesh.display()
        );
    }
    let dir = mfm_reproduce::workspace::target_dir().join("bench-operators");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let script = mfm_reproduce::workspace::root().join("xtask/python/bench_operators.py");
    eprintln!(
        "xtask: timing libigl on {} (levels {levels})",
        mesh.display()
    );
    let igl = capture(
        Command::new(&env.python)
            .arg(&script)
            .args([
                "--subdiv",
                levels,
                "--runs",
                &runs.to_string(),
                "--write-off",
            ])
            .arg(&dir)
            .arg(mesh),
    )?;
    let stem = mesh
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "mesh".to_owned());
    let mut files: Vec<PathBuf> = Vec::new();
    for level in levels.split(',') {
        files.push(dir.join(format!("{stem}_s{}.off", level.trim())));
    }
    eprintln!("xtask: timing mfm-geometry on the same arrays");
    let ours = capture(
        mfm_reproduce::workspace::cargo(env)
            .args([
                "run",
                "--quiet",
                "--release",
                "-p",
                "mfm-geometry",
                "--example",
                "operator_timings",
                "--",
                "--runs",
                &runs.to_string(),
            ])
            .args(&files),
    )?;
    print_table(&igl, &ours)
}

/// Runs `cmd`, returning its stdout parsed as JSON.
fn capture(cmd: &mut Command) -> Result<Value> {
    let out = cmd
        .stderr(std::process::Stdio::inherit())
        .output()
        .with_context(|| format!("cannot run {cmd:?}"))?;
    if !out.status.success() {
        bail!("command failed ({}): {cmd:?}", out.status);
    }
    serde_json::from_slice(&out.stdout).with_context(|| format!("{cmd:?} did not print JSON"))
}

fn print_table(igl: &Value, ours: &Value) -> Result<()> {
    let empty = Vec::new();
    let a = igl["results"].as_array().unwrap_or(&empty);
    let b = ours["results"].as_array().unwrap_or(&empty);
    if a.len() != b.len() || a.is_empty() {
        bail!(
            "the two runs timed different meshes ({} vs {})",
            a.len(),
            b.len()
        );
    }
    println!(
        "threads: {}, runs per timing: {} (median ms; ratio = libigl / mfm)",
        ours["threads"], ours["runs"]
    );
    println!(
        "| {:<20} | {:>8} | {:>9} | {:>10} | {:>10} | {:>6} |",
        "operator", "V", "F", "libigl ms", "mfm ms", "ratio"
    );
    println!(
        "|{:-<22}|{:->10}|{:->11}|{:->12}|{:->12}|{:->8}|",
        "", "", "", "", "", ""
    );
    for (ri, ro) in a.iter().zip(b) {
        if ri["vertices"] != ro["vertices"] || ri["faces"] != ro["faces"] {
            bail!("mesh sizes differ between the runs: {ri} vs {ro}");
        }
        for op in OPERATORS {
            let ti = ri["median_ms"][op].as_f64().unwrap_or(f64::NAN);
            let to = ro["median_ms"][op].as_f64().unwrap_or(f64::NAN);
            println!(
                "| {:<20} | {:>8} | {:>9} | {:>10.2} | {:>10.2} | {:>6.2} |",
                op,
                ro["vertices"].as_u64().unwrap_or(0),
                ro["faces"].as_u64().unwrap_or(0),
                ti,
                to,
                ti / to
            );
        }
    }
    Ok(())
}

//! `cargo xtask demo`: the main job on a built-in default.
//!
//! Builds the `mfm` binary, loads a built-in procedural mesh, prints its
//! report, writes its operators and rendered pictures, samples Matérn and
//! naive noise on it, measures the noise spectrum on two resolutions, and
//! writes a short Markdown report linking everything. Training and sampling
//! join when the flow-matching crate lands.

use crate::pyenv::PyEnv;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The built-in mesh the demo runs on.
const DEMO_MESH: &str = "builtin:torus";

fn mfm_binary(env: &PyEnv) -> Result<PathBuf> {
    crate::run(crate::cargo(env).args(["build", "--release", "--quiet", "-p", "mfm-cli"]))?;
    let exe = crate::target_dir().join("release/mfm");
    anyhow::ensure!(exe.is_file(), "built mfm not found at {}", exe.display());
    Ok(exe)
}

fn mfm(exe: &Path, args: &[&str]) -> Result<String> {
    let out = Command::new(exe)
        .args(args)
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    print!("{stdout}");
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    anyhow::ensure!(
        out.status.success(),
        "mfm {} failed ({})",
        args.join(" "),
        out.status
    );
    Ok(stdout)
}

/// Runs the demo, writing everything under `out`.
pub fn run(env: &PyEnv, out: &Path) -> Result<()> {
    let start = std::time::Instant::now();
    let out = if out.is_absolute() {
        out.to_path_buf()
    } else {
        crate::root().join(out)
    };
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let exe = mfm_binary(env)?;
    let s = |p: &Path| p.to_string_lossy().into_owned();

    println!("== mesh report ({DEMO_MESH})");
    let report = mfm(&exe, &["info", DEMO_MESH])?;
    let mesh_path = out.join("mesh.ply");
    mfm(&exe, &["convert", DEMO_MESH, &s(&mesh_path)])?;

    println!("== operators");
    let ops_dir = out.join("operators");
    let ops = mfm(&exe, &["operators", DEMO_MESH, "--out", &s(&ops_dir)])?;

    println!("== pictures");
    let shaded = out.join("mesh.png");
    mfm(&exe, &["render", DEMO_MESH, "--out", &s(&shaded)])?;
    let mass_png = out.join("mass.png");
    mfm(
        &exe,
        &[
            "render",
            DEMO_MESH,
            "--scalar",
            "mass",
            "--out",
            &s(&mass_png),
        ],
    )?;

    println!("== noise");
    let noise_png = out.join("matern.png");
    let naive_png = out.join("naive.png");
    let noise = mfm(
        &exe,
        &[
            "noise",
            DEMO_MESH,
            "--kind",
            "matern",
            "--tau",
            "50",
            "--samples",
            "4",
            "--seed",
            "1",
            "--out",
            &s(&out.join("matern.npy")),
            "--png",
            &s(&noise_png),
        ],
    )?;
    mfm(
        &exe,
        &[
            "noise",
            DEMO_MESH,
            "--kind",
            "naive",
            "--seed",
            "1",
            "--out",
            &s(&out.join("naive.npy")),
            "--png",
            &s(&naive_png),
        ],
    )?;
    println!("== spectrum (matern on the mesh and a finer builtin:torus:2)");
    let spectrum = mfm(
        &exe,
        &[
            "spectrum",
            DEMO_MESH,
            "builtin:torus:2",
            "--tau",
            "50",
            "--samples",
            "2000",
            "--k",
            "64",
            "--out",
            &s(&out.join("spectrum.json")),
            "--plots",
            &s(&out.join("spectrum")),
        ],
    )?;

    let mut md = String::new();
    writeln!(md, "# mfm demo\n")?;
    writeln!(md, "Mesh: `{DEMO_MESH}` (written to `mesh.ply`).\n")?;
    writeln!(md, "## Report\n\n```\n{}```\n", report)?;
    writeln!(
        md,
        "## Operators\n\nWritten to `operators/` (Matrix Market and .npy).\n\n```\n{}```\n",
        ops
    )?;
    writeln!(
        md,
        "## Pictures\n\n![shaded](mesh.png)\n\n![lumped mass per vertex](mass.png)\n"
    )?;
    writeln!(
        md,
        "## Noise\n\nMatérn noise (tau = 50) and naive per-vertex noise, same seed:\n\n\
![matern](matern.png) ![naive](naive.png)\n\n```\n{noise}```\n"
    )?;
    writeln!(
        md,
        "## Spectrum\n\nPer-frequency variance of Matérn noise against theory on two \
resolutions of the torus (`spectrum.json`):\n\n```\n{spectrum}```\n\n\
![variance](spectrum/variance.png)\n\n![coefficients](spectrum/coefficients.png)\n"
    )?;
    writeln!(md, "Total time: {:.1} s", start.elapsed().as_secs_f64())?;
    let report_path = out.join("README.md");
    std::fs::write(&report_path, md)?;
    println!(
        "== demo finished in {:.1} s; report: {}",
        start.elapsed().as_secs_f64(),
        report_path.display()
    );
    Ok(())
}

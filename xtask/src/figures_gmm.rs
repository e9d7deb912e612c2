//! `cargo xtask reproduce-figures gmm`: the paper's GMM table (Table 2) at
//! CPU scale.
//!
//! One dataset of Gaussian-bump signals on a uniform triangulation (the
//! shared bunny when `../shared/meshes` is present, else the built-in blob)
//! and a reference set on a non-uniform triangulation of the same surface
//! (half refined twice). For each noise kind (default matern, white, naive)
//! the same network is trained for the same number of steps with the same
//! seed, then samples on the non-uniform mesh are compared to the reference
//! set: GMM test error, MMD, COV, 1-NNA. Drives the release `mfm` binary (the
//! xtask itself does not link libtorch). Writes `table.md`, `table.csv`,
//! `table.json`, and per kind the run folder, the samples and
//! `means_KIND.png` (point-wise mean, generated vs reference).

use crate::pyenv::PyEnv;
use anyhow::{Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `reproduce-figures gmm`.
#[derive(clap::Args)]
pub struct GmmArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/gmm")]
    pub out: PathBuf,
    /// Training mesh (default: ../shared/meshes/bunny.off when present,
    /// else builtin:blob).
    #[arg(long)]
    pub mesh: Option<String>,
    /// Noise kinds to compare, comma-separated (mfm train --noise forms).
    #[arg(long, value_delimiter = ',', default_value = "matern:100,white,naive")]
    pub kinds: Vec<String>,
    /// Training steps per kind (run preset `cpu` otherwise).
    #[arg(long, default_value_t = 1500)]
    pub steps: u64,
    /// Training signals.
    #[arg(long, default_value_t = 1000)]
    pub n: usize,
    /// Reference signals on the test mesh, and generated samples per kind.
    #[arg(long, default_value_t = 200)]
    pub reference: usize,
    /// Seed of the dataset, the training runs and the samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

fn mfm_live(exe: &Path, args: &[&str]) -> Result<()> {
    println!("$ mfm {}", args.join(" "));
    crate::demo::mfm_live(exe, args)
}

/// Runs the experiment.
pub fn gmm(env: &PyEnv, args: &GmmArgs) -> Result<()> {
    let root = crate::root();
    let out = if args.out.is_absolute() {
        args.out.clone()
    } else {
        root.join(&args.out)
    };
    let mesh = match &args.mesh {
        Some(m) => m.clone(),
        None => {
            let bunny = root.join("../shared/meshes/bunny.off");
            if bunny.is_file() {
                bunny.to_string_lossy().into_owned()
            } else {
                println!("../shared/meshes/bunny.off not found: using builtin:blob");
                "builtin:blob".to_owned()
            }
        }
    };
    let exe = crate::demo::mfm_binary(env)?;
    let start = Instant::now();
    if out.exists() {
        std::fs::remove_dir_all(&out)
            .with_context(|| format!("cannot remove the previous {}", out.display()))?;
    }
    std::fs::create_dir_all(&out)?;
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let data = out.join("data");
    let seed = args.seed.to_string();
    mfm_live(
        &exe,
        &[
            "dataset",
            "gmm",
            "--mesh",
            &mesh,
            "--out",
            &s(&data),
            "--n",
            &args.n.to_string(),
            "--reference",
            &args.reference.to_string(),
            "--seed",
            &seed,
        ],
    )?;
    let dataset_seconds = start.elapsed().as_secs_f64();
    let test_mesh = data.join("reference/mesh.ply");
    let mut rows: Vec<(String, Value, f64, f64)> = Vec::new();
    for kind in &args.kinds {
        let tag: String = kind
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        let run = out.join(format!("run_{tag}"));
        let t = Instant::now();
        mfm_live(
            &exe,
            &[
                "train",
                "--preset",
                "cpu",
                "--dataset",
                &s(&data.join("train")),
                "--out",
                &s(&run),
                "--steps",
                &args.steps.to_string(),
                "--seed",
                &seed,
                "--noise",
                kind,
                "--quiet",
            ],
        )?;
        let train_seconds = t.elapsed().as_secs_f64();
        let samples = out.join(format!("samples_{tag}"));
        let t = Instant::now();
        mfm_live(
            &exe,
            &[
                "sample",
                "--run",
                &s(&run),
                "--mesh",
                &s(&test_mesh),
                "--n",
                &args.reference.to_string(),
                "--seed",
                &seed,
                "--out",
                &s(&samples),
            ],
        )?;
        let sample_seconds = t.elapsed().as_secs_f64();
        let metrics_path = out.join(format!("metrics_{tag}.json"));
        mfm_live(
            &exe,
            &[
                "eval",
                "--samples",
                &s(&samples.join("samples.npy")),
                "--reference",
                &s(&data.join("reference")),
                "--out",
                &s(&metrics_path),
                "--png",
                &s(&out.join(format!("means_{tag}.png"))),
            ],
        )?;
        let metrics: Value = serde_json::from_str(&std::fs::read_to_string(&metrics_path)?)
            .with_context(|| format!("reading {}", metrics_path.display()))?;
        rows.push((kind.clone(), metrics, train_seconds, sample_seconds));
    }
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let mut md = String::new();
    writeln!(
        md,
        "GMM at CPU scale: train on `{mesh}` (uniform), test on its half-refined remeshing; \
{} training signals, {} reference and {} generated samples, run preset `cpu`, {} steps, seed {}.\n",
        args.n, args.reference, args.reference, args.steps, args.seed
    )?;
    writeln!(
        md,
        "| noise | test error | MMD | COV | 1-NNA | train s | sample s |\n|---|---|---|---|---|---|---|"
    )?;
    let mut csv = String::from("noise,test_error,mmd,cov,one_nna,train_seconds,sample_seconds\n");
    for (kind, m, tr, sa) in &rows {
        writeln!(
            md,
            "| {kind} | {:.4} | {:.4} | {:.3} | {:.3} | {tr:.0} | {sa:.1} |",
            f(m, "test_error"),
            f(m, "mmd"),
            f(m, "cov"),
            f(m, "one_nna")
        )?;
        writeln!(
            csv,
            "{kind},{},{},{},{},{tr:.1},{sa:.2}",
            f(m, "test_error"),
            f(m, "mmd"),
            f(m, "cov"),
            f(m, "one_nna")
        )?;
    }
    writeln!(
        md,
        "\nDataset generation {dataset_seconds:.1} s; total {:.1} s.",
        start.elapsed().as_secs_f64()
    )?;
    std::fs::write(out.join("table.md"), &md)?;
    std::fs::write(out.join("table.csv"), &csv)?;
    let json: Vec<Value> = rows
        .iter()
        .map(|(kind, m, tr, sa)| {
            serde_json::json!({
                "noise": kind, "metrics": m, "train_seconds": tr, "sample_seconds": sa,
            })
        })
        .collect();
    std::fs::write(
        out.join("table.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "mesh": mesh, "steps": args.steps, "n": args.n, "reference": args.reference,
            "seed": args.seed, "rows": json,
        }))?,
    )?;
    print!("{md}");
    println!("reproduce-figures gmm: wrote {}", out.display());
    Ok(())
}

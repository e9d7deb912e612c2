//! `cargo xtask reproduce-figures gmm`: the paper's GMM table (Table 2) at
//! CPU scale.
//!
//! One dataset of Gaussian-bump signals on a uniform triangulation (the
//! shared bunny when `../shared/meshes` is present, else the built-in blob)
//! and a reference set on a non-uniform triangulation of the same surface
//! (half refined twice). For each noise kind (default matern, white, naive)
//! the same network is trained for the same number of steps with the same
//! seed, then samples on the non-uniform mesh are compared to the reference
//! set: the bump-fit quality (residual of a fit by the generator's own
//! family, peak, bumps above half height, the fraction within twice the
//! data's residual, diversity; `mfm_eval::quality`), GMM test error, MMD, COV,
//! 1-NNA. Drives the release `mfm` binary (the
//! xtask itself does not link libtorch). Writes `table.md`, `table.csv`,
//! `table.json`, and per kind the run folder, the samples and
//! `means_KIND.png` (point-wise mean, generated vs reference).

use crate::flow_steps::{Comparison, Quality, arg, fresh_dir, mesh_or_shared, quartiles};
use crate::mfm::Mfm;
use crate::reports::EvalOutcome;
use crate::workspace::in_root;
use anyhow::Result;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::PathBuf;
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
    /// Run preset of every kind's training (`mfm train --preset`).
    #[arg(long, default_value = "cpu")]
    pub preset: String,
    /// Training steps per kind (the preset's otherwise).
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

/// Runs the experiment.
///
/// # Errors
/// When a step fails (a kind whose sampling fails is a row of the table).
pub fn gmm(mfm: &Mfm, args: &GmmArgs) -> Result<()> {
    let out = in_root(&args.out);
    let mesh = mesh_or_shared(args.mesh.as_deref(), "bunny.off", "builtin:blob");
    mfm.exe()?;
    let start = Instant::now();
    fresh_dir(&out)?;
    let data = out.join("data");
    mfm.run(&[
        "dataset",
        "gmm",
        "--mesh",
        &mesh,
        "--out",
        &arg(&data),
        "--n",
        &args.n.to_string(),
        "--reference",
        &args.reference.to_string(),
        "--seed",
        &args.seed.to_string(),
    ])?;
    let dataset_seconds = start.elapsed().as_secs_f64();
    let comparison = Comparison {
        out: &out,
        preset: &args.preset,
        dataset: &data.join("train"),
        steps: args.steps,
        seed: args.seed,
        test_mesh: &data.join("reference/mesh.ply"),
        samples: args.reference,
        reference: &data.join("reference"),
        picture: "means",
    };
    let rows = args
        .kinds
        .iter()
        .map(|kind| mfm.compare_kind(&comparison, kind))
        .collect::<Result<Vec<_>>>()?;
    let mut md = String::new();
    writeln!(
        md,
        "GMM at CPU scale: train on `{mesh}` (uniform), test on its half-refined remeshing; \
{} training signals, {} reference and {} generated samples, run preset `{}`, {} steps, seed {}.\n",
        args.n, args.reference, args.reference, args.preset, args.steps, args.seed
    )?;
    writeln!(
        md,
        "| noise | bump-fit residual median [q1, q3] | peak median | bumps > 1/2 | data-like | diversity | test error | MMD | COV | 1-NNA | train s | sample s |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    )?;
    let mut csv = String::from(
        "noise,residual_median,residual_q1,residual_q3,peak_median,bumps_above_half,within_twice_floor,diversity,test_error,mmd,cov,one_nna,train_seconds,sample_seconds\n",
    );
    let mut floor = None;
    for r in &rows {
        let (kind, tr, sa) = (&r.kind, r.train_seconds, r.sample_seconds);
        let EvalOutcome::Report(m) = &r.metrics else {
            // mfm's own message is in the log above and in table.json
            writeln!(
                md,
                "| {kind} | sampling failed (see the log) | | | | | | | | | {tr:.0} | {sa:.1} |"
            )?;
            writeln!(csv, "{kind},,,,,,,,,,,,{tr:.1},{sa:.2}")?;
            continue;
        };
        let section = Quality::section(m)?;
        let q = Quality::of(section);
        floor.get_or_insert_with(|| section.reference.clone());
        let metrics = &m.metrics;
        let [err, mmd, cov, nna] = [
            metrics.test_error,
            metrics.mmd,
            metrics.cov,
            metrics.one_nna,
        ];
        writeln!(
            md,
            "| {kind} | {} | {err:.4} | {mmd:.4} | {cov:.3} | {nna:.3} | {tr:.0} | {sa:.1} |",
            q.cells()
        )?;
        writeln!(
            csv,
            "{kind},{},{},{},{},{},{},{},{err},{mmd},{cov},{nna},{tr:.1},{sa:.2}",
            q.residual[1], q.residual[0], q.residual[2], q.peak[1], q.bumps, q.within, q.diversity
        )?;
    }
    if let Some(d) = floor {
        let residual = quartiles(d.residual);
        writeln!(
            md,
            "| reference set (the floor) | {:.3} [{:.3}, {:.3}] | {:.2} | {:.2} | | 1 | | | | | | |",
            residual[1], residual[0], residual[2], d.peak.median, d.bumps_above_half
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
        .map(|r| {
            serde_json::json!({
                "noise": r.kind, "metrics": r.metrics,
                "train_seconds": r.train_seconds, "sample_seconds": r.sample_seconds,
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

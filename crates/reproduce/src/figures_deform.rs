//! `cargo xtask reproduce-figures deform`: the paper's deformation
//! experiments at CPU scale (ablation table, robustness table, generation
//! across resolutions).
//!
//! 1. `mfm dataset deform` on a real mesh (the shared elephant when
//!    `../shared/meshes` is present, else the built-in capsule): ARAP poses
//!    from random handle motions on a decimated training mesh, a held-out
//!    reference set on a finer non-uniform triangulation.
//! 2. Ablation: for each noise kind (matern, matern without screening,
//!    white, naive, explicit-k) the same network (run preset `cpu-deform`)
//!    is trained for the same steps with the same seed, then samples on the
//!    evaluation mesh are scored: projection MSE (plausibility), MMD, COV,
//!    parameter count.
//! 3. Generalization: the first kind's samples on the training mesh against
//!    the training set (distance to the nearest training shape), next to the
//!    same for held-out shapes.
//! 4. Resolution transfer: the first kind's model samples the same seeds on
//!    the coarse mesh, its 4x and 16x midpoint refinements, the original
//!    mesh and the original refined 16x; time per sample and projection MSE
//!    per resolution, and one picture of sample 0 on every resolution.
//! 5. Robustness: the first kind's model on damaged evaluation meshes
//!    (holes, a partial cut, edge flips): projection MSE and renders.
//!
//! Drives the release `mfm` binary (the xtask does not link libtorch).
//! Writes `table.md`, `table.json`, and the folders and PNGs of every step.

use crate::flow_steps::{Comparison, KindResult, arg, fresh_dir, mesh_or_shared, tag};
use crate::mfm::Mfm;
use crate::reports::{EvalOutcome, EvalReport, PlausibilityReport, SampleTiming};
use crate::workspace::in_root;
use anyhow::{Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `reproduce-figures deform`.
#[derive(clap::Args)]
pub struct DeformArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/deform")]
    pub out: PathBuf,
    /// Mesh to deform (default: ../shared/meshes/elephant.obj when present,
    /// else builtin:capsule).
    #[arg(long)]
    pub mesh: Option<String>,
    /// Noise kinds of the ablation, comma-separated (mfm train --noise
    /// forms); the first one also runs the generalization, resolution and
    /// robustness experiments.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "matern:100,matern:0,white,naive,explicit:64:100"
    )]
    pub kinds: Vec<String>,
    /// Run preset of every kind's training (`mfm train --preset`).
    #[arg(long, default_value = "cpu-deform")]
    pub preset: String,
    /// Training steps per kind (the preset's otherwise).
    #[arg(long, default_value_t = 1000)]
    pub steps: u64,
    /// Training shapes.
    #[arg(long, default_value_t = 400)]
    pub n: usize,
    /// Held-out reference shapes, and generated samples per kind.
    #[arg(long, default_value_t = 64)]
    pub reference: usize,
    /// Faces of the coarse training mesh.
    #[arg(long, default_value_t = 3000)]
    pub coarse_faces: usize,
    /// Samples per resolution and per damaged mesh.
    #[arg(long, default_value_t = 4)]
    pub per_mesh: usize,
    /// Skip the resolution-transfer and robustness experiments.
    #[arg(long)]
    pub ablation_only: bool,
    /// Seed of the dataset, the runs and the samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Number of parameters in a safetensors file (from its header).
fn parameter_count(path: &Path) -> Result<u64> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (_, metadata) = safetensors::SafeTensors::read_metadata(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a safetensors file: {e:?}", path.display()))?;
    Ok(metadata
        .tensors()
        .values()
        .map(|t| t.shape.iter().product::<usize>() as u64)
        .sum())
}

/// One row of the ablation table.
struct AblationRow {
    result: KindResult,
    params: u64,
}

/// Runs the experiment.
///
/// # Errors
/// When a step fails (a kind whose sampling fails is a row of the table).
pub fn deform(mfm: &Mfm, args: &DeformArgs) -> Result<()> {
    anyhow::ensure!(!args.kinds.is_empty(), "--kinds is empty");
    let out = in_root(&args.out);
    let mesh = mesh_or_shared(args.mesh.as_deref(), "elephant.obj", "builtin:capsule");
    mfm.exe()?;
    let start = Instant::now();
    fresh_dir(&out)?;
    let data = out.join("data");
    mfm.run(&[
        "dataset",
        "deform",
        "--mesh",
        &mesh,
        "--out",
        &arg(&data),
        "--n",
        &args.n.to_string(),
        "--reference",
        &args.reference.to_string(),
        "--coarse-faces",
        &args.coarse_faces.to_string(),
        "--seed",
        &args.seed.to_string(),
    ])?;
    let dataset_seconds = start.elapsed().as_secs_f64();
    let space = data.join("space.json");

    // 2. ablation
    let comparison = Comparison {
        out: &out,
        preset: &args.preset,
        dataset: &data.join("train"),
        steps: args.steps,
        seed: args.seed,
        test_mesh: &data.join("eval.ply"),
        samples: args.reference,
        reference: &data.join("reference"),
        picture: "shapes",
    };
    let mut rows = Vec::new();
    for kind in &args.kinds {
        let result = mfm.compare_kind(&comparison, kind)?;
        let params = parameter_count(&result.run.join("model.safetensors"))?;
        rows.push(AblationRow { result, params });
    }
    let main_run = out.join(format!("run_{}", tag(&args.kinds[0])));

    // 3. generalization: nearest training shapes
    let coarse_samples = out.join("samples_coarse");
    let train_dir = arg(&data.join("train"));
    mfm.sample(
        &main_run,
        &data.join("coarse.ply"),
        args.reference,
        args.seed,
        &coarse_samples,
        &[],
    )?;
    let nearest = |samples: &Path, name: &str| -> Result<f64> {
        let m: EvalReport =
            mfm.eval(samples, &["--reference", &train_dir], &out.join(name), None)?;
        Ok(m.metrics.mmd)
    };
    let generalization = (
        nearest(
            &coarse_samples.join("samples.npy"),
            "nearest_train_generated.json",
        )?,
        nearest(
            &data.join("holdout/signals.npy"),
            "nearest_train_heldout.json",
        )?,
    );

    let mut md = String::new();
    writeln!(
        md,
        "Deformations at CPU scale: `mfm dataset deform` on `{mesh}` ({} training shapes on the \
{}-face decimation, {} held-out shapes on its half-refined remeshing); run preset `{}`, \
{} steps, seed {}.\n",
        args.n, args.coarse_faces, args.reference, args.preset, args.steps, args.seed
    )?;
    writeln!(
        md,
        "| noise | projection MSE x 1e4 median [q1, q3] (mean) | rotation spread / data's | translation spread / data's | MMD | COV | 1-NNA | # params | train s | sample s |\n|---|---|---|---|---|---|---|---|---|---|"
    )?;
    let mut floor = None;
    for AblationRow { result: r, params } in &rows {
        let EvalOutcome::Report(m) = &r.metrics else {
            // mfm's own message is in the log above and in table.json
            writeln!(
                md,
                "| {} | sampling failed (see the log) | | | | | | {} | {:.0} | {:.1} |",
                r.kind, params, r.train_seconds, r.sample_seconds
            )?;
            continue;
        };
        let shapes = shape_report(m, &r.kind)?;
        let (q, ratio) = (shapes.projection_mse_quartiles, shapes.spread_ratio);
        floor.get_or_insert(shapes.reference_projection_mse);
        writeln!(
            md,
            "| {} | {:.2} [{:.2}, {:.2}] ({:.2}) | {:.2} | {:.2} | {:.4} | {:.3} | {:.3} | {} | {:.0} | {:.1} |",
            r.kind,
            q.median * 1e4,
            q.q1 * 1e4,
            q.q3 * 1e4,
            shapes.projection_mse * 1e4,
            ratio.rotation,
            ratio.translation,
            m.metrics.mmd,
            m.metrics.cov,
            m.metrics.one_nna,
            params,
            r.train_seconds,
            r.sample_seconds
        )?;
    }
    if let Some(floor) = floor {
        writeln!(
            md,
            "\nHeld-out reference shapes themselves project with MSE x 1e4 = {:.4} (the floor of the metric).",
            floor * 1e4
        )?;
    }
    writeln!(
        md,
        "\nGeneralization ({}): mean distance from a generated shape to its nearest training shape {:.4}; \
from a held-out shape to its nearest training shape {:.4} (both on the training mesh).",
        args.kinds[0], generalization.0, generalization.1
    )?;

    let mut json = serde_json::json!({
        "mesh": mesh, "steps": args.steps, "n": args.n, "reference": args.reference,
        "coarse_faces": args.coarse_faces, "seed": args.seed,
        "dataset_seconds": dataset_seconds,
        "ablation": rows.iter().map(|AblationRow { result: r, params }| serde_json::json!({
            "noise": r.kind, "metrics": r.metrics, "parameters": params,
            "train_seconds": r.train_seconds, "sample_seconds": r.sample_seconds,
        })).collect::<Vec<_>>(),
        "nearest_training_distance": {
            "generated": generalization.0, "held_out": generalization.1,
        },
    });

    if !args.ablation_only {
        let (res_md, res_json) = resolutions(mfm, args, &data, &space, &main_run, &out)?;
        md.push_str(&res_md);
        json["resolutions"] = res_json;
        let (rob_md, rob_json) = robustness(mfm, args, &data, &space, &main_run, &out)?;
        md.push_str(&rob_md);
        json["robustness"] = rob_json;
    }
    writeln!(
        md,
        "\nDataset generation {dataset_seconds:.1} s; total {:.1} s.",
        start.elapsed().as_secs_f64()
    )?;
    std::fs::write(out.join("table.md"), &md)?;
    std::fs::write(out.join("table.json"), serde_json::to_string_pretty(&json)?)?;
    print!("{md}");
    println!("reproduce-figures deform: wrote {}", out.display());
    Ok(())
}

/// Samples `args.per_mesh` shapes of `run` on `mesh` into `dir` and scores
/// them with the projection metric; returns (seconds per sample, projection
/// MSE, vertices).
fn sample_and_project(
    mfm: &Mfm,
    args: &DeformArgs,
    run: &Path,
    mesh: &Path,
    space: &Path,
    dir: &Path,
) -> Result<(f64, f64, u64)> {
    mfm.sample(run, mesh, args.per_mesh, args.seed, dir, &["--ply", "1"])?;
    let m: PlausibilityReport = mfm.eval(
        &dir.join("samples.npy"),
        &["--space", &arg(space), "--mesh", &arg(mesh)],
        &dir.join("projection.json"),
        Some(&dir.join("projections.png")),
    )?;
    let timing = SampleTiming::of(dir)?;
    Ok((
        timing.seconds_per_sample,
        m.projection_mse,
        timing.vertices as u64,
    ))
}

/// The projection part of a kind's evaluation.
fn shape_report<'a>(
    m: &'a EvalReport,
    kind: &str,
) -> Result<&'a mfm_eval::evaluation::ShapeReport> {
    m.shapes.as_ref().with_context(|| {
        format!(
            "{kind}: the evaluation has no projection (mfm eval on a deformation set writes one)"
        )
    })
}

/// Generation on the coarse mesh, its 4x and 16x refinements, the original
/// and the original refined 16x.
fn resolutions(
    mfm: &Mfm,
    args: &DeformArgs,
    data: &Path,
    space: &Path,
    run: &Path,
    out: &Path,
) -> Result<(String, Value)> {
    let dir = out.join("resolutions");
    std::fs::create_dir_all(&dir)?;
    let mut meshes: Vec<(String, PathBuf)> = vec![("coarse".into(), data.join("coarse.ply"))];
    for (name, base, rounds) in [
        ("coarse x4", "coarse.ply", 1),
        ("coarse x16", "coarse.ply", 2),
        ("original", "original.ply", 0),
        ("original x16", "original.ply", 2),
    ] {
        let path = if rounds == 0 {
            data.join(base)
        } else {
            let p = dir.join(format!("{}.ply", name.replace(' ', "_")));
            mfm.run(&[
                "remesh",
                &arg(&data.join(base)),
                "--subdivide",
                &rounds.to_string(),
                "--out",
                &arg(&p),
            ])?;
            p
        };
        meshes.push((name.into(), path));
    }
    let mut md = String::from(
        "\nGeneration across resolutions (same seed; the model was trained on `coarse`):\n\n\
| mesh | vertices | seconds per sample | projection MSE x 1e4 |\n|---|---|---|---|\n",
    );
    let mut rows = Vec::new();
    let mut firsts = Vec::new();
    for (name, mesh) in &meshes {
        let sub = dir.join(name.replace(' ', "_"));
        let (sec, mse, v) = match sample_and_project(mfm, args, run, mesh, space, &sub) {
            Ok(r) => r,
            Err(e) => {
                writeln!(md, "| {name} | | failed: {} | |", first_line(&e))?;
                rows.push(serde_json::json!({"mesh": name, "error": format!("{e:#}")}));
                continue;
            }
        };
        writeln!(md, "| {name} | {v} | {sec:.2} | {:.3} |", mse * 1e4)?;
        rows.push(serde_json::json!({
            "mesh": name, "vertices": v, "seconds_per_sample": sec, "projection_mse": mse,
        }));
        firsts.push((name.clone(), sub.join("sample_000.ply")));
    }
    let sheet = dir.join("same_seed.png");
    side_by_side(&firsts, &sheet)?;
    writeln!(md, "\nSample 0 on every resolution: `{}`.", arg(&sheet))?;
    Ok((md, Value::Array(rows)))
}

/// The main model on damaged evaluation meshes.
fn robustness(
    mfm: &Mfm,
    args: &DeformArgs,
    data: &Path,
    space: &Path,
    run: &Path,
    out: &Path,
) -> Result<(String, Value)> {
    let dir = out.join("robustness");
    std::fs::create_dir_all(&dir)?;
    let mut md = String::from(
        "\nRobustness (the first kind's model on damaged versions of the evaluation mesh):\n\n\
| source mesh | vertices | projection MSE x 1e4 |\n|---|---|---|\n",
    );
    let mut rows = Vec::new();
    let mut firsts = Vec::new();
    let clean = dir.join("clean");
    let (_, mse, v) = sample_and_project(mfm, args, run, &data.join("eval.ply"), space, &clean)?;
    writeln!(md, "| clean | {v} | {:.3} |", mse * 1e4)?;
    rows.push(serde_json::json!({"damage": "none", "vertices": v, "projection_mse": mse}));
    firsts.push(("clean".to_owned(), clean.join("sample_000.ply")));
    for damage in [
        "small-holes",
        "medium-holes",
        "large-holes",
        "partial",
        "mild-flips",
        "severe-flips",
    ] {
        let mesh = dir.join(format!("{damage}.ply"));
        mfm.run(&[
            "remesh",
            &arg(&data.join("eval.ply")),
            "--damage",
            damage,
            "--space",
            &arg(space),
            "--seed",
            &args.seed.to_string(),
            "--out",
            &arg(&mesh),
        ])?;
        let sub = dir.join(damage);
        let (_, mse, v) = match sample_and_project(mfm, args, run, &mesh, space, &sub) {
            Ok(r) => r,
            Err(e) => {
                writeln!(md, "| {damage} | | failed: {} |", first_line(&e))?;
                rows.push(serde_json::json!({"damage": damage, "error": format!("{e:#}")}));
                continue;
            }
        };
        writeln!(md, "| {damage} | {v} | {:.3} |", mse * 1e4)?;
        rows.push(serde_json::json!({"damage": damage, "vertices": v, "projection_mse": mse}));
        firsts.push((damage.to_owned(), sub.join("sample_000.ply")));
    }
    let sheet = dir.join("same_seed.png");
    side_by_side(&firsts, &sheet)?;
    writeln!(md, "\nSample 0 on every source mesh: `{}`.", arg(&sheet))?;
    Ok((md, Value::Array(rows)))
}

fn first_line(e: &anyhow::Error) -> String {
    format!("{e:#}")
        .lines()
        .next()
        .unwrap_or_default()
        .to_owned()
}

/// Renders the meshes side by side (shaded, one camera for all).
fn side_by_side(meshes: &[(String, PathBuf)], path: &Path) -> Result<()> {
    use mfm_render::{GridOptions, Panel, render_grid, save_png};
    let loaded: Vec<(String, mfm_geometry::TriMesh)> = meshes
        .iter()
        .map(|(name, p)| Ok((name.clone(), mfm_meshio::read_mesh(p)?)))
        .collect::<Result<_>>()?;
    let panels: Vec<Panel<'_>> = loaded
        .iter()
        .map(|(name, m)| Panel::new(m, None, format!("{name} ({} V)", m.num_vertices())))
        .collect();
    let opts = GridOptions {
        title: Some("the same sample seed on every mesh".into()),
        ..GridOptions::default()
    };
    let img = render_grid(&panels, panels.len().min(4), &opts)?;
    save_png(&img, path)?;
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use safetensors::tensor::{Dtype, TensorView};

    #[test]
    fn parameters_are_counted_from_the_header() {
        let (a, b) = (vec![0u8; 4 * 6], vec![0u8; 8 * 5]);
        let tensors = [
            (
                "a.weight",
                TensorView::new(Dtype::F32, vec![2, 3], &a).unwrap(),
            ),
            ("b", TensorView::new(Dtype::F64, vec![5], &b).unwrap()),
        ];
        let metadata = Some(std::collections::HashMap::from([(
            "format".to_owned(),
            "pt".to_owned(),
        )]));
        let bytes = safetensors::serialize(tensors, &metadata).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.safetensors");
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(parameter_count(&path).unwrap(), 11);
        std::fs::write(&path, &bytes[..12]).unwrap();
        let e = parameter_count(&path).unwrap_err().to_string();
        assert!(e.contains("model.safetensors"), "{e}");
    }
}

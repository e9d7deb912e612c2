//! `cargo xtask reproduce-figures arbitrary`: the paper's arbitrary-source
//! model (section 5.1) at CPU scale.
//!
//! 1. `mfm dataset pairs` on a humanoid (the shared alien when
//!    `../shared/meshes` is present, else the built-in capsule): body shapes
//!    of the decimated template in ARAP poses; held-out shapes on the
//!    template's triangulation and on a finer non-uniform one.
//! 2. `mfm train --mode predictor` (the eigenvector predictor), then
//!    `mfm train --mode arbitrary` (the flow conditioned on it).
//! 3. `mfm eval-arbitrary` on both held-out sets: projection onto each
//!    source's own deformation space against the data's floor,
//!    displacement ratio, pose spread, MMD/COV, predictor error; pictures.
//! 4. With `--other MESH` (default: the shared decimated knight when
//!    present), `mfm sample --source` on a mesh of another object.
//!
//! Drives the release `mfm` binary. Writes `table.md`, `table.json` and
//! the folders and PNGs of every step.

use crate::flow_steps::{arg, fresh_dir, mesh_or_shared};
use crate::mfm::Mfm;
use crate::reports::{self, SetEvaluation};
use crate::workspace::{self, in_root};
use anyhow::Result;
use serde_json::json;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `reproduce-figures arbitrary`.
#[derive(clap::Args)]
pub struct ArbitraryArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/arbitrary")]
    pub out: PathBuf,
    /// Template mesh (default: ../shared/meshes/alien.obj when present,
    /// else builtin:capsule).
    #[arg(long)]
    pub mesh: Option<String>,
    /// A mesh of another object to generate over (default:
    /// ../shared/meshes/decimated-knight.off when present; `none` skips).
    #[arg(long)]
    pub other: Option<String>,
    /// Training body shapes.
    #[arg(long, default_value_t = 40)]
    pub shapes: usize,
    /// Poses per shape.
    #[arg(long, default_value_t = 4)]
    pub poses: usize,
    /// Held-out shapes.
    #[arg(long, default_value_t = 8)]
    pub reference: usize,
    /// Faces of the coarse template.
    #[arg(long, default_value_t = 3000)]
    pub coarse_faces: usize,
    /// Preset of both trainings (`cpu` or `paper`).
    #[arg(long, default_value = "cpu")]
    pub preset: String,
    /// Predictor steps (the preset's otherwise).
    #[arg(long)]
    pub predictor_steps: Option<u64>,
    /// Flow steps (the preset's otherwise).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Targets generated per held-out source.
    #[arg(long, default_value_t = 4)]
    pub per_source: usize,
    /// Seed of the dataset, the runs and the samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Runs the experiment.
///
/// # Errors
/// When a step fails.
pub fn arbitrary(mfm: &Mfm, args: &ArbitraryArgs) -> Result<()> {
    let out = in_root(&args.out);
    let mesh = mesh_or_shared(args.mesh.as_deref(), "alien.obj", "builtin:capsule");
    let other = match args.other.as_deref() {
        Some("none") => None,
        Some(m) => Some(m.to_owned()),
        None => {
            let knight = workspace::root().join("../shared/meshes/decimated-knight.off");
            knight.is_file().then(|| arg(&knight))
        }
    };
    mfm.exe()?;
    fresh_dir(&out)?;
    let (data, predictor, flow, eval) = (
        out.join("data"),
        out.join("predictor"),
        out.join("flow"),
        out.join("eval"),
    );
    let seed = args.seed.to_string();
    let mut seconds = Vec::new();
    let timed =
        |what: &str, f: &mut dyn FnMut() -> Result<()>, seconds: &mut Vec<(String, f64)>| {
            let t = Instant::now();
            let r = f();
            seconds.push((what.to_owned(), t.elapsed().as_secs_f64()));
            r
        };
    timed(
        "dataset",
        &mut || {
            mfm.run(&[
                "dataset",
                "pairs",
                "--mesh",
                &mesh,
                "--out",
                &arg(&data),
                "--shapes",
                &args.shapes.to_string(),
                "--poses",
                &args.poses.to_string(),
                "--reference",
                &args.reference.to_string(),
                "--coarse-faces",
                &args.coarse_faces.to_string(),
                "--seed",
                &seed,
            ])
        },
        &mut seconds,
    )?;
    let train = arg(&data.join("train"));
    let steps = |s: Option<u64>| s.map(|s| vec!["--steps".to_owned(), s.to_string()]);
    timed(
        "predictor",
        &mut || {
            let mut a: Vec<String> = [
                "train",
                "--mode",
                "predictor",
                "--preset",
                &args.preset,
                "--dataset",
                &train,
                "--out",
                &arg(&predictor),
                "--seed",
                &seed,
                "--quiet",
            ]
            .map(str::to_owned)
            .to_vec();
            a.extend(steps(args.predictor_steps).unwrap_or_default());
            mfm.run(&a)
        },
        &mut seconds,
    )?;
    timed(
        "flow",
        &mut || {
            let mut a: Vec<String> = [
                "train",
                "--mode",
                "arbitrary",
                "--preset",
                &args.preset,
                "--dataset",
                &train,
                "--predictor",
                &arg(&predictor),
                "--out",
                &arg(&flow),
                "--seed",
                &seed,
                "--quiet",
            ]
            .map(str::to_owned)
            .to_vec();
            a.extend(steps(args.steps).unwrap_or_default());
            mfm.run(&a)
        },
        &mut seconds,
    )?;
    timed(
        "evaluation",
        &mut || {
            mfm.run(&[
                "eval-arbitrary",
                "--run",
                &arg(&flow),
                "--experiment",
                &arg(&data),
                "--sources",
                &args.reference.to_string(),
                "--per-source",
                &args.per_source.to_string(),
                "--seed",
                &seed,
                "--out",
                &arg(&eval),
            ])
        },
        &mut seconds,
    )?;
    if let Some(o) = &other {
        timed(
            "other object",
            &mut || {
                mfm.run(&[
                    "sample",
                    "--run",
                    &arg(&flow),
                    "--source",
                    o,
                    "--n",
                    &args.per_source.to_string(),
                    "--seed",
                    &seed,
                    "--out",
                    &arg(&out.join("other")),
                ])
            },
            &mut seconds,
        )?;
    }
    let sets: Vec<SetEvaluation> = reports::read(&eval.join("report.json"))?;
    let mut md = String::new();
    writeln!(
        md,
        "Arbitrary-source model at CPU scale: `mfm dataset pairs` on `{mesh}` ({} body shapes x {} \
poses of the {}-face decimation, {} held-out shapes); preset `{}`, seed {}.\n",
        args.shapes, args.poses, args.coarse_faces, args.reference, args.preset, args.seed
    )?;
    writeln!(
        md,
        "| held-out set | vertices | projection MSE median [q1, q3] | data floor | displacement ratio | \
pose spread rot / trans (x data) | MMD | COV | predictor error (vectors 1-8) |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    for s in &sets {
        let predictor = |q: Option<mfm_eval::quality::Quartiles>| {
            q.map_or_else(|| "not measured".to_owned(), |q| format!("{:.3}", q.median))
        };
        writeln!(
            md,
            "| {} | {} | {:.2e} [{:.2e}, {:.2e}] | {:.1e} | {:.2} | {:.2} / {:.2} | {:.4} | {:.2} | {} ({}) |",
            s.set,
            s.vertices,
            s.projection.median,
            s.projection.q1,
            s.projection.q3,
            s.projection_floor.median,
            s.displacement_ratio,
            s.pose_spread.rotation / s.reference_pose_spread.rotation,
            s.pose_spread.translation / s.reference_pose_spread.translation,
            s.mmd,
            s.cov,
            predictor(s.predictor_error),
            predictor(s.predictor_error_low),
        )?;
    }
    writeln!(md)?;
    let times: Vec<String> = seconds
        .iter()
        .map(|(w, s)| format!("{w} {s:.0} s"))
        .collect();
    writeln!(md, "Wall times: {}.", times.join(", "))?;
    writeln!(
        md,
        "\nPictures: `eval/holdout.png`, `eval/reference.png` (sources, generated targets, a data pose){}.",
        if other.is_some() {
            ", `other/samples.png` and `other/eigenvectors.png` (the other object)"
        } else {
            ""
        }
    )?;
    std::fs::write(out.join("table.md"), &md)?;
    let json = json!({
        "mesh": mesh,
        "sets": sets,
        "seconds": seconds.iter().map(|(w, s)| json!({"stage": w, "seconds": s})).collect::<Vec<_>>(),
    });
    std::fs::write(out.join("table.json"), serde_json::to_string_pretty(&json)?)?;
    print!("{md}");
    Ok(())
}

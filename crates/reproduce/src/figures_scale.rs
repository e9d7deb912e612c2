//! `cargo xtask reproduce-figures scale`: a shape model sampled far beyond
//! its training resolution, timed and pictured (issue 41).
//!
//! The shipped shape model (`fixtures/pretrained/elephant/`, or `--run`
//! with its training mesh `--mesh`) samples `--samples` shapes on its
//! training mesh and on `--levels` rounds of midpoint subdivision of it (4x
//! the faces each: the elephant's 3000 faces become 3.07M at level 5),
//! every level from the same noise (drawn on the training mesh and carried,
//! `mfm sample --noise-from`), so the pictures show the same shapes at
//! every resolution. Per level: vertices, faces, seconds per sample (from
//! `timing.json`: operators, factorizations, noise, ODE and writing) and the
//! sampling process's peak resident memory (`wait4`). Writes `report.md`
//! and `report.json` under `--out`, with each level's `samples.png`.
//! Measure on an otherwise idle machine: libtorch's workers slow down
//! several times beside another busy process.

use crate::flow_steps::{arg, fresh_dir};
use crate::mfm::Mfm;
use crate::reports::SampleTiming;
use crate::workspace::{self, in_root};
use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `reproduce-figures scale`.
#[derive(clap::Args)]
pub struct ScaleArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/scale")]
    pub out: PathBuf,
    /// A shape run to sample (default: the shipped elephant model, whose
    /// training mesh is made from ../shared/meshes/elephant.obj).
    #[arg(long, requires = "mesh")]
    pub run: Option<PathBuf>,
    /// The run's training mesh (with --run).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Rounds of midpoint subdivision beyond the training mesh.
    #[arg(long, default_value_t = 5)]
    pub levels: u32,
    /// Samples per level (all in one `mfm sample` call).
    #[arg(long, default_value_t = 2)]
    pub samples: usize,
}

/// One level's measurements.
#[derive(serde::Serialize)]
struct Level {
    level: u32,
    vertices: u64,
    faces: u64,
    seconds_per_sample: f64,
    peak_bytes: u64,
}

/// Runs the command (see the [module docs](self)).
///
/// # Errors
/// When the model or its mesh is not there, or a step fails.
pub fn scale(mfm: &Mfm, args: &ScaleArgs) -> Result<()> {
    let out = in_root(&args.out);
    fresh_dir(&out)?;
    mfm.exe()?;
    let (run, coarse) = match (&args.run, &args.mesh) {
        (Some(run), Some(mesh)) => (in_root(run), in_root(mesh)),
        _ => {
            let run = crate::pretrain::shipped_at(crate::pretrain::ELEPHANT_DIR, "elephant")?;
            let mesh = workspace::root().join(crate::pretrain::ELEPHANT_MESH);
            if !mesh.is_file() {
                bail!(
                    "{} not found: the shipped shape model's training mesh is made from the \
                     shared meshes (or pass --run RUN --mesh ITS_TRAINING_MESH)",
                    mesh.display()
                );
            }
            let data = out.join("data");
            mfm.run(&[
                "dataset",
                "deform",
                "--mesh",
                &arg(&mesh),
                "--n",
                "2",
                "--reference",
                "1",
                "--out",
                &arg(&data),
            ])?;
            (run, data.join("coarse.ply"))
        }
    };
    let coarse_faces = mfm_meshio::read_mesh(&coarse)
        .with_context(|| format!("reading {}", coarse.display()))?
        .num_faces() as u64;
    let mut levels = Vec::new();
    for level in 0..=args.levels {
        let mesh = if level == 0 {
            coarse.clone()
        } else {
            let fine = out.join(format!("mesh_{level}.ply"));
            mfm.run(&[
                "remesh",
                &arg(&coarse),
                "--subdivide",
                &level.to_string(),
                "--out",
                &arg(&fine),
            ])?;
            fine
        };
        let samples = out.join(format!("samples_{level}"));
        let peak_bytes = mfm.run_with_peak_memory(&[
            "sample",
            "--run",
            &arg(&run),
            "--mesh",
            &arg(&mesh),
            "--noise-from",
            &arg(&coarse),
            "--n",
            &args.samples.to_string(),
            "--ply",
            "0",
            "--out",
            &arg(&samples),
        ])?;
        let timing = SampleTiming::of(&samples)?;
        let (vertices, seconds_per_sample) = (timing.vertices as u64, timing.seconds_per_sample);
        // midpoint subdivision multiplies the faces by 4 per round
        let faces = coarse_faces << (2 * level);
        println!(
            "level {level}: {vertices} vertices, {faces} faces: {seconds_per_sample:.2} s a sample, peak {:.2} GB",
            peak_bytes as f64 / 1e9
        );
        levels.push(Level {
            level,
            vertices,
            faces,
            seconds_per_sample,
            peak_bytes,
        });
    }
    let mut md = String::new();
    writeln!(md, "# A shape model far beyond its training resolution\n")?;
    writeln!(
        md,
        "`{}` sampled on its training mesh (`{}`) and on {} rounds of midpoint \
subdivision of it, {} samples per level from the same noise (drawn on the training \
mesh and carried: `mfm sample --noise-from`). Seconds per sample from `timing.json` \
(everything but loading), peak memory of the sampling process. Made by `cargo xtask \
reproduce-figures scale`; measure on an idle machine.\n",
        run.display(),
        coarse.display(),
        args.levels,
        args.samples
    )?;
    writeln!(
        md,
        "| level | vertices | faces | seconds per sample | peak memory |\n|---|---|---|---|---|"
    )?;
    for l in &levels {
        writeln!(
            md,
            "| {} | {} | {} | {:.2} | {:.2} GB |",
            l.level,
            l.vertices,
            l.faces,
            l.seconds_per_sample,
            l.peak_bytes as f64 / 1e9
        )?;
    }
    writeln!(md)?;
    for l in &levels {
        writeln!(
            md,
            "Level {} ({} faces):\n\n![level {}](samples_{}/samples.png)\n",
            l.level, l.faces, l.level, l.level
        )?;
    }
    std::fs::write(out.join("report.md"), md)?;
    std::fs::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&levels)?,
    )?;
    println!("report: {}", out.join("report.md").display());
    Ok(())
}

//! `mfm eval`: distribution metrics, sample-quality fits and pictures of
//! generated samples against a reference dataset or a deformation space
//! ([`mfm_eval::evaluation`]).

use crate::mesh::{load_mesh_checked, mesh_path};
use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_eval::evaluation::{EvalFiles, PlausibilityFiles};
use std::path::PathBuf;

/// Arguments of `mfm eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// Generated samples (.npy [N, V, C], e.g. from `mfm sample`).
    #[arg(long)]
    samples: PathBuf,
    /// Reference dataset folder (its mesh is the mesh the samples live on),
    /// or an experiment folder (its reference/ set). For shapes imported
    /// with `mfm dataset import`, adds the measures that need no generator:
    /// plausibility, coverage, novelty, roughness and flipped faces against
    /// the training and held-out shapes.
    #[arg(long, required_unless_present = "space")]
    reference: Option<PathBuf>,
    /// Without a reference set: the space.json of `mfm dataset deform`; only
    /// the projection (plausibility) error is computed, on --mesh.
    #[arg(long, requires = "mesh", conflicts_with = "reference")]
    space: Option<PathBuf>,
    /// The mesh the samples live on (with --space).
    #[arg(long)]
    mesh: Option<crate::mesh::MeshSpec>,
    /// Write the metrics as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Render the point-wise means (generated vs reference) to this PNG; for
    /// a deformation reference set (`mfm dataset deform`), the first
    /// generated shapes beside their projections onto the deformation space;
    /// for imported shapes, the first samples beside their nearest real
    /// shapes.
    #[arg(long)]
    png: Option<PathBuf>,
}

/// Runs `mfm eval`.
pub fn eval(a: EvalArgs) -> Result<()> {
    if let Some(reference) = &a.reference {
        let e = EvalFiles {
            samples: &a.samples,
            reference,
            json: a.out.as_deref(),
            png: a.png.as_deref(),
        }
        .run()
        .with_context(|| format!("evaluating against {}", reference.display()))?;
        println!("{}", e.report.summary());
        return Ok(());
    }
    let (Some(space), Some(mesh_spec)) = (&a.space, &a.mesh) else {
        bail!("give --reference DIR, or --space space.json with --mesh MESH");
    };
    let mesh = load_mesh_checked(mesh_spec)?;
    let r = PlausibilityFiles {
        samples: &a.samples,
        space,
        mesh: &mesh,
        mesh_file: mesh_path(mesh_spec),
        json: a.out.as_deref(),
        png: a.png.as_deref(),
    }
    .run()?;
    println!(
        "projection MSE (plausibility): mean {:.3e} median {:.3e} ({} samples on {} vertices)",
        r.projection_mse, r.projection_mse_median, r.num_generated, r.vertices
    );
    Ok(())
}

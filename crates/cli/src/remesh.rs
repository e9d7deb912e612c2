//! `mfm remesh`: other triangulations of a mesh's surface, for sampling a
//! trained model across resolutions and on damaged inputs.

use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_data::deformations::{Damage, damaged_mesh};
use mfm_geometry::subdivide;
use std::path::PathBuf;

use crate::mesh_arg::{load_mesh_checked, mesh_path};

/// Arguments of `mfm remesh`.
#[derive(Args)]
pub struct RemeshArgs {
    /// Mesh file or builtin:NAME.
    mesh: String,
    /// Output mesh (.ply or .obj).
    #[arg(long)]
    out: PathBuf,
    /// Rounds of midpoint subdivision (each multiplies the faces by 4 and
    /// keeps the surface).
    #[arg(long, default_value_t = 0)]
    subdivide: u32,
    /// Damage the mesh: small-holes, medium-holes, large-holes, partial,
    /// mild-flips, severe-flips (needs --space).
    #[arg(long, requires = "space")]
    damage: Option<String>,
    /// space.json of `mfm dataset deform`: damage keeps its handle regions
    /// intact.
    #[arg(long)]
    space: Option<PathBuf>,
    /// Seed of the random hole centres and flips.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Runs `mfm remesh`.
pub fn run(a: RemeshArgs) -> Result<()> {
    if a.subdivide > 6 {
        bail!(
            "--subdivide {}: at most 6 rounds (4096x the faces)",
            a.subdivide
        );
    }
    let undo = crate::output::prepare_outputs(
        &[mesh_path(&a.mesh), a.space.as_deref()],
        std::slice::from_ref(&a.out),
    )?;
    let mut mesh = load_mesh_checked(&a.mesh)?;
    let input = (mesh.num_vertices(), mesh.num_faces());
    for _ in 0..a.subdivide {
        mesh = subdivide::midpoint(&mesh)?;
    }
    if let Some(name) = &a.damage {
        let damage: Damage = name.parse()?;
        let path = a.space.as_ref().context("--damage needs --space")?;
        let space = mfm_data::layout::read_space(path)?;
        mesh = damaged_mesh(&mesh, &space, damage, a.seed)?;
    }
    mfm_meshio::write_mesh(&a.out, &mesh)?;
    undo.keep();
    println!(
        "{}: {} vertices, {} faces (from {} vertices, {} faces)",
        a.out.display(),
        mesh.num_vertices(),
        mesh.num_faces(),
        input.0,
        input.1
    );
    Ok(())
}

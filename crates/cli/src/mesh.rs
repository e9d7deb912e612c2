//! The MESH argument ([`mfm_meshio::spec`]: a file or `builtin:NAME[:N]`)
//! and the commands on one mesh: `info`, `operators`, `convert`, `render`,
//! `remesh`.

use crate::output::prepare_outputs;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use mfm_data::deformations::{Damage, damaged_mesh};
use mfm_geometry::{MeshReport, TriMesh, operators, subdivide};
pub use mfm_meshio::spec::MeshSpec;
use std::path::{Path, PathBuf};

/// The file a mesh argument names, `None` for a built-in mesh.
pub fn mesh_path(spec: &MeshSpec) -> Option<&Path> {
    spec.path()
}

/// Loads a mesh as it is (`info`, `convert`, `render`, `net bench`).
pub fn load_mesh(spec: &MeshSpec) -> Result<TriMesh> {
    Ok(spec.load()?)
}

/// Loads a mesh to compute on: duplicate faces are an error, the other
/// problems `mfm info` reports are warnings on standard error.
pub fn load_mesh_checked(spec: &MeshSpec) -> Result<TriMesh> {
    let checked = spec.load_checked()?;
    for p in &checked.warnings {
        eprintln!("warning: {spec}: {p} (`mfm info {spec}` shows the full report)");
    }
    Ok(checked.mesh)
}

/// Arguments of `mfm info`.
#[derive(Args)]
pub struct InfoArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

impl InfoArgs {
    /// Prints the [`MeshReport`].
    pub fn run(self) -> Result<()> {
        let report = MeshReport::new(&load_mesh(&self.mesh)?);
        if self.json {
            println!("{}", serde_json::to_string_pretty(&report)?);
        } else {
            print!("{report}");
        }
        Ok(())
    }
}

/// Arguments of `mfm operators`.
#[derive(Args)]
pub struct OperatorsArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Output folder (created if missing).
    #[arg(long)]
    out: PathBuf,
}

impl OperatorsArgs {
    /// Writes the folder ([`mfm_meshio::export::write_operator_folder`]).
    pub fn run(self) -> Result<()> {
        let mesh = load_mesh_checked(&self.mesh)?;
        let s =
            mfm_meshio::export::write_operator_folder(&self.mesh.to_string(), &mesh, &self.out)?;
        println!(
            "wrote L.mtx ({} nnz), G.mtx ({} nnz), mass.npy, face_areas.npy, summary.json to {}; Gamma = {:.6e}",
            s.laplacian_nonzeros,
            s.gradient_nonzeros,
            self.out.display(),
            s.gamma
        );
        Ok(())
    }
}

/// Arguments of `mfm convert`.
#[derive(Args)]
pub struct ConvertArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Output file, .obj or .ply.
    out: PathBuf,
}

impl ConvertArgs {
    /// Writes the mesh by the output's extension.
    pub fn run(self) -> Result<()> {
        let mesh = load_mesh(&self.mesh)?;
        let undo = prepare_outputs(
            &[mesh_path(&self.mesh)],
            std::slice::from_ref(&self.out),
            &[],
        )?;
        mfm_meshio::write_mesh(&self.out, &mesh)?;
        undo.keep();
        println!(
            "wrote {} ({} vertices, {} faces)",
            self.out.display(),
            mesh.num_vertices(),
            mesh.num_faces()
        );
        Ok(())
    }
}

/// Per-vertex quantities `mfm render --scalar` can show.
#[derive(Clone, Copy, ValueEnum)]
pub enum Quantity {
    /// x coordinate.
    X,
    /// y coordinate.
    Y,
    /// z coordinate.
    Z,
    /// Lumped (barycentric) vertex mass.
    Mass,
}

/// Arguments of `mfm render`.
#[derive(Args)]
pub struct RenderArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Color by a built-in per-vertex quantity.
    #[arg(long, value_enum, conflicts_with = "scalars")]
    scalar: Option<Quantity>,
    /// Color by values from a .npy file with one value per vertex.
    #[arg(long)]
    scalars: Option<PathBuf>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 800)]
    size: u32,
}

impl RenderArgs {
    /// Renders the mesh, coloured when asked, to a PNG.
    pub fn run(self) -> Result<()> {
        if !(16..=8192).contains(&self.size) {
            bail!("--size {}: expected 16..=8192 pixels", self.size);
        }
        let inputs = [mesh_path(&self.mesh), self.scalars.as_deref()];
        let undo = prepare_outputs(&inputs, std::slice::from_ref(&self.out), &[])?;
        let mesh = load_mesh(&self.mesh)?;
        let coordinate = |k: usize| mesh.positions().iter().map(|p| p[k]).collect();
        let values: Option<Vec<f64>> = match (self.scalar, &self.scalars) {
            (Some(Quantity::X), _) => Some(coordinate(0)),
            (Some(Quantity::Y), _) => Some(coordinate(1)),
            (Some(Quantity::Z), _) => Some(coordinate(2)),
            (Some(Quantity::Mass), _) => Some(operators::lumped_mass(&mesh)),
            (None, Some(path)) => {
                let a = mfm_files::npy::read::<f64>(path)?;
                if a.values.len() != mesh.num_vertices() {
                    bail!(
                        "{}: expected {} values (one per vertex), found shape {:?}",
                        path.display(),
                        mesh.num_vertices(),
                        a.shape
                    );
                }
                let bad = a.values.iter().filter(|v| !v.is_finite()).count();
                if bad == a.values.len() {
                    bail!(
                        "{}: all {bad} values are non-finite (NaN or inf): nothing to colour by",
                        path.display()
                    );
                }
                if bad > 0 {
                    eprintln!(
                        "warning: {}: {bad} of {} values are non-finite (NaN or inf); \
                         those vertices are drawn grey and the colour bar spans the finite ones",
                        path.display(),
                        a.values.len()
                    );
                }
                Some(a.values)
            }
            (None, None) => None,
        };
        let opts = mfm_render::RenderOptions {
            width: self.size,
            height: self.size,
            colorbar: values.is_some(),
            ..Default::default()
        };
        let img = mfm_render::render_mesh(&mesh, values.as_deref(), &opts)?;
        mfm_render::save_png(&img, &self.out)?;
        undo.keep();
        println!("wrote {}", self.out.display());
        Ok(())
    }
}

/// Arguments of `mfm remesh`.
#[derive(Args)]
pub struct RemeshArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Output mesh (.ply or .obj).
    #[arg(long)]
    out: PathBuf,
    /// Rounds of midpoint subdivision (each multiplies the faces by 4 and
    /// keeps the surface).
    #[arg(long, default_value_t = 0)]
    subdivide: u32,
    /// Rounds of longest-edge bisection of the faces on one half of the
    /// mesh (x below the split of the GMM experiment's test mesh), after
    /// --subdivide: a non-uniform triangulation of the same surface, about
    /// 2.5x the faces for 2 rounds.
    #[arg(long, default_value_t = 0)]
    refine_half: u32,
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

impl RemeshArgs {
    /// Subdivides, then damages, and writes the mesh.
    pub fn run(self) -> Result<()> {
        if self.subdivide > 6 {
            bail!(
                "--subdivide {}: at most 6 rounds (4096x the faces)",
                self.subdivide
            );
        }
        if self.refine_half > 4 {
            bail!(
                "--refine-half {}: at most 4 rounds (about 4x the faces of the half per 2 rounds)",
                self.refine_half
            );
        }
        let inputs = [mesh_path(&self.mesh), self.space.as_deref()];
        let undo = prepare_outputs(&inputs, std::slice::from_ref(&self.out), &[])?;
        let mut mesh = load_mesh_checked(&self.mesh)?;
        let input = (mesh.num_vertices(), mesh.num_faces());
        for _ in 0..self.subdivide {
            mesh = subdivide::midpoint(&mesh)?;
        }
        if self.refine_half > 0 {
            let density = mfm_data::experiment::HalfDensity::Refine {
                rounds: self.refine_half,
            };
            mesh = mfm_data::experiment::GmmMeshes::from_base(mesh, density)?.test;
        }
        if let Some(name) = &self.damage {
            let damage: Damage = name.parse()?;
            let path = self.space.as_ref().context("--damage needs --space")?;
            let space = mfm_data::layout::read_space(path)?;
            mesh = damaged_mesh(&mesh, &space, damage, self.seed)?;
        }
        mfm_meshio::write_mesh(&self.out, &mesh)?;
        undo.keep();
        println!(
            "{}: {} vertices, {} faces (from {} vertices, {} faces)",
            self.out.display(),
            mesh.num_vertices(),
            mesh.num_faces(),
            input.0,
            input.1
        );
        Ok(())
    }
}

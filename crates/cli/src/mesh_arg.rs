//! Resolving a MESH argument: a file path or a `builtin:` procedural mesh.

use anyhow::{Context, Result, bail};
use mfm_geometry::validate::{MeshProblem, MeshReport};
use mfm_geometry::{TriMesh, procedural};
use std::path::Path;

/// Names accepted after `builtin:`.
pub const BUILTINS: &[&str] = &["icosphere", "blob", "uv-sphere", "torus", "capsule", "grid"];

/// Loads a mesh from a file, or builds a built-in one (`builtin:NAME[:N]`,
/// where N is a resolution parameter: subdivisions for the icosphere, cells per
/// side for the grid, a resolution multiplier otherwise).
pub fn load_mesh(spec: &str) -> Result<TriMesh> {
    let Some(rest) = spec.strip_prefix("builtin:") else {
        return mfm_meshio::read_mesh(Path::new(spec)).map_err(anyhow::Error::from);
    };
    let (name, param) = match rest.split_once(':') {
        Some((n, p)) => {
            let v: u32 = p.parse().with_context(|| {
                format!("{spec}: resolution `{p}` is not a non-negative integer")
            })?;
            (n, Some(v))
        }
        None => (rest, None),
    };
    let mesh = match name {
        "icosphere" => {
            let s = param.unwrap_or(3);
            if s > 8 {
                bail!("{spec}: at most 8 subdivisions (the mesh would have over 1.3M vertices)");
            }
            procedural::icosphere(s)
        }
        "blob" => {
            let s = param.unwrap_or(4);
            if s > 8 {
                bail!("{spec}: at most 8 subdivisions (the mesh would have over 1.3M vertices)");
            }
            procedural::blob(s)?
        }
        "uv-sphere" => {
            let k = param.unwrap_or(1).clamp(1, 64);
            procedural::uv_sphere(24 * k, 48 * k)?
        }
        "torus" => {
            let k = param.unwrap_or(1).clamp(1, 64);
            procedural::torus(1.0, 0.4, 64 * k, 24 * k)?
        }
        "capsule" => {
            let k = param.unwrap_or(1).clamp(1, 64);
            procedural::capsule(0.5, 0.75, 16 * k, 48 * k)?
        }
        "grid" => {
            let n = param.unwrap_or(32).clamp(1, 4096);
            procedural::plane_grid(n, n, 1.0, 1.0)?
        }
        other => bail!(
            "{spec}: unknown built-in mesh `{other}` (known: {})",
            BUILTINS.join(", ")
        ),
    };
    Ok(mesh)
}

/// The file a MESH argument names, `None` for a built-in mesh.
pub fn mesh_path(spec: &str) -> Option<&Path> {
    (!spec.starts_with("builtin:")).then(|| Path::new(spec))
}

/// [`load_mesh`] for a command that computes on the mesh (operators, eigs,
/// noise, spectrum, datasets, sampling, remeshing): the problems `mfm info`
/// reports ([`MeshReport`]) are warnings on standard error, and duplicate
/// faces, which every operator would count twice, are an error. `info`,
/// `convert` and `render` take any mesh as it is.
pub fn load_mesh_checked(spec: &str) -> Result<TriMesh> {
    let mesh = load_mesh(spec)?;
    check_mesh(spec, &mesh)?;
    Ok(mesh)
}

/// The policy of [`load_mesh_checked`] on a mesh already loaded.
pub fn check_mesh(spec: &str, mesh: &TriMesh) -> Result<()> {
    let report = MeshReport::new(mesh);
    if let Some(p) = report
        .problems
        .iter()
        .find(|p| matches!(p, MeshProblem::DuplicateFaces { .. }))
    {
        bail!(
            "{spec}: {p}; every operator would count their area twice: remove them first \
(`mfm info {spec}` lists the mesh's problems)"
        );
    }
    for p in &report.problems {
        eprintln!("warning: {spec}: {p} (`mfm info {spec}` shows the full report)");
    }
    Ok(())
}

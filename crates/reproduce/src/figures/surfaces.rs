//! The meshes behind the spectral figures: the input surface (normalized to
//! unit area), three resolutions of it, a coarse/fine pair for the full
//! spectrum, and non-uniform triangulations.

use anyhow::{Context, Result};
use mfm_geometry::{TriMesh, procedural, subdivide};
use mfm_processing::decimate;
use mfm_processing::refine::{RefineCriterion, refine_region};
use std::path::{Path, PathBuf};

/// The surface the figures are drawn on.
#[derive(Debug, Clone)]
pub struct Surface {
    /// Where it came from, for captions and the README.
    pub name: String,
    /// The mesh, centred at its bounding-box centre and scaled to unit area.
    pub mesh: TriMesh,
}

/// A mesh with a short label used in legends, tables and file names.
#[derive(Debug, Clone)]
pub struct Labeled {
    /// Short label, e.g. `"13.9k V"`.
    pub label: String,
    /// How it was made, in words.
    pub how: String,
    /// The mesh.
    pub mesh: TriMesh,
}

/// `mesh` centred at its bounding-box centre and scaled to unit area, so that
/// eigenvalues follow Weyl's law `lambda_k ~ 4 pi k` and `tau = 100` sits near
/// the eighth frequency whatever the input's units.
pub fn unit_area(mesh: &TriMesh) -> TriMesh {
    let (lo, hi) = mesh.bounding_box();
    let s = 1.0 / mesh.total_area().sqrt();
    let c = [0, 1, 2].map(|k| -0.5 * (lo[k] + hi[k]) * s);
    mesh.transformed(s, c)
}

/// The default input: `$MFM_SHARED_MESHES/bunny.off` or
/// `<root>/../shared/meshes/bunny.off` when present.
pub fn default_mesh_path(root: &Path) -> Option<PathBuf> {
    let dir = std::env::var_os("MFM_SHARED_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("../shared/meshes"));
    let path = dir.join("bunny.off");
    path.is_file().then_some(path)
}

/// The built-in bunny-like surface `builtin:blob` of the CLI
/// ([`procedural::blob`]) with `level` subdivisions: smooth, closed,
/// uniformly triangulated. Deterministic.
pub fn blob(level: u32) -> Result<TriMesh> {
    Ok(procedural::blob(level)?)
}

/// Loads `path` (or the default bunny, or falls back to [`blob`]) and
/// normalizes it with [`unit_area`].
pub fn load(path: Option<&Path>, root: &Path) -> Result<Surface> {
    let path = match path {
        Some(p) => Some(p.to_path_buf()),
        None => default_mesh_path(root),
    };
    let (name, mesh) = match path {
        Some(p) => {
            let mesh = mfm_meshio::read_mesh(&p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string());
            (name, mesh)
        }
        None => {
            eprintln!(
                "xtask: shared bunny not found; using the procedural blob (builtin:blob, level 4)"
            );
            (
                "procedural blob (builtin:blob, level 4)".to_owned(),
                blob(4)?,
            )
        }
    };
    Ok(Surface {
        name,
        mesh: unit_area(&mesh),
    })
}

/// `"13.9k V"` style vertex count.
pub fn count_label(v: usize) -> String {
    if v >= 10_000 {
        format!("{:.1}k V", v as f64 / 1000.0)
    } else if v >= 1000 {
        format!("{:.2}k V", v as f64 / 1000.0)
    } else {
        format!("{v} V")
    }
}

/// Three resolutions of one piecewise-flat surface for the per-frequency
/// statistics, finest last.
///
/// The base is `surface` midpoint-subdivided (which keeps the surface
/// exactly) until it has at least `min_vertices` vertices, so that the
/// highest kept frequency is well resolved on every resolution: the discrete
/// `lambda_i` of a mesh with `V` vertices is below the converged one by
/// roughly `i / V` relative (measured on the bunny: 17% at `i = 500` with 3.5k
/// vertices, 3% with 14k), and frequencies are matched by index. Then
/// - coarse: the base decimated to half its faces (quadric edge collapse,
///   a different and irregular triangulation of nearly the same surface);
/// - fine: one round of longest-edge bisection of every face of the base
///   (same surface, about 2.3x the vertices, other triangle shapes).
pub fn ladder(surface: &TriMesh, min_vertices: usize) -> Result<[Labeled; 3]> {
    let mut base = surface.clone();
    let mut levels = 0;
    while base.num_vertices() < min_vertices {
        base = subdivide::midpoint(&base)?;
        levels += 1;
    }
    let coarse = decimate::decimate(&base, base.num_faces() / 2, None)?.mesh;
    let fine = refine_region(&base, |_| true, RefineCriterion::Rounds(1))?;
    let base_how = if levels == 0 {
        "the input mesh".to_owned()
    } else {
        format!("the input, midpoint-subdivided {levels}x")
    };
    Ok([
        Labeled {
            label: count_label(coarse.num_vertices()),
            how: format!("{base_how}, decimated to half its faces"),
            mesh: coarse,
        },
        Labeled {
            label: count_label(base.num_vertices()),
            how: base_how.clone(),
            mesh: base,
        },
        Labeled {
            label: count_label(fine.num_vertices()),
            how: format!("{base_how}, every face bisected once (longest edge)"),
            mesh: fine,
        },
    ])
}

/// A coarse mesh of about `coarse_vertices` vertices (the surface decimated)
/// and its midpoint subdivision (the same piecewise-flat surface, ~4x the
/// vertices): small enough for their complete spectra.
pub fn spectrum_pair(surface: &TriMesh, coarse_vertices: usize) -> Result<[Labeled; 2]> {
    // closed genus-0 meshes have F = 2V - 4
    let target_faces = 2 * coarse_vertices;
    let coarse = if surface.num_faces() > target_faces {
        decimate::decimate(surface, target_faces, None)?.mesh
    } else {
        surface.clone()
    };
    let fine = subdivide::midpoint(&coarse)?;
    Ok([
        Labeled {
            label: format!("coarse {}", count_label(coarse.num_vertices())),
            how: "the input decimated".to_owned(),
            mesh: coarse,
        },
        Labeled {
            label: format!("fine {}", count_label(fine.num_vertices())),
            how: "the coarse mesh midpoint-subdivided (same surface)".to_owned(),
            mesh: fine,
        },
    ])
}

/// A flat unit square with `cells x cells` cells (two triangles each), and
/// the same square with its right half (`x > 0`) refined by `rounds` rounds
/// of longest-edge bisection (each two rounds halve the edge length).
pub fn plane_pair(cells: u32, rounds: u32) -> Result<[Labeled; 2]> {
    let plane = procedural::plane_grid(cells, cells, 1.0, 1.0)?;
    let half = refine_region(&plane, |c| c[0] > 0.0, RefineCriterion::Rounds(rounds))?;
    Ok([
        Labeled {
            label: format!("uniform {}", count_label(plane.num_vertices())),
            how: format!("unit square, {cells}x{cells} cells"),
            mesh: plane,
        },
        Labeled {
            label: format!("right half refined {}", count_label(half.num_vertices())),
            how: format!("the square with x > 0 bisected {rounds} rounds"),
            mesh: half,
        },
    ])
}

/// `surface` with the half `x > centre` refined by `rounds` rounds of
/// longest-edge bisection.
pub fn half_refined(surface: &TriMesh, rounds: u32) -> Result<Labeled> {
    let (lo, hi) = surface.bounding_box();
    let centre = 0.5 * (lo[0] + hi[0]);
    let mesh = refine_region(surface, |c| c[0] > centre, RefineCriterion::Rounds(rounds))?;
    Ok(Labeled {
        label: format!("half refined {}", count_label(mesh.num_vertices())),
        how: format!("the input with x > centre bisected {rounds} rounds"),
        mesh,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_area_normalizes_and_centres() -> Result<()> {
        let m = unit_area(&blob(2)?.transformed(3.0, [1.0, 2.0, 3.0]));
        assert!((m.total_area() - 1.0).abs() < 1e-12);
        let (lo, hi) = m.bounding_box();
        for k in 0..3 {
            assert!((lo[k] + hi[k]).abs() < 1e-12);
        }
        Ok(())
    }

    #[test]
    fn ladder_is_ordered_and_keeps_the_area() -> Result<()> {
        let s = unit_area(&blob(2)?);
        let [c, b, f] = ladder(&s, 300)?;
        assert!(c.mesh.num_vertices() < b.mesh.num_vertices());
        assert!(b.mesh.num_vertices() < f.mesh.num_vertices());
        assert!(b.mesh.num_vertices() >= 300);
        // subdivision and bisection keep the surface; decimation nearly
        assert!((b.mesh.total_area() - 1.0).abs() < 1e-12);
        assert!((f.mesh.total_area() - 1.0).abs() < 1e-12);
        assert!((c.mesh.total_area() - 1.0).abs() < 0.05);
        Ok(())
    }
}

//! Train/test meshes for the GMM experiment (paper section 5, supplementary
//! "GMM datasets"; docs/conventions.md, "Experiments").
//!
//! The model is trained on a **uniform** triangulation and evaluated on a
//! **non-uniform triangulation of the same surface**, in which one half has
//! a different vertex density. The paper coarsens the left half of the
//! bunny; here the default is to **refine** it ([`HalfDensity::Refine`]):
//! refinement by longest-edge bisection
//! ([`mfm_processing::refine::refine_region`]) inserts edge midpoints only, so
//! the test mesh is *exactly* the same piecewise-linear surface as the
//! training mesh (same area, same volume, same positions for every original
//! vertex), and only the triangulation differs. [`HalfDensity::Coarsen`]
//! follows the paper instead (quadric-error decimation restricted to the
//! half, [`mfm_processing::decimate::decimate`]); it moves the surface slightly
//! (the area typically changes by well under a percent on smooth meshes).
//!
//! "Half" is the part of the surface with `x` below the area-weighted
//! centroid's `x` ([`split_x`]), decided per face centroid (refinement) or
//! per edge endpoint (decimation).
//!
//! # Example
//! ```
//! use mfm_data::experiment::{GmmMeshes, HalfDensity};
//! use mfm_geometry::procedural;
//! let meshes = GmmMeshes::from_base(procedural::icosphere(2), HalfDensity::default()).unwrap();
//! assert!(meshes.test.num_vertices() > 2 * meshes.train.num_vertices());
//! assert!((meshes.test.total_area() - meshes.train.total_area()).abs() < 1e-9);
//! ```

use mfm_geometry::TriMesh;
use mfm_geometry::operators::face_areas;
use mfm_geometry::procedural;
use mfm_processing::decimate::decimate;
use mfm_processing::refine::{RefineCriterion, refine_region};

use crate::error::{DataError, Result};

/// Subdivision level of the [`procedural::blob`] used by
/// [`GmmMeshes::builtin`] (2562 vertices).
pub const BUILTIN_BLOB_SUBDIVISIONS: u32 = 4;

/// How the test mesh's half differs from the training mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HalfDensity {
    /// Refine the half by this many rounds of longest-edge bisection (each
    /// round halves the faces' areas there: `rounds = 2` gives about 4x the
    /// vertex density). Keeps the surface exactly.
    Refine {
        /// Bisection rounds (at least 1).
        rounds: u32,
    },
    /// Decimate the half until it has about `1 / factor` of its faces (so
    /// about `1 / factor` of the vertex density). Moves the surface slightly.
    Coarsen {
        /// Density reduction factor (greater than 1).
        factor: f64,
    },
}

impl Default for HalfDensity {
    /// `Refine { rounds: 2 }`: about 4x the vertex density on one half.
    fn default() -> Self {
        Self::Refine { rounds: 2 }
    }
}

/// The GMM experiment's meshes: the uniform training mesh and the
/// non-uniform test mesh of the same surface (see the [module docs](self)).
#[derive(Clone, Debug)]
pub struct GmmMeshes {
    /// The uniform triangulation the model is trained on.
    pub train: TriMesh,
    /// The non-uniform triangulation the model is evaluated on.
    pub test: TriMesh,
}

impl GmmMeshes {
    /// `train = base`; `test = base` with its `x < split_x(base)` half
    /// refined or coarsened as `density` says.
    ///
    /// Cost: `O(F log F)` of the output.
    ///
    /// # Errors
    /// [`DataError::Config`] for `rounds == 0` or `factor <= 1`;
    /// [`DataError::MeshProcessing`] if refinement or decimation fails (e.g.
    /// a non-manifold base).
    pub fn from_base(base: TriMesh, density: HalfDensity) -> Result<Self> {
        let cut = split_x(&base);
        let left = move |p: [f64; 3]| p[0] < cut;
        let test = match density {
            HalfDensity::Refine { rounds } => {
                if rounds == 0 {
                    return Err(DataError::Config(
                        "the test mesh's refinement needs at least 1 round".into(),
                    ));
                }
                refine_region(&base, left, RefineCriterion::Rounds(rounds)).map_err(|e| {
                    DataError::MeshProcessing {
                        what: "refining half of the GMM test mesh".into(),
                        source: Box::new(e),
                    }
                })?
            }
            HalfDensity::Coarsen { factor } => {
                if !(factor.is_finite() && factor > 1.0) {
                    return Err(DataError::Config(format!(
                        "the test mesh's coarsening factor must be finite and > 1, found {factor}"
                    )));
                }
                let p = base.positions();
                let in_half = base
                    .faces()
                    .iter()
                    .filter(|f| f.iter().all(|&v| left(p[v as usize])))
                    .count();
                let removed = (in_half as f64 * (1.0 - 1.0 / factor)).round() as usize;
                let target = base.num_faces().saturating_sub(removed);
                let region: &dyn Fn([f64; 3]) -> bool = &left;
                decimate(&base, target, Some(region))
                    .map_err(|e| DataError::MeshProcessing {
                        what: "coarsening half of the GMM test mesh".into(),
                        source: Box::new(e),
                    })?
                    .mesh
            }
        };
        Ok(Self { train: base, test })
    }

    /// The built-in pair used by the demo and the CPU-scale reproduction:
    /// train on [`procedural::blob`]`(`[`BUILTIN_BLOB_SUBDIVISIONS`]`)`
    /// (2562 vertices, 5120 faces), test on the same mesh with its `x < c_x`
    /// half refined twice ([`HalfDensity::default`]; about 6.4k vertices).
    ///
    /// # Errors
    /// As [`GmmMeshes::from_base`] (not expected for the built-in shape).
    pub fn builtin() -> Result<Self> {
        let blob =
            procedural::blob(BUILTIN_BLOB_SUBDIVISIONS).map_err(|e| DataError::MeshProcessing {
                what: "building the built-in blob".into(),
                source: Box::new(e),
            })?;
        Self::from_base(blob, HalfDensity::default())
    }
}

/// The `x` coordinate of the area-weighted centroid of the surface (the
/// mean of the face centroids weighted by face area): where the test mesh
/// is split in halves. Independent of how the surface is triangulated.
pub fn split_x(mesh: &TriMesh) -> f64 {
    let areas = face_areas(mesh);
    let p = mesh.positions();
    let (mut sum, mut total) = (0.0, 0.0);
    for (f, a) in mesh.faces().iter().zip(&areas) {
        let cx = (p[f[0] as usize][0] + p[f[1] as usize][0] + p[f[2] as usize][0]) / 3.0;
        sum += a * cx;
        total += a;
    }
    if total > 0.0 { sum / total } else { 0.0 }
}

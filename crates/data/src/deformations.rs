//! Deformation datasets (docs/conventions.md, "Experiments"; the paper's
//! reposing and elastic-deformation experiments at CPU scale).
//!
//! The paper's deformation data (SMPL poses, IPC simulations) is not
//! available here, so shapes come from a *known* parametric space instead:
//! [`mfm_deform::DeformSpace`], as-rigid-as-possible deformations driven by
//! random rigid motions of a few handle regions (feet, trunk, tail...) with a
//! fixed anchor (the torso). A shape is stored as a 3-channel signal (its
//! vertex positions) over the rest mesh, aligned to the rest shape (centered,
//! rotation about the up axis removed).
//!
//! Meshes ([`DeformMeshes`]): the user's mesh is normalized (area centroid at
//! the origin, unit bounding-box diagonal) into `original`; `coarse` is its
//! decimation (the training mesh, as in the paper where the simulation mesh
//! is much coarser than the surface); `eval` is `coarse` with its `x <
//! centroid` half refined twice (a finer, non-uniform triangulation of the
//! same surface, as in the GMM experiment). Handles live in ambient space, so
//! one [`mfm_deform::HandleSet`] selects corresponding regions on all of them
//! and the same parameters give the same pose at every resolution.
//!
//! How plausible generated shapes are (their distance to the space) is
//! measured by `mfm_eval::plausibility`.

use std::ops::Range;
use std::path::Path;

use indicatif::{ProgressBar, ProgressStyle};
use mfm_deform::{DeformParams, DeformSpace, HandleSet, normalize_rest};
use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use mfm_processing::decimate::decimate;
use serde::{Deserialize, Serialize};

use crate::dataset::{Dataset, Manifest};
use crate::error::{DataError, Result};
use crate::experiment::{GmmMeshes, HalfDensity};
use crate::signals::InMemorySignals;

/// The generator name recorded in the manifest of a deformation dataset.
pub const GENERATOR: &str = "deform";

/// File beside `signals.npy` holding every sample's [`DeformParams`] (a JSON
/// array in sample order).
pub const PARAMS_FILE: &str = "params.json";

/// The meshes of a deformation experiment; see the [module docs](self).
#[derive(Clone, Debug)]
pub struct DeformMeshes {
    /// The user's mesh, normalized (area centroid at the origin, unit
    /// bounding-box diagonal).
    pub original: TriMesh,
    /// The decimated training mesh (or `original` when it is already small).
    pub coarse: TriMesh,
    /// `coarse` with its `x < centroid` half refined twice: finer and
    /// non-uniform, the same surface as `coarse`.
    pub eval: TriMesh,
    /// The map `p -> scale * p + shift` that took the user's mesh to
    /// `original` (from [`normalize_rest`]).
    pub normalization: Normalization,
    /// The canonical frame of `coarse`, the training surface (recorded in
    /// every dataset of the experiment).
    pub frame: CanonicalFrame,
}

/// The similarity that took the user's mesh to [`DeformMeshes::original`]
/// (the values [`normalize_rest`] returns).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Scale factor (applied first).
    pub scale: f64,
    /// Shift added after scaling.
    pub shift: [f64; 3],
}

impl DeformMeshes {
    /// Normalizes `mesh`, decimates it to at most `coarse_faces` faces (kept
    /// as is when it has fewer) and builds the evaluation mesh.
    ///
    /// Cost: `O(F log F)`.
    ///
    /// # Errors
    /// [`DataError::Config`] for `coarse_faces < 100`;
    /// [`DataError::MeshProcessing`] when normalization, decimation or
    /// refinement fails (e.g. a non-manifold mesh).
    pub fn from_mesh(mesh: &TriMesh, coarse_faces: usize) -> Result<Self> {
        if coarse_faces < 100 {
            return Err(DataError::Config(format!(
                "the coarse mesh needs at least 100 faces, asked for {coarse_faces}"
            )));
        }
        let (original, scale, shift) =
            normalize_rest(mesh).map_err(|e| mesh_error("normalizing the mesh", e))?;
        let coarse = if original.num_faces() > coarse_faces {
            decimate(&original, coarse_faces, None)
                .map_err(|e| mesh_error("decimating the mesh to the training resolution", e))?
                .mesh
        } else {
            original.clone()
        };
        let eval = GmmMeshes::from_base(coarse.clone(), HalfDensity::default())?.test;
        let frame = CanonicalFrame::of(&coarse)
            .map_err(|e| mesh_error("placing the coarse mesh in the canonical frame", e))?;
        Ok(Self {
            frame,
            original,
            coarse,
            eval,
            normalization: Normalization { scale, shift },
        })
    }
}

fn mesh_error(what: &str, e: impl std::error::Error + Send + Sync + 'static) -> DataError {
    DataError::MeshProcessing {
        what: what.into(),
        source: Box::new(e),
    }
}

/// What a deformation dataset's manifest records (`generator_params`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeformManifest {
    /// The deformation space (handles, ranges, ARAP options, up axis).
    pub space: DeformSpace,
    /// Which samples of the seed's sequence the dataset holds.
    pub first: usize,
    /// The normalization of the source mesh.
    pub normalization: Normalization,
    /// What the mesh is (`coarse`, `eval`, `original`...).
    pub mesh_role: String,
}

impl DeformManifest {
    /// Reads the deformation parameters of a dataset (`None` when another
    /// generator made it).
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) naming the manifest when `generator_params` do
    /// not parse.
    pub fn of(dataset: &Dataset) -> Result<Option<Self>> {
        dataset.generator_params(GENERATOR)
    }
}

/// Generates samples `range` of `seed` on `mesh` and writes them as a
/// dataset folder `dir` (mesh, `signals.npy` `[N, V, 3]` f32, manifest
/// recording `frame`, the training surface's canonical frame) plus
/// [`PARAMS_FILE`]. Shows a progress bar when `progress` is set.
///
/// Cost: one ARAP factorization of `mesh`, then per sample a few tens of
/// 3-column solves and local SVD steps (parallel over samples).
///
/// # Errors
/// [`DataError::Deform`] (empty handle region on this mesh, ...), and the
/// errors of [`Dataset::write`].
#[allow(clippy::too_many_arguments)]
pub fn write_dataset(
    dir: &Path,
    mesh: &TriMesh,
    space: &DeformSpace,
    seed: u64,
    range: Range<usize>,
    normalization: Normalization,
    frame: CanonicalFrame,
    mesh_role: &str,
    provenance: &str,
    progress: bool,
) -> Result<Dataset> {
    let n = range.len();
    if n == 0 {
        return Err(DataError::Config(
            "a deformation dataset needs at least 1 sample".into(),
        ));
    }
    let bar = if progress {
        let bar = ProgressBar::new(n as u64);
        bar.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} shapes ({eta} left)")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_prefix(format!("ARAP on {} vertices", mesh.num_vertices()));
        bar
    } else {
        ProgressBar::hidden()
    };
    let first = range.start;
    let shapes = space.generate(mesh, seed, range, |_| bar.inc(1))?;
    bar.finish_and_clear();
    let v = mesh.num_vertices();
    let data: Vec<f32> = shapes
        .iter()
        .flat_map(|s| s.positions.iter().flat_map(|p| p.map(|x| x as f32)))
        .collect();
    let signals = InMemorySignals::new(data, n, v, 3)?;
    let params = DeformManifest {
        space: space.clone(),
        first,
        normalization,
        mesh_role: mesh_role.into(),
    };
    let manifest = Manifest::new(
        GENERATOR,
        serde_json::to_value(&params).map_err(|e| DataError::Config(e.to_string()))?,
    )
    .with_seed(seed)
    .with_provenance(provenance)
    .with_frame(frame);
    let dataset = Dataset::write(dir, mesh, &signals, manifest)?;
    let all: Vec<&DeformParams> = shapes.iter().map(|s| &s.params).collect();
    let path = dataset.dir().join(PARAMS_FILE);
    let text = serde_json::to_string(&all).map_err(|e| DataError::Config(e.to_string()))?;
    std::fs::write(&path, text).map_err(|e| DataError::io(&path, e))?;
    Ok(dataset)
}

/// Picks the handles of a new deformation space on `original` (see
/// [`HandleSet::auto`]) and returns the space with the given ranges.
///
/// # Errors
/// [`DataError::Deform`] when the handles cannot be placed.
pub fn space_for(
    original: &TriMesh,
    handles: usize,
    radius: f64,
    max_angle: f64,
    max_shift: f64,
) -> Result<DeformSpace> {
    let set = HandleSet::auto(original, handles, radius)?;
    let mut space = DeformSpace::new(original, set);
    space.max_angle = max_angle;
    space.max_shift = max_shift;
    space.validate()?;
    Ok(space)
}

/// A damaged source mesh for the robustness table (the paper's holes,
/// partial meshes and edge flips); see [`damaged_mesh`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Damage {
    /// Three holes of radius 2% of the bounding-box diagonal.
    SmallHoles,
    /// Three holes of radius 4% of the diagonal.
    MediumHoles,
    /// Three holes of radius 7% of the diagonal.
    LargeHoles,
    /// One large patch (radius up to 20% of the diagonal) missing where the
    /// surface is farthest from every handle: an open, partial scan.
    Partial,
    /// 10% of the interior edges flipped.
    MildFlips,
    /// 50% of the interior edges flipped.
    SevereFlips,
}

impl Damage {
    /// Every damage, in table order.
    pub const ALL: [Damage; 6] = [
        Damage::SmallHoles,
        Damage::MediumHoles,
        Damage::LargeHoles,
        Damage::Partial,
        Damage::MildFlips,
        Damage::SevereFlips,
    ];

    /// The kebab-case name (`small-holes`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Damage::SmallHoles => "small-holes",
            Damage::MediumHoles => "medium-holes",
            Damage::LargeHoles => "large-holes",
            Damage::Partial => "partial",
            Damage::MildFlips => "mild-flips",
            Damage::SevereFlips => "severe-flips",
        }
    }
}

impl std::str::FromStr for Damage {
    type Err = DataError;
    fn from_str(s: &str) -> Result<Self> {
        Damage::ALL
            .into_iter()
            .find(|d| d.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Damage::ALL.iter().map(|d| d.name()).collect();
                DataError::Config(format!(
                    "unknown damage {s:?}; expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

/// Largest relative difference between a mesh's bounding-box diagonal and
/// the diagonal a [`DeformSpace`] was made for ([`space_fits`]).
pub const SPACE_DIAGONAL_TOLERANCE: f64 = 0.05;

/// Checks that `space` belongs to `mesh`'s surface (any triangulation of
/// it, in the space's units): the bounding-box diagonals agree within
/// [`SPACE_DIAGONAL_TOLERANCE`] and every handle ball holds vertices of
/// `mesh`, disjointly. A space made for another surface (or for this one
/// in other units) would place its handles, and so the regions damage must
/// spare, anywhere.
///
/// # Errors
/// [`DataError::Config`] naming both diagonals or the handle without a
/// vertex.
pub fn space_fits(mesh: &TriMesh, space: &DeformSpace) -> Result<()> {
    let diag = mesh.bounding_box_diagonal();
    let rel = (diag - space.diagonal).abs() / space.diagonal.abs().max(f64::MIN_POSITIVE);
    if rel.is_nan() || rel > SPACE_DIAGONAL_TOLERANCE {
        return Err(DataError::Config(format!(
            "the deformation space was made for a surface of bounding-box diagonal {}, this mesh's is {}: not the space's surface (use the meshes of the dataset the space belongs to)",
            four_digits(space.diagonal),
            four_digits(diag)
        )));
    }
    space.handles.regions(mesh).map_err(|e| {
        DataError::Config(format!(
            "the deformation space does not fit this mesh ({e}): not the space's surface"
        ))
    })?;
    Ok(())
}

/// `x` to four significant digits, in the shared number format.
fn four_digits(x: f64) -> String {
    mfm_files::fmt_f64(format!("{x:.3e}").parse().unwrap_or(x))
}

/// `mesh` damaged as `damage` says, keeping every handle region of the
/// space's handles intact (hole centres are drawn among vertices farther than the hole
/// radius plus the handle radius from every handle centre; the partial
/// patch stops short of every handle region) so that the projection metric
/// stays defined. Holes are geodesic (edge-path) discs; the largest connected
/// component is kept. Deterministic in `seed`.
///
/// # Errors
/// [`space_fits`]'s when the space is not of `mesh`'s surface;
/// [`DataError::Config`] when no vertex is far enough from the handles for a
/// hole; [`DataError::MeshProcessing`] when punching fails.
pub fn damaged_mesh(
    mesh: &TriMesh,
    space: &DeformSpace,
    damage: Damage,
    seed: u64,
) -> Result<TriMesh> {
    space_fits(mesh, space)?;
    let handles = &space.handles;
    use mfm_processing::flips::{FlipAmount, random_edge_flips};
    use mfm_processing::holes::{HoleMetric, largest_component, punch_holes};
    use rand::{Rng, SeedableRng};
    let diag = mesh.bounding_box_diagonal();
    let hole_radius = match damage {
        Damage::SmallHoles => 0.02,
        Damage::MediumHoles => 0.04,
        Damage::LargeHoles => 0.07,
        Damage::MildFlips => {
            return Ok(random_edge_flips(mesh, FlipAmount::Fraction(0.1), seed).mesh);
        }
        Damage::SevereFlips => {
            return Ok(random_edge_flips(mesh, FlipAmount::Fraction(0.5), seed).mesh);
        }
        Damage::Partial => return partial_mesh(mesh, handles),
    } * diag;
    let far: Vec<usize> = mesh
        .positions()
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            handles.iter().all(|h| {
                let d = mfm_geometry::mesh::norm(mfm_geometry::mesh::sub(**p, h.center));
                d > h.radius + 1.5 * hole_radius
            })
        })
        .map(|(i, _)| i)
        .collect();
    if far.len() < 3 {
        return Err(DataError::Config(format!(
            "no room for {} holes away from the handles",
            damage.name()
        )));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let centers: Vec<usize> = (0..3)
        .map(|_| far[rng.random_range(0..far.len())])
        .collect();
    let punched = punch_holes(mesh, &centers, hole_radius, HoleMetric::Geodesic)
        .map_err(|e| mesh_error("punching holes", e))?;
    Ok(largest_component(&punched.mesh))
}

/// One large missing patch, like a scan that never saw part of the
/// surface: a geodesic disc around the vertex farthest from every handle
/// centre, of radius 20% of the diagonal, or less so that it stops short of
/// every handle region; the largest component is kept.
fn partial_mesh(mesh: &TriMesh, handles: &HandleSet) -> Result<TriMesh> {
    use mfm_geometry::mesh::{norm, sub};
    use mfm_processing::holes::{HoleMetric, largest_component, punch_holes};
    let clearance = |p: [f64; 3]| {
        handles
            .iter()
            .map(|h| norm(sub(p, h.center)) - h.radius)
            .fold(f64::INFINITY, f64::min)
    };
    let (center, room) = mesh
        .positions()
        .iter()
        .enumerate()
        .map(|(i, &p)| (i, clearance(p)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or_else(|| DataError::Config("a partial mesh of an empty mesh".into()))?;
    let radius = (0.2 * mesh.bounding_box_diagonal()).min(0.8 * room);
    if radius <= 0.0 {
        return Err(DataError::Config(
            "no room for a missing patch away from the handles".into(),
        ));
    }
    let punched = punch_holes(mesh, &[center], radius, HoleMetric::Geodesic)
        .map_err(|e| mesh_error("cutting a partial mesh", e))?;
    Ok(largest_component(&punched.mesh))
}

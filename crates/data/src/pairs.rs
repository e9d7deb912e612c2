//! Datasets of (source, target) shape pairs for the arbitrary-source model
//! (the paper's section 5.1, "arbitrary, unseen 3D human shapes").
//!
//! The paper pairs SMPL bodies: a source and a target share a body shape
//! and differ in pose. SMPL is not available here, so the shapes come from
//! a known parameter space instead: a [`ShapeFamily`] of the template
//! (smooth region-wise anisotropic scalings) for the body shape and the
//! template's [`DeformSpace`] (ARAP poses of handle regions) for the pose.
//! Shape `s` in pose `a` is the member `s` of the family, posed by ARAP with
//! the template's handle regions (same vertices) turning about the moved
//! centres, and aligned to the member ([`ShapeFamily::pose_space`]).
//!
//! ## Folder
//! A pairs dataset is a dataset folder ([`crate::dataset`]) whose mesh is
//! the template (the connectivity every stored shape has) and whose
//! `signals.npy` `[S * P, V, 3]` holds `P` posed meshes of each of `S`
//! shapes, shape-major: mesh `i` is shape `i / P` in pose `i % P`. The
//! pairs are every ordered pair of two different poses of one shape
//! ([`PairSpace::pairs`]). [`PARAMS_FILE`] holds the parameters of every
//! shape and every pose, from which [`PairSpace::realize`] rebuilds each
//! mesh (on this template or on any other triangulation of its surface).
//!
//! ## Seeds
//! Shape `s` has [`ShapeFamily::sample_params`]`(seed, s)`; its pose `a`
//! has [`DeformSpace::sample_params`]`(seed ^ POSE_SALT, s * P + a)`: pure
//! functions of the seed and the indices, so a held-out set is the same
//! seed at shape indices past the training set's, and the same shapes can
//! be realized on a remeshing.

use std::ops::Range;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::{ProgressBar, ProgressStyle};
use mfm_deform::{Arap, DeformParams, DeformSpace, ShapeFamily, ShapeParams};
use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::SignalSource;
use crate::dataset::{Dataset, Manifest};
use crate::deformations::Normalization;
use crate::error::{DataError, Result};
use crate::signals::InMemorySignals;

/// The generator name recorded in the manifest of a pairs dataset.
pub const GENERATOR: &str = "pairs";

/// File beside `signals.npy` holding the [`PairParams`] of the dataset.
pub const PARAMS_FILE: &str = "params.json";

/// Mixed into the seed for the pose stream, so that poses and shapes never
/// read the same random numbers.
pub const POSE_SALT: u64 = 0x706f_7365_7061_6972;

/// A space of posed body shapes of one template; see the [module
/// docs](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairSpace {
    /// The body shapes.
    pub family: ShapeFamily,
    /// The poses (handles on the template).
    pub poses: DeformSpace,
    /// Poses stored per shape (`P >= 2`, so each shape has pairs).
    pub poses_per_shape: usize,
}

/// The parameters of every mesh of a pairs dataset, as stored in
/// [`PARAMS_FILE`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairParams {
    /// One entry per shape, in order.
    pub shapes: Vec<ShapeParams>,
    /// One entry per mesh (shape-major), in order.
    pub poses: Vec<DeformParams>,
}

/// What a pairs dataset's manifest records (`generator_params`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairsManifest {
    /// The space the shapes were drawn from.
    pub space: PairSpace,
    /// The index of the dataset's first shape in the seed's sequence.
    pub first_shape: usize,
    /// The normalization that took the user's mesh to the template's units.
    pub normalization: Normalization,
    /// What the mesh is (`coarse`, `eval`...).
    pub mesh_role: String,
}

impl PairsManifest {
    /// Reads the parameters of a pairs dataset (`None` when another
    /// generator made it).
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) naming the manifest when `generator_params` do
    /// not parse.
    pub fn of(dataset: &Dataset) -> Result<Option<Self>> {
        dataset.generator_params(GENERATOR)
    }
}

impl PairSpace {
    /// Checks the family, the pose space and `poses_per_shape >= 2`.
    ///
    /// # Errors
    /// [`DataError::Config`] / [`DataError::Deform`] naming the problem.
    pub fn validate(&self) -> Result<()> {
        self.family.validate()?;
        self.poses.validate()?;
        if self.poses_per_shape < 2 {
            return Err(DataError::Config(format!(
                "a pairs dataset needs at least 2 poses per shape, found {}",
                self.poses_per_shape
            )));
        }
        Ok(())
    }

    /// The parameters of shape `s` and of its poses under `seed`.
    pub fn params(&self, seed: u64, shape: usize) -> (ShapeParams, Vec<DeformParams>) {
        let p = self.poses_per_shape;
        let poses = (0..p)
            .map(|a| self.poses.sample_params(seed ^ POSE_SALT, shape * p + a))
            .collect();
        (self.family.sample_params(seed, shape), poses)
    }

    /// The posed meshes of one shape on `template` (any triangulation of
    /// the surface the space was made for): the member `shape` of the
    /// family, posed by each of `poses` and aligned to the member
    /// (vertex positions, in pose order). The poses run in parallel.
    ///
    /// Cost: one ARAP factorization of the member, then one ARAP solve per
    /// pose.
    ///
    /// # Errors
    /// [`DataError::Deform`]: a folded shape, a handle region empty on
    /// `template`, a failed ARAP solve.
    pub fn realize(
        &self,
        template: &TriMesh,
        shape: &ShapeParams,
        poses: &[DeformParams],
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        let member = self.family.realize(template, shape)?;
        let (posing, regions) = self.family.pose_space(template, &self.poses, shape)?;
        let arap = Arap::with_regions(&member, &posing.handles, regions)?;
        poses
            .par_iter()
            .with_max_len(1)
            .map(|pose| Ok(posing.realize(&arap, pose)?))
            .collect()
    }

    /// Generates shapes `shapes` under `seed` on `template`, in parallel
    /// (shapes and their poses), calling `progress` once per finished shape
    /// with the number finished so far. Returns the parameters and the
    /// meshes (shape-major), bit-identical for any thread count.
    ///
    /// # Errors
    /// As [`PairSpace::validate`] and [`PairSpace::realize`].
    pub fn generate(
        &self,
        template: &TriMesh,
        seed: u64,
        shapes: Range<usize>,
        progress: impl Fn(usize) + Sync,
    ) -> Result<(PairParams, Vec<Vec<[f64; 3]>>)> {
        self.validate()?;
        let done = AtomicUsize::new(0);
        let per_shape = shapes
            .into_par_iter()
            .with_max_len(1)
            .map(|s| {
                let (shape, poses) = self.params(seed, s);
                let meshes = self.realize(template, &shape, &poses)?;
                progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                Ok((shape, poses, meshes))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut params = PairParams {
            shapes: Vec::with_capacity(per_shape.len()),
            poses: Vec::new(),
        };
        let mut meshes = Vec::new();
        for (shape, poses, m) in per_shape {
            params.shapes.push(shape);
            params.poses.extend(poses);
            meshes.extend(m);
        }
        Ok((params, meshes))
    }

    /// The ordered (source, target) mesh pairs of a dataset of `meshes`
    /// meshes: every two different poses of one shape, shape-major, then
    /// source, then target. `S P (P - 1)` pairs for `S` shapes.
    pub fn pairs(&self, meshes: usize) -> Vec<(usize, usize)> {
        let p = self.poses_per_shape;
        (0..meshes / p)
            .flat_map(|s| {
                (0..p).flat_map(move |a| {
                    (0..p)
                        .filter(move |&b| b != a)
                        .map(move |b| (s * p + a, s * p + b))
                })
            })
            .collect()
    }
}

/// The ordered (source, target) mesh pairs the arbitrary-source model
/// trains on, for either kind of pairs dataset: one made by `mfm dataset
/// pairs` (every two different poses of one shape, [`PairSpace::pairs`])
/// or one imported from the authors' arbitrary-source file (mesh `2 i` is
/// the source of pair `i`, mesh `2 i + 1` its target,
/// [`crate::import::ImportManifest::pairs`]). `None` for a dataset of
/// single shapes.
///
/// # Errors
/// [`DataError::Files`] (`Format`) naming the manifest when its record does
/// not parse, or an imported pairs set with an odd number of meshes.
pub fn training_pairs(dataset: &Dataset) -> Result<Option<Vec<(usize, usize)>>> {
    let meshes = dataset.len();
    if let Some(manifest) = PairsManifest::of(dataset)? {
        return Ok(Some(manifest.space.pairs(meshes)));
    }
    match crate::import::ImportManifest::of(dataset)? {
        Some(import) if import.pairs => {
            if meshes % 2 != 0 {
                return Err(DataError::format(
                    dataset.dir().join(crate::dataset::MANIFEST_FILE),
                    format!(
                        "records (source, target) pairs but the set holds {meshes} meshes, an \
                         odd number"
                    ),
                ));
            }
            Ok(Some((0..meshes / 2).map(|i| (2 * i, 2 * i + 1)).collect()))
        }
        _ => Ok(None),
    }
}

/// Reads a pairs dataset's [`PARAMS_FILE`].
///
/// # Errors
/// [`DataError::Files`] (`Io`) / [`DataError::Files`] (`Format`) naming the file.
pub fn read_params(dataset: &Dataset) -> Result<PairParams> {
    let path = dataset.dir().join(PARAMS_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, e))?;
    serde_json::from_str(&text).map_err(|e| DataError::format(&path, e.to_string()))
}

/// Generates shapes `shapes` of `seed` on `template` and writes them as a
/// pairs dataset folder `dir` (see the [module docs](self)), the manifest
/// recording the space, `frame` (the template's canonical frame) and the
/// seed, plus [`PARAMS_FILE`]. Shows a progress bar when `progress` is set.
///
/// # Errors
/// [`DataError::Config`] for no shapes; those of [`PairSpace::generate`]
/// and [`Dataset::write`].
#[allow(clippy::too_many_arguments)]
pub fn write_dataset(
    dir: &Path,
    template: &TriMesh,
    space: &PairSpace,
    seed: u64,
    shapes: Range<usize>,
    normalization: Normalization,
    frame: CanonicalFrame,
    mesh_role: &str,
    provenance: &str,
    progress: bool,
) -> Result<Dataset> {
    if shapes.is_empty() {
        return Err(DataError::Config(
            "a pairs dataset needs at least 1 shape".into(),
        ));
    }
    let bar = if progress {
        let bar = ProgressBar::new(shapes.len() as u64);
        bar.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} shapes ({eta} left)")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_prefix(format!(
            "{} poses per shape on {} vertices",
            space.poses_per_shape,
            template.num_vertices()
        ));
        bar
    } else {
        ProgressBar::hidden()
    };
    let first_shape = shapes.start;
    let (params, meshes) = space.generate(template, seed, shapes, |_| bar.inc(1))?;
    bar.finish_and_clear();
    let data: Vec<f32> = meshes
        .iter()
        .flat_map(|m| m.iter().flat_map(|p| p.map(|x| x as f32)))
        .collect();
    let signals = InMemorySignals::new(data, meshes.len(), template.num_vertices(), 3)?;
    let recorded = PairsManifest {
        space: space.clone(),
        first_shape,
        normalization,
        mesh_role: mesh_role.into(),
    };
    let manifest = Manifest::new(
        GENERATOR,
        serde_json::to_value(&recorded).map_err(|e| DataError::Config(e.to_string()))?,
    )
    .with_seed(seed)
    .with_provenance(provenance)
    .with_frame(frame);
    let dataset = Dataset::write(dir, template, &signals, manifest)?;
    let path = dataset.dir().join(PARAMS_FILE);
    mfm_files::write_json(&path, &params).map_err(|e| DataError::format(&path, e.to_string()))?;
    Ok(dataset)
}

//! The folder layout of an experiment: what `mfm dataset gmm`,
//! `mfm dataset deform` and `mfm dataset pairs` write, and where `mfm train`, `mfm eval` and the
//! xtask experiments find it.
//!
//! | entry | written by | what |
//! |---|---|---|
//! | [`TRAIN`] | both | the training set, a dataset folder on the training mesh |
//! | [`REFERENCE`] | both, when held-out signals are asked for | held-out signals on the evaluation mesh (another triangulation of the same surface) |
//! | [`HOLDOUT`] | deform, pairs | the same held-out parameters on the training mesh |
//! | [`TEST_MESH`] | gmm, without a reference set | the test mesh alone |
//! | `original.ply`, `coarse.ply`, `eval.ply` | deform, pairs | the normalized input, training and evaluation meshes ([`DEFORM_MESHES`]) |
//! | [`SPACE`] | deform | the deformation space ([`read_space`]) |
//! | [`PAIR_SPACE`] | pairs | the shape and pose space of a pairs experiment ([`read_pair_space`]) |
//! | [`PREVIEW`] | all | a picture of the first training signals ([`crate::pictures`]) |
//!
//! Held-out sets draw from [`held_out_seed`]`(seed)`, a different stream
//! than the training set's `seed`, so they are not copies of training
//! signals on another mesh. Every dataset of an experiment records the
//! canonical frame of the training mesh.
//!
//! # Example
//! ```
//! use mfm_data::experiment::GmmMeshes;
//! use mfm_data::gmm::{GenerateOptions, GmmConfig, GmmDistance};
//! use mfm_data::layout::{self, GmmExperiment};
//! use mfm_data::SignalSource;
//! use mfm_geometry::procedural;
//! let meshes = GmmMeshes::from_base(procedural::icosphere(2), Default::default()).unwrap();
//! let config = GmmConfig { distance: GmmDistance::Euclidean, ..GmmConfig::default() };
//! let dir = tempfile::tempdir().unwrap();
//! let experiment = GmmExperiment {
//!     config: &config,
//!     train_mesh: &meshes.train,
//!     test_mesh: &meshes.test,
//!     source: "icosphere(2)",
//!     train: 4,
//!     reference: 2,
//!     seed: 7,
//! };
//! let train = experiment.write(dir.path(), &GenerateOptions::default()).unwrap();
//! assert_eq!(train.len(), 4);
//! assert!(dir.path().join(layout::REFERENCE).join("manifest.json").is_file());
//! ```

use std::ops::Range;
use std::path::Path;

use mfm_deform::DeformSpace;
use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;

use crate::dataset::{Dataset, Manifest};
use crate::deformations::{self, DeformMeshes};
use crate::error::{DataError, Result};
use crate::gmm::{GenerateOptions, GmmConfig, GmmGenerator};
use crate::pairs::{self, PairSpace};
use crate::pictures;
use crate::signals::InMemorySignals;

/// The training set's folder.
pub const TRAIN: &str = mfm_files::owned::SETS[0];
/// The held-out set on the evaluation mesh.
pub const REFERENCE: &str = mfm_files::owned::SETS[1];
/// The held-out set on the training mesh (deformation experiments).
pub const HOLDOUT: &str = mfm_files::owned::SETS[2];
/// The test mesh of a GMM experiment written without a reference set.
pub const TEST_MESH: &str = "test_mesh.ply";
/// The deformation space of a deformation experiment.
pub const SPACE: &str = mfm_files::owned::SPACE;
/// The preview picture of the training signals.
pub const PREVIEW: &str = "preview.png";
/// The mesh files of a deformation experiment, by role.
pub const DEFORM_MESHES: [&str; 3] = ["original.ply", "coarse.ply", "eval.ply"];

/// Every entry an `mfm dataset` command (gmm, deform, pairs, import)
/// writes in its folder: what a killed one may have left there.
pub const EXPERIMENT_ENTRIES: [&str; 12] = [
    TRAIN,
    REFERENCE,
    HOLDOUT,
    TEST_MESH,
    SPACE,
    PAIR_SPACE,
    PREVIEW,
    DEFORM_MESHES[0],
    DEFORM_MESHES[1],
    DEFORM_MESHES[2],
    crate::import::TRANSFER,
    crate::import::SUMMARY,
];

/// The seed of an experiment's held-out sets, given the training seed.
pub fn held_out_seed(seed: u64) -> u64 {
    seed ^ 0x5eed_0f2e_f5e7
}

/// A GMM experiment: a training set on `train_mesh` and, when `reference >
/// 0`, a reference set on `test_mesh`.
#[derive(Clone, Copy, Debug)]
pub struct GmmExperiment<'a> {
    /// The generator's parameters.
    pub config: &'a GmmConfig,
    /// The training mesh (it fixes the canonical frame).
    pub train_mesh: &'a TriMesh,
    /// The test mesh: another triangulation of the same surface.
    pub test_mesh: &'a TriMesh,
    /// Where the meshes came from, for the manifests (`builtin:blob`, a path).
    pub source: &'a str,
    /// Number of training signals (at least 1).
    pub train: usize,
    /// Number of reference signals (0 writes [`TEST_MESH`] instead).
    pub reference: usize,
    /// The training seed.
    pub seed: u64,
}

impl GmmExperiment<'_> {
    /// Generates and writes the experiment into `out` (missing or empty),
    /// with [`PREVIEW`] of the first training signals; returns the training
    /// set. On failure, what it created is removed.
    ///
    /// Cost: one [`GmmGenerator`] per mesh (a factorization for geodesic
    /// distances), then `O(V)` per signal.
    ///
    /// # Errors
    /// [`mfm_files::FileError::NotEmpty`] for a folder with anything in it;
    /// [`DataError::Config`] for no training signals or invalid GMM
    /// parameters; the generator's, the dataset writer's and the picture's
    /// errors.
    pub fn write(&self, out: &Path, options: &GenerateOptions) -> Result<Dataset> {
        fill(
            out,
            || self.write_sets(out, options),
            |train, path| {
                pictures::signals(
                    self.train_mesh,
                    train,
                    "signal",
                    "GMM training signals",
                    path,
                )
            },
        )
    }

    fn write_sets(&self, out: &Path, options: &GenerateOptions) -> Result<Dataset> {
        self.config.validate()?;
        if self.train == 0 {
            return Err(DataError::Config(
                "a GMM experiment needs at least 1 training signal".into(),
            ));
        }
        let mut sets = vec![(TRAIN, self.train as u128, self.train_mesh.num_vertices())];
        if self.reference > 0 {
            sets.push((
                REFERENCE,
                self.reference as u128,
                self.test_mesh.num_vertices(),
            ));
        }
        refuse_oversized(out, &sets, 1, 4)?;
        let frame = CanonicalFrame::of(self.train_mesh).map_err(|e| DataError::MeshProcessing {
            what: format!(
                "placing the training mesh {} in the canonical frame",
                self.source
            ),
            source: Box::new(e),
        })?;
        let write = |dir: &Path, mesh: &TriMesh, n: usize, seed: u64, role: &str| {
            let generator = GmmGenerator::new(mesh, self.config)?;
            let signals = generator.generate_with(n, seed, options)?;
            let manifest = Manifest::new(crate::gmm::GENERATOR_NAME, self.config.manifest_params())
                .with_seed(seed)
                .with_provenance(format!("mfm dataset gmm: {role} set on {}", self.source))
                .with_frame(frame);
            Dataset::write(dir, mesh, &signals, manifest)
        };
        let train = write(
            &out.join(TRAIN),
            self.train_mesh,
            self.train,
            self.seed,
            "training",
        )?;
        if self.reference > 0 {
            write(
                &out.join(REFERENCE),
                self.test_mesh,
                self.reference,
                held_out_seed(self.seed),
                "reference",
            )?;
        } else {
            mfm_meshio::write_ply(out.join(TEST_MESH), self.test_mesh, &[])?;
        }
        Ok(train)
    }
}

/// A deformation experiment: training shapes on the coarse mesh, held-out
/// shapes on the evaluation mesh ([`REFERENCE`]) and on the coarse mesh
/// ([`HOLDOUT`]), the three meshes and the deformation space.
#[derive(Clone, Copy, Debug)]
pub struct DeformExperiment<'a> {
    /// The normalized, coarse and evaluation meshes.
    pub meshes: &'a DeformMeshes,
    /// The deformation space (handles on `meshes.original`, ranges).
    pub space: &'a DeformSpace,
    /// Where the mesh came from, for the manifests.
    pub source: &'a str,
    /// Number of training shapes (at least 1).
    pub train: usize,
    /// Number of held-out shapes (0 writes no held-out sets).
    pub reference: usize,
    /// The training seed.
    pub seed: u64,
    /// Whether to show progress bars.
    pub progress: bool,
}

impl DeformExperiment<'_> {
    /// Writes the meshes, the space, the datasets and [`PREVIEW`] (the rest
    /// shape and the first training shapes) into `out` (missing or empty);
    /// returns the training set. On failure, what it created is removed.
    ///
    /// Cost: one ARAP solve per shape, per mesh it is written on.
    ///
    /// # Errors
    /// [`mfm_files::FileError::NotEmpty`]; [`DataError::Config`] for no
    /// training shapes; the deformation, writing and picture errors.
    pub fn write(&self, out: &Path) -> Result<Dataset> {
        fill(
            out,
            || self.write_sets(out),
            |train, path| pictures::deform_preview(&self.meshes.coarse, train, path),
        )
    }

    fn write_sets(&self, out: &Path) -> Result<Dataset> {
        let m = self.meshes;
        let (train, held) = (self.train as u128, self.reference as u128);
        let (coarse, eval) = (m.coarse.num_vertices(), m.eval.num_vertices());
        let mut sets = vec![(TRAIN, train, coarse)];
        if held > 0 {
            sets.extend([(REFERENCE, held, eval), (HOLDOUT, held, coarse)]);
        }
        refuse_oversized(out, &sets, 3, SHAPE_BYTES)?;
        for (file, mesh) in DEFORM_MESHES.iter().zip([&m.original, &m.coarse, &m.eval]) {
            mfm_meshio::write_ply(out.join(file), mesh, &[])?;
        }
        write_space(&out.join(SPACE), self.space)?;
        let set =
            |dir: &str, mesh: &TriMesh, seed: u64, range: Range<usize>, role: &str, what: &str| {
                deformations::write_dataset(
                    &out.join(dir),
                    mesh,
                    self.space,
                    seed,
                    range,
                    m.normalization,
                    m.frame,
                    role,
                    &format!("mfm dataset deform: {what} of {}", self.source),
                    self.progress,
                )
            };
        let train = set(
            TRAIN,
            &m.coarse,
            self.seed,
            0..self.train,
            "coarse",
            "training shapes on the coarse mesh",
        )?;
        if self.reference > 0 {
            let held_out = held_out_seed(self.seed);
            set(
                REFERENCE,
                &m.eval,
                held_out,
                0..self.reference,
                "eval",
                "held-out shapes on the evaluation mesh",
            )?;
            set(
                HOLDOUT,
                &m.coarse,
                held_out,
                0..self.reference,
                "coarse",
                "held-out shapes on the coarse mesh",
            )?;
        }
        Ok(train)
    }
}

/// Bytes of memory per value of a generated shape: its `f64` position and
/// the `f32` copy that is written.
const SHAPE_BYTES: u128 = 12;

/// Refuses an experiment too large for this machine before anything is
/// generated or written: each of `sets` (folder, signals, vertices) of
/// `channels` is generated in memory, `bytes_per_value` bytes a value, one
/// set at a time, and all are written to `out` as `f32` `.npy` files.
///
/// # Errors
/// [`mfm_files::FileError::NoMemory`] naming the set, or
/// [`mfm_files::FileError::NoSpace`] for the disk.
fn refuse_oversized(
    out: &Path,
    sets: &[(&str, u128, usize)],
    channels: usize,
    bytes_per_value: u128,
) -> Result<()> {
    let mut disk = 0u128;
    for &(set, n, v) in sets {
        let values = n.saturating_mul(v as u128).saturating_mul(channels as u128);
        let what = format!(
            "the {set} set's {n} signals x {v} vertices x {channels} channel{}",
            if channels == 1 { "" } else { "s" }
        );
        mfm_files::space::ensure_memory(&what, values, bytes_per_value)?;
        disk = disk.saturating_add(values.saturating_mul(4));
    }
    mfm_files::space::ensure_space(out, u64::try_from(disk).unwrap_or(u64::MAX))?;
    Ok(())
}

/// Fills the experiment folder `out` (missing or empty) with `sets`, then
/// draws `preview` of the training set to [`PREVIEW`]; on any failure all
/// it wrote, and the folder if it created it, is removed
/// ([`mfm_files::Undo::empty_folder`]).
fn fill(
    out: &Path,
    sets: impl FnOnce() -> Result<Dataset>,
    preview: impl FnOnce(&InMemorySignals, &Path) -> Result<()>,
) -> Result<Dataset> {
    let undo = mfm_files::Undo::empty_folder(out)?;
    let train = sets()?;
    preview(&train.load_all()?, &out.join(PREVIEW))?;
    undo.keep();
    Ok(train)
}

/// Writes a deformation space as pretty JSON ([`SPACE`]), atomically.
///
/// # Errors
/// [`DataError::Files`] (`Io`) naming the file.
pub fn write_space(path: &Path, space: &DeformSpace) -> Result<()> {
    write_pretty(path, space)
}

/// Pretty JSON at `path`, atomically, with this crate's errors.
fn write_pretty(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    Ok(mfm_files::write_json(path, value)?)
}

/// Reads a deformation space ([`SPACE`] of a deformation experiment).
///
/// # Errors
/// [`DataError::Files`] (`Io`) if it cannot be read, [`DataError::Files`] (`Format`) if it is
/// not a deformation space.
pub fn read_space(path: &Path) -> Result<DeformSpace> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| {
        DataError::format(
            path,
            format!("not a deformation space (space.json of mfm dataset deform): {e}"),
        )
    })
}

/// The pair space of a pairs experiment ([`PairsExperiment`]).
pub const PAIR_SPACE: &str = mfm_files::owned::PAIR_SPACE;

/// A pairs experiment (`mfm dataset pairs`): posed shapes of a template for
/// the arbitrary-source model ([`crate::pairs`]).
///
/// [`TRAIN`] holds shapes `0..train` of `seed` on the coarse mesh;
/// [`HOLDOUT`] holds shapes `0..reference` of [`held_out_seed`]`(seed)` on
/// the coarse mesh (unseen body shapes, the training connectivity) and
/// [`REFERENCE`] the same held-out shapes on the evaluation mesh (unseen
/// shapes on another triangulation). The meshes are those of a deformation
/// experiment ([`DeformMeshes`]).
#[derive(Clone, Copy, Debug)]
pub struct PairsExperiment<'a> {
    /// The normalized, coarse and evaluation meshes.
    pub meshes: &'a DeformMeshes,
    /// The shape family and pose space (on `meshes.original`).
    pub space: &'a PairSpace,
    /// Where the mesh came from, for the manifests.
    pub source: &'a str,
    /// Number of training shapes (at least 1).
    pub train: usize,
    /// Number of held-out shapes (0 writes no held-out sets).
    pub reference: usize,
    /// The training seed.
    pub seed: u64,
    /// Whether to show progress bars.
    pub progress: bool,
}

impl PairsExperiment<'_> {
    /// Writes the meshes, the space, the datasets and [`PREVIEW`] (the poses
    /// of the first two shapes) into `out` (missing or empty); returns the
    /// training set. On failure, what it created is removed.
    ///
    /// Cost: per shape and mesh, one ARAP factorization and one solve per
    /// pose.
    ///
    /// # Errors
    /// [`mfm_files::FileError::NotEmpty`]; [`DataError::Config`] for no
    /// training shapes; the shape, pose, writing and picture errors.
    pub fn write(&self, out: &Path) -> Result<Dataset> {
        fill(
            out,
            || self.write_sets(out),
            |train, path| {
                pictures::pairs_preview(
                    &self.meshes.coarse,
                    train,
                    self.space.poses_per_shape,
                    path,
                )
            },
        )
    }

    fn write_sets(&self, out: &Path) -> Result<Dataset> {
        let m = self.meshes;
        let poses = self.space.poses_per_shape as u128;
        let train = (self.train as u128).saturating_mul(poses);
        let held = (self.reference as u128).saturating_mul(poses);
        let (coarse, eval) = (m.coarse.num_vertices(), m.eval.num_vertices());
        let mut sets = vec![(TRAIN, train, coarse)];
        if held > 0 {
            sets.extend([(HOLDOUT, held, coarse), (REFERENCE, held, eval)]);
        }
        refuse_oversized(out, &sets, 3, SHAPE_BYTES)?;
        for (file, mesh) in DEFORM_MESHES.iter().zip([&m.original, &m.coarse, &m.eval]) {
            mfm_meshio::write_ply(out.join(file), mesh, &[])?;
        }
        write_pretty(&out.join(PAIR_SPACE), self.space)?;
        let set =
            |dir: &str, mesh: &TriMesh, seed: u64, range: Range<usize>, role: &str, what: &str| {
                pairs::write_dataset(
                    &out.join(dir),
                    mesh,
                    self.space,
                    seed,
                    range,
                    m.normalization,
                    m.frame,
                    role,
                    &format!("mfm dataset pairs: {what} of {}", self.source),
                    self.progress,
                )
            };
        let train = set(
            TRAIN,
            &m.coarse,
            self.seed,
            0..self.train,
            "coarse",
            "training shapes on the coarse mesh",
        )?;
        if self.reference > 0 {
            let held_out = held_out_seed(self.seed);
            set(
                HOLDOUT,
                &m.coarse,
                held_out,
                0..self.reference,
                "coarse",
                "held-out shapes on the coarse mesh",
            )?;
            set(
                REFERENCE,
                &m.eval,
                held_out,
                0..self.reference,
                "eval",
                "held-out shapes on the evaluation mesh",
            )?;
        }
        Ok(train)
    }
}

/// Reads the pair space of a pairs experiment ([`PAIR_SPACE`]).
///
/// # Errors
/// [`DataError::Files`] (`Io`) if it cannot be read, [`DataError::Files`] (`Format`) if it is
/// not a pair space.
pub fn read_pair_space(path: &Path) -> Result<PairSpace> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let space: PairSpace = serde_json::from_str(&text).map_err(|e| {
        DataError::format(
            path,
            format!("not a pair space ({PAIR_SPACE} of mfm dataset pairs): {e}"),
        )
    })?;
    space.validate()?;
    Ok(space)
}

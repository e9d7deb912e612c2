//! The error type of every fallible entry point of the crate.

use std::path::PathBuf;

/// Everything that can go wrong training, sampling, or reading and writing
/// runs and checkpoints; dataset and metric errors arrive as
/// [`FmError::Data`].
///
/// Variants that concern a file name it, so a user can tell which of their
/// files is at fault.
#[derive(Debug, thiserror::Error)]
pub enum FmError {
    /// Two sizes that must agree do not.
    #[error("size mismatch: {what} has {found}, expected {expected}")]
    SizeMismatch {
        /// What was measured.
        what: String,
        /// The size implied by the other inputs.
        expected: usize,
        /// The size found.
        found: usize,
    },
    /// An invalid parameter or configuration value.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A run folder cannot do what was asked (it holds no run, its dataset
    /// is gone); the message says what to do instead.
    #[error("{0}")]
    RunFolder(String),
    /// A numerical breakdown: sampling whose state or network output stopped
    /// being finite, or a model whose weights are not finite.
    #[error("{0}")]
    Diverged(String),
    /// A mesh could not be read.
    #[error(transparent)]
    ReadMesh(#[from] mfm_meshio::ReadError),
    /// A mesh could not be written.
    #[error(transparent)]
    WriteMesh(#[from] mfm_meshio::WriteError),
    /// A mesh could not be built or processed (procedural construction,
    /// refinement, decimation), e.g. for an experiment's train/test meshes.
    #[error("{what}: {source}")]
    MeshProcessing {
        /// The step that failed.
        what: String,
        /// The geometry crate's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The mesh operators could not be built.
    #[error("mesh operators: {0}")]
    Operators(#[from] mfm_geometry::operators::OperatorError),
    /// A sparse factorization or solve failed.
    #[error("solver: {0}")]
    Solver(#[from] mfm_solver::SolverError),
    /// Generating, fitting or projecting a deformation failed.
    #[error("deformation: {0}")]
    Deform(#[from] mfm_deform::DeformError),
    /// Noise sampling failed.
    #[error("noise: {0}")]
    Noise(#[from] mfm_noise::NoiseError),
    /// The network failed (shape, libtorch, save/load).
    #[error("network: {0}")]
    Net(#[from] mfm_net::NetError),
    /// An error reported by libtorch outside the network.
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    /// A dataset, signal or metric error ([`mfm_data`]).
    #[error(transparent)]
    Data(#[from] mfm_data::DataError),
    /// A file could not be read or written, or its contents are not what
    /// they should be (truncated, corrupted, wrong shape, wrong version),
    /// naming the file ([`mfm_files::FileError`]: the one I/O and format
    /// error of every mfm crate).
    #[error(transparent)]
    Files(#[from] mfm_files::FileError),
}

/// A kernel error (the mesh tensors, a solve) is a network error
/// ([`mfm_net::NetError::Kernel`]), so it reads "network: ..." like the
/// other failures of the network.
impl From<mfm_net::KernelError> for FmError {
    fn from(e: mfm_net::KernelError) -> Self {
        Self::Net(e.into())
    }
}

/// The training loop's errors ([`mfm_train::TrainError`]) become the
/// variants of the same name and message.
impl From<mfm_train::TrainError> for FmError {
    fn from(e: mfm_train::TrainError) -> Self {
        use mfm_train::TrainError as T;
        match e {
            T::Config(m) => Self::Config(m),
            T::RunFolder(m) => Self::RunFolder(m),
            T::Diverged(m) => Self::Diverged(m),
            T::Net(e) => Self::Net(e),
            T::Torch(e) => Self::Torch(e),
            T::Files(e) => Self::Files(e),
        }
    }
}

/// What the training loop tells a diverged step from a broken one by.
impl mfm_train::StepError for FmError {
    fn is_numerical(&self) -> bool {
        matches!(self, Self::Net(_) | Self::Torch(_))
    }

    fn reports_non_finite(&self) -> bool {
        match self {
            Self::Net(e) => e.reports_non_finite(),
            Self::Torch(e) => mfm_net::error::torch_reports_non_finite(e),
            Self::Solver(e) => e.is_non_finite(),
            _ => false,
        }
    }
}

impl FmError {
    /// An operating-system error on `path`: [`FmError::Files`] holding
    /// [`mfm_files::FileError::Io`], the one I/O error of every mfm crate.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Files(mfm_files::FileError::io(path, source))
    }

    /// A file whose contents are not what they should be (truncated,
    /// corrupted, wrong shape, wrong version): [`FmError::Files`] holding
    /// [`mfm_files::FileError::Format`].
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Files(mfm_files::FileError::format(path, message))
    }
}

/// `Result` with [`FmError`].
pub type Result<T, E = FmError> = std::result::Result<T, E>;

//! The error of the network: the kernels' errors under it, and what only a
//! network has (its configuration, its weights and configuration files).

use std::path::PathBuf;

pub use mfm_kernels::error::{KernelError, torch_reports_non_finite};

/// Everything that can go wrong building, running, saving or loading a
/// PoissonNet.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// A kernel, a mesh operator or libtorch failed, or a tensor does not
    /// fit the operation ([`KernelError`], shown as it is).
    #[error(transparent)]
    Kernel(#[from] KernelError),
    /// An invalid configuration value.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A configuration file could not be parsed or written.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The JSON error.
        source: serde_json::Error,
    },
    /// A weights file does not match the network it is loaded into.
    #[error("weights file {path} does not match the network: {detail}")]
    WeightsMismatch {
        /// The weights file.
        path: PathBuf,
        /// What differs (names, shapes or configuration fields).
        detail: String,
    },
}

/// A libtorch error is a kernel error ([`KernelError::Torch`]), so the
/// network and the kernels report it the same way.
impl From<tch::TchError> for NetError {
    fn from(e: tch::TchError) -> Self {
        Self::Kernel(KernelError::Torch(e))
    }
}

/// Result alias of this crate.
pub type Result<T, E = NetError> = std::result::Result<T, E>;

impl NetError {
    /// Whether this error reports a NaN or infinity reaching one of the
    /// network's Poisson solves ([`KernelError::reports_non_finite`]): what
    /// a diverged network's overflowing values cause.
    pub fn reports_non_finite(&self) -> bool {
        match self {
            Self::Kernel(e) => e.reports_non_finite(),
            _ => false,
        }
    }
}

/// [`mfm_kernels::error::shape_error`] as a [`NetError`]: `what`, the
/// expected shape in words and `t`'s actual shape.
pub fn shape_error(
    what: impl Into<String>,
    expected: impl Into<String>,
    t: &tch::Tensor,
) -> NetError {
    mfm_kernels::error::shape_error(what, expected, t).into()
}

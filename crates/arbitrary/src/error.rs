//! The error of the arbitrary-source model: what only it can get wrong
//! (a dataset that is not pairs, a source mesh it cannot take, a predictor
//! of another template), beside the flow crate's errors (files, network,
//! noise, data), which it carries as they are.

use mfm_fm::FmError;

/// Everything that can go wrong training, sampling or evaluating an
/// arbitrary-source model. Messages name the file, folder or mesh at
/// fault.
#[derive(Debug, thiserror::Error)]
pub enum ArbitraryError {
    /// An invalid configuration value (a preset name, a schedule field).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A dataset that does not fit what was asked of it (not a pairs
    /// dataset, no pairs, not shapes, a template too coarse).
    #[error("{0}")]
    Dataset(String),
    /// A source mesh the model cannot take (another vertex count,
    /// non-finite or degenerate positions).
    #[error("{0}")]
    Source(String),
    /// Two parts of a run that must agree do not: a predictor of another
    /// template or frame, a stored configuration, an experiment of another
    /// template.
    #[error("{0}")]
    Mismatch(String),
    /// A run folder that cannot do what was asked (no finished model, a
    /// model imported from the authors' code, a flow without a predictor).
    #[error("{0}")]
    RunFolder(String),
    /// An error of the flow crate: files, network, noise, data, the
    /// training loop.
    #[error(transparent)]
    Fm(#[from] FmError),
}

/// The errors the flow crate turns into [`FmError`] become
/// [`ArbitraryError::Fm`] the same way.
macro_rules! through_fm {
    ($($t:ty),* $(,)?) => {
        $(impl From<$t> for ArbitraryError {
            fn from(e: $t) -> Self {
                Self::Fm(FmError::from(e))
            }
        })*
    };
}

through_fm!(
    tch::TchError,
    mfm_net::NetError,
    mfm_net::KernelError,
    mfm_data::DataError,
    mfm_files::FileError,
    mfm_noise::NoiseError,
    mfm_solver::SolverError,
    mfm_geometry::operators::OperatorError,
    mfm_meshio::ReadError,
    mfm_meshio::WriteError,
    mfm_deform::DeformError,
    mfm_train::TrainError,
);

impl ArbitraryError {
    /// An operating-system error on `path` ([`FmError::io`]).
    pub fn io(path: impl Into<std::path::PathBuf>, source: std::io::Error) -> Self {
        Self::Fm(FmError::io(path, source))
    }

    /// A file whose contents are not what they should be
    /// ([`FmError::format`]).
    pub fn format(path: impl Into<std::path::PathBuf>, message: impl Into<String>) -> Self {
        Self::Fm(FmError::format(path, message))
    }
}

/// What the training loop tells a diverged step from a broken one by.
impl mfm_train::StepError for ArbitraryError {
    fn is_numerical(&self) -> bool {
        matches!(self, Self::Fm(e) if mfm_train::StepError::is_numerical(e))
    }

    fn reports_non_finite(&self) -> bool {
        matches!(self, Self::Fm(e) if mfm_train::StepError::reports_non_finite(e))
    }
}

/// `Result` with [`ArbitraryError`].
pub type Result<T, E = ArbitraryError> = std::result::Result<T, E>;

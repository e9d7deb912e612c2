//! The error type of the training loop and its checkpoints.

use std::path::PathBuf;

/// What can go wrong in the loop shared by every training: an invalid
/// setting, a diverged run, the network or libtorch, a run folder that
/// cannot be resumed, or a file (named).
///
/// The crates that train (`mfm-fm`, `mfm-arbitrary`) turn each variant into
/// their own variant of the same name and message.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// An invalid setting, or a run description edited since its checkpoint.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A run folder cannot do what was asked; the message says what to do
    /// instead.
    #[error("{0}")]
    RunFolder(String),
    /// The loss or the weights stopped being finite.
    #[error("{0}")]
    Diverged(String),
    /// The network failed (shape, libtorch, save/load).
    #[error("network: {0}")]
    Net(#[from] mfm_net::NetError),
    /// An error reported by libtorch outside the network.
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    /// A file could not be read or written, or its contents are not what
    /// they should be, naming the file ([`mfm_files::FileError`]).
    #[error(transparent)]
    Files(#[from] mfm_files::FileError),
}

impl TrainError {
    /// An operating-system error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Files(mfm_files::FileError::io(path, source))
    }

    /// A file whose contents are not what they should be.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Files(mfm_files::FileError::format(path, message))
    }
}

/// `Result` with [`TrainError`].
pub type Result<T, E = TrainError> = std::result::Result<T, E>;

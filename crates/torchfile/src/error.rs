//! The errors of reading and writing checkpoint files.

use std::path::PathBuf;

/// What can go wrong reading or writing a PyTorch checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum TorchFileError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
    /// The file is not a `torch.save` zip archive, or a record of it is
    /// missing or damaged.
    #[error("{path}: {message}")]
    Archive {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The pickle program is malformed or uses what the reader refuses.
    #[error("pickle, byte {offset}: {message}")]
    Pickle {
        /// Byte offset of the opcode.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// An entry of the checkpoint is not what it must be (an object the
    /// reader does not build, a tensor that does not fit its storage...).
    #[error("{path}: entry {entry}: {message}")]
    Entry {
        /// The file.
        path: PathBuf,
        /// The entry's path inside the checkpoint (`state_dict.base_model.proj_in.weight`).
        entry: String,
        /// What is wrong.
        message: String,
    },
}

impl TorchFileError {
    /// The message without the file's name, for a caller whose own error
    /// names the file (so that it is not printed twice).
    pub fn without_path(&self) -> String {
        match self {
            Self::Io { source, .. } => source.to_string(),
            Self::Archive { message, .. } => message.clone(),
            Self::Pickle { .. } => self.to_string(),
            Self::Entry { entry, message, .. } => format!("entry {entry}: {message}"),
        }
    }
}

/// Result of this crate.
pub type Result<T> = std::result::Result<T, TorchFileError>;

//! The error type of this crate.

use std::path::PathBuf;

/// Why a file could not be read or written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// An operating-system error on `path`.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The output exists and is not a regular file.
    #[error(
        "{} is {kind}, not a regular file; mfm writes only regular files (nothing was written)",
        path.display()
    )]
    NotRegular {
        /// The output path as given.
        path: PathBuf,
        /// What it is: "a folder", "a device", "a FIFO", "a socket".
        kind: &'static str,
    },
    /// An output is one of the command's inputs.
    #[error(
        "{}{} is also an input of this command; choose another output (nothing was written)",
        output.display(),
        if output == input { String::new() } else { format!(" (the same file as {})", input.display()) }
    )]
    OutputIsInput {
        /// The output as given.
        output: PathBuf,
        /// The input as given.
        input: PathBuf,
    },
    /// An output would go into a folder another mfm command owns (a
    /// dataset, an experiment, a training run; [`crate::owned`]).
    #[error(
        "{} would be written into {}, {kind} (it holds {marker}); mfm never writes into a \
         dataset, experiment or run folder but its own: choose an output outside it (nothing \
         was written)",
        path.display(), folder.display()
    )]
    InsideOwnedFolder {
        /// The output as given.
        path: PathBuf,
        /// The owned folder.
        folder: PathBuf,
        /// What the folder is ("a dataset folder").
        kind: &'static str,
        /// The entry that shows it.
        marker: String,
    },
    /// An input is not a regular file.
    #[error(
        "{} is {kind}, not a regular file; mfm reads its inputs from regular files only",
        path.display()
    )]
    InputNotRegular {
        /// The input as given.
        path: PathBuf,
        /// What it is: "a folder", "a device", "a FIFO", "a socket".
        kind: &'static str,
    },
    /// An output folder's path holds a file (or anything but a folder).
    #[error(
        "{} exists and is not a folder; this command writes a folder of files there: choose \
         another path (nothing was written)",
        path.display()
    )]
    NotAFolder {
        /// The path as given.
        path: PathBuf,
    },
    /// A file a command writes without the user naming it exists.
    #[error(
        "{} exists, and this command would replace it without being asked (a summary or plot \
         written beside its output); move it, or choose another output (nothing was written)",
        path.display()
    )]
    ImplicitExists {
        /// The file.
        path: PathBuf,
    },
    /// An output lies inside an input folder.
    #[error(
        "{} is inside the input folder {}; choose an output outside it (nothing was written)",
        output.display(), input.display()
    )]
    OutputInsideInput {
        /// The output as given.
        output: PathBuf,
        /// The input folder as given.
        input: PathBuf,
    },
    /// Two outputs of one command are the same file.
    #[error(
        "{} and {} are the same file; give each output its own path (nothing was written)",
        first.display(), second.display()
    )]
    SameOutput {
        /// The first output as given.
        first: PathBuf,
        /// The second output as given.
        second: PathBuf,
    },
    /// The output needs more space than its file system has free.
    #[error(
        "{}: disk full: the output needs {}, and mfm leaves {} free beside it (1% of the free \
         space, at least 16 MiB); only {} are free there (nothing was written)",
        path.display(), crate::space::human_bytes(*needed), crate::space::human_bytes(*margin),
        crate::space::human_bytes(*available)
    )]
    NoSpace {
        /// The output.
        path: PathBuf,
        /// Bytes the output needs.
        needed: u64,
        /// Bytes left free beside it ([`crate::space::margin`]).
        margin: u64,
        /// Bytes free on its file system.
        available: u64,
    },
    /// A request needs more memory than the machine has available.
    #[error(
        "{what}: needs {} of memory, but this machine has {} available; ask for fewer (nothing was written)",
        crate::space::human_bytes(*needed), crate::space::human_bytes(*available)
    )]
    NoMemory {
        /// What needs the memory, in words ("1000000000 signals x 162
        /// vertices x 1 channel of f32").
        what: String,
        /// Bytes needed (saturated at `u64::MAX`).
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// An output folder exists and is not empty.
    #[error(
        "{} exists and is not empty; choose another --out (nothing was overwritten)",
        path.display()
    )]
    NotEmpty {
        /// The folder as given.
        path: PathBuf,
    },
    /// Another process holds the folder's lock ([`crate::FolderLock`]).
    #[error(
        "{} is in use by {holder}; wait for it to finish (or stop it) and run again (nothing was written)",
        path.display()
    )]
    Locked {
        /// The folder as given.
        path: PathBuf,
        /// Who holds it: `PID N (command)`.
        holder: String,
    },
    /// A file's contents are not what was expected.
    #[error("{}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, with numbers.
        message: String,
    },
}

impl FileError {
    /// [`FileError::Io`] on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// [`FileError::Format`] on `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}

//! File output for mfm that never loses a user's data, and `.npy` input
//! that never trusts its header.
//!
//! - [`atomic`]: [`AtomicFile`] and [`write_atomic`] (and [`write_json`]
//!   on top of it), the one way mfm writes
//!   a file: an exclusive temporary file in the target's folder, synced, then
//!   renamed over the target; removed again on any failure. Existing targets
//!   that are not regular files (folders, devices, FIFOs, sockets) are
//!   refused; a symbolic link is followed and its target written, the link
//!   itself stays.
//! - [`guard`]: [`Outputs`], the check a command runs before it writes
//!   anything: no output may be one of the command's inputs, lie inside an
//!   input folder, or be another output of the same command.
//! - [`undo`]: [`Undo`], which removes what a failed command created (and
//!   only that); [`Outputs::prepare`] checks a command's outputs and returns
//!   the [`Undo`] for them.
//! - [`lock`]: [`FolderLock`], one writer per run, dataset or sample
//!   folder (an advisory lock beside it, naming its holder).
//! - [`matrix_market`]: sparse matrices as Matrix Market coordinate files.
//! - [`space`]: free space on the file system of a path.
//! - [`npy`]: reading `.npy` arrays (shape checked against the file's length
//!   before anything is allocated) and writing them, also in streamed
//!   batches for outputs larger than memory.
//! - [`run_folder`]: what a training run folder holds as plain files (its
//!   checkpoints, their `state.json`, the log), for readers without the
//!   training crates.
//! - [`text`]: [`fmt_f64`], how every number mfm writes as text is formatted
//!   (shortest digits that parse back to the same bits).
//!
//! Nothing here depends on meshes or networks; every mfm crate that writes
//! files uses it.

pub mod atomic;
pub mod error;
pub mod guard;
pub mod interrupt;
pub mod lock;
pub mod matrix_market;
pub mod npy;
pub mod owned;
pub mod run_folder;
pub mod space;
pub mod text;
pub mod undo;

pub use atomic::{AtomicFile, open_regular, read_regular, write_atomic, write_json};
pub use error::FileError;
pub use guard::{Outputs, ensure_empty_dir};
pub use lock::FolderLock;
pub use text::fmt_f64;
pub use undo::Undo;

//! The output guard every command runs before it writes
//! ([`mfm_files::Outputs::prepare`]).

use anyhow::Result;
use std::path::{Path, PathBuf};

pub use mfm_files::ensure_empty_dir as ensure_empty;

/// Refuses outputs that are inputs, lie in an input folder, name one file
/// twice or are not regular files, creates the outputs' folders, and
/// returns the [`mfm_files::Undo`] of what the command creates.
pub fn prepare_outputs(inputs: &[Option<&Path>], outputs: &[PathBuf]) -> Result<mfm_files::Undo> {
    let guard = mfm_files::Outputs::new().inputs(inputs.iter().flatten());
    Ok(guard.outputs(outputs).prepare()?)
}

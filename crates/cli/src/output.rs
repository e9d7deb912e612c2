//! Writing results: Matrix Market, NumPy `.npy` and JSON, each through
//! [`mfm_files::write_atomic`] (a temporary file in the target folder,
//! synced, renamed into place; folders, devices and FIFOs refused, links
//! followed), so a failed run never leaves a half-written file where a good
//! one was.

use anyhow::{Context, Result, bail};
use faer::sparse::SparseColMat;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes what `fill` produces to `path` atomically, creating the folder.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    create_parent(path)?;
    Ok(mfm_files::write_atomic(path, fill)?)
}

/// Creates the folder `path` will be written into.
pub fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create folder {}", dir.display()))?;
    }
    Ok(())
}

/// Writes a sparse matrix in Matrix Market coordinate format (1-based,
/// general, real), every stored entry, full `f64` precision.
pub fn write_matrix_market(path: &Path, m: &SparseColMat<usize, f64>) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "%%MatrixMarket matrix coordinate real general")?;
        writeln!(w, "% written by mfm {}", env!("CARGO_PKG_VERSION"))?;
        let col_ptr = m.symbolic().col_ptr();
        let row_idx = m.symbolic().row_idx();
        let val = m.val();
        writeln!(w, "{} {} {}", m.nrows(), m.ncols(), val.len())?;
        for j in 0..m.ncols() {
            for k in col_ptr[j]..col_ptr[j + 1] {
                writeln!(w, "{} {} {:e}", row_idx[k] + 1, j + 1, val[k])?;
            }
        }
        Ok(())
    })
}

/// Writes `data` (row-major, `shape`) as a little-endian `f64` `.npy` file.
pub fn write_npy(path: &Path, data: &[f64], shape: &[u64]) -> Result<()> {
    create_parent(path)?;
    Ok(mfm_files::npy::write(path, data, shape)?)
}

/// Writes pretty JSON ([`mfm_files::write_json`]), creating the folder.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    create_parent(path)?;
    Ok(mfm_files::write_json(path, value)?)
}

/// Before a command writes anything: refuses outputs that are inputs, lie
/// in an input folder, name one file twice or are not regular files
/// ([`mfm_files::Outputs`]), creates the outputs' folders, and returns an
/// [`mfm_files::Undo`] that removes the folders and files the command
/// creates unless it succeeds (`undo.keep()`).
pub fn prepare_outputs(inputs: &[Option<&Path>], outputs: &[PathBuf]) -> Result<mfm_files::Undo> {
    let mut guard = mfm_files::Outputs::new();
    for input in inputs.iter().flatten() {
        guard = guard.input(input);
    }
    for out in outputs {
        guard = guard.output(out);
    }
    guard.check()?;
    let mut undo = mfm_files::Undo::new();
    for out in outputs {
        if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            undo.create_dir_all(dir)?;
        }
        undo.file(out);
    }
    Ok(undo)
}

/// Refuses a non-empty folder `dir` (a missing or empty one is fine).
pub fn ensure_empty(dir: &Path) -> Result<()> {
    if let Ok(mut entries) = std::fs::read_dir(dir)
        && entries.next().is_some()
    {
        bail!(
            "{} exists and is not empty; choose another --out (nothing was overwritten)",
            dir.display()
        );
    }
    Ok(())
}

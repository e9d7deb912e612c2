//! Writing results: Matrix Market, NumPy `.npy` and JSON, each atomically
//! (a temporary file in the target folder, renamed into place), so a failed
//! run never leaves a half-written file where a good one was.

use anyhow::{Context, Result};
use faer::sparse::SparseColMat;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `bytes` produced by `fill` to `path` atomically.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create folder {}", dir.display()))?;
    let name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| -> std::io::Result<()> {
        let file = std::fs::File::create(&tmp)?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        w.flush()?;
        w.get_ref().sync_all()?;
        Ok(())
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("cannot write {}", path.display()));
    }
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot move the finished file to {}", path.display()))
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
    anyhow::ensure!(
        shape.iter().product::<u64>() == data.len() as u64,
        "internal error: shape {shape:?} does not match {} values",
        data.len()
    );
    write_atomic(path, |w| {
        use npyz::WriterBuilder;
        let mut npy = npyz::WriteOptions::new()
            .default_dtype()
            .shape(shape)
            .writer(w)
            .begin_nd()?;
        npy.extend(data.iter().copied())?;
        npy.finish()
    })
}

/// Writes pretty JSON.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })
}

//! Sparse matrices as Matrix Market coordinate files (the format scipy's
//! `mmread` and MATLAB read).

use crate::atomic::write_atomic;
use crate::error::FileError;
use std::path::Path;

/// A compressed-sparse-column matrix, borrowed: column `j`'s entries are
/// `row_idx[col_ptr[j]..col_ptr[j + 1]]` with values `val[..]` at the same
/// positions (faer's and scipy's CSC layout, 0-based).
#[derive(Clone, Copy, Debug)]
pub struct CscView<'a> {
    /// Rows.
    pub nrows: usize,
    /// Columns.
    pub ncols: usize,
    /// `ncols + 1` offsets into `row_idx` and `val`.
    pub col_ptr: &'a [usize],
    /// Row of each stored entry.
    pub row_idx: &'a [usize],
    /// Value of each stored entry.
    pub val: &'a [f64],
}

/// Writes `m` atomically ([`write_atomic`]) as a Matrix Market
/// `coordinate real general` file: 1-based indices, every stored entry
/// (explicit zeros included) column by column, `f64` values in `{:e}`
/// notation (shortest digits that parse back to the same bits).
///
/// # Errors
/// [`FileError::Format`] when the view is inconsistent (offsets not
/// `ncols + 1`, not ascending, or past the entries; a row out of range);
/// the errors of [`write_atomic`].
///
/// # Example
/// ```
/// use mfm_files::matrix_market::{CscView, write};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("m.mtx");
/// // [[2, 0], [-1, 0.5]]
/// let m = CscView { nrows: 2, ncols: 2, col_ptr: &[0, 2, 3], row_idx: &[0, 1, 1], val: &[2.0, -1.0, 0.5] };
/// write(&path, m, "example").unwrap();
/// let text = std::fs::read_to_string(&path).unwrap();
/// assert!(text.starts_with("%%MatrixMarket matrix coordinate real general\n% example\n2 2 3\n1 1 2e0\n"));
/// ```
pub fn write(path: &Path, m: CscView<'_>, comment: &str) -> Result<(), FileError> {
    let bad = |what: String| Err(FileError::format(path, format!("not a CSC matrix: {what}")));
    if m.col_ptr.len() != m.ncols + 1 {
        return bad(format!(
            "{} column offsets for {} columns",
            m.col_ptr.len(),
            m.ncols
        ));
    }
    let nnz = m.col_ptr[m.ncols];
    if m.col_ptr.windows(2).any(|w| w[0] > w[1]) || nnz > m.row_idx.len() || nnz > m.val.len() {
        return bad("offsets not ascending or past the entries".to_owned());
    }
    if let Some(r) = m.row_idx[..nnz].iter().find(|&&r| r >= m.nrows) {
        return bad(format!("row {r} of a {}-row matrix", m.nrows));
    }
    write_atomic(path, |w| {
        writeln!(w, "%%MatrixMarket matrix coordinate real general")?;
        for line in comment.lines() {
            writeln!(w, "% {line}")?;
        }
        writeln!(w, "{} {} {nnz}", m.nrows, m.ncols)?;
        for j in 0..m.ncols {
            for k in m.col_ptr[j]..m.col_ptr[j + 1] {
                writeln!(w, "{} {} {:e}", m.row_idx[k] + 1, j + 1, m.val[k])?;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn entries_round_trip_through_the_text() -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("m.mtx");
        let val = [0.1, -3.0e-300, 7.0, 0.0];
        let m = CscView {
            nrows: 3,
            ncols: 3,
            col_ptr: &[0, 1, 1, 4],
            row_idx: &[2, 0, 1, 2],
            val: &val,
        };
        write(&path, m, "a\nb")?;
        let text = std::fs::read_to_string(&path)?;
        let mut lines = text.lines();
        assert_eq!(
            lines.next(),
            Some("%%MatrixMarket matrix coordinate real general")
        );
        assert_eq!(lines.next(), Some("% a"));
        assert_eq!(lines.next(), Some("% b"));
        assert_eq!(lines.next(), Some("3 3 4"));
        let entries: Vec<(usize, usize, f64)> = lines
            .map(|l| {
                let f: Vec<&str> = l.split(' ').collect();
                (
                    f[0].parse().unwrap_or(0),
                    f[1].parse().unwrap_or(0),
                    f[2].parse().unwrap_or(f64::NAN),
                )
            })
            .collect();
        assert_eq!(
            entries,
            vec![(3, 1, 0.1), (1, 3, -3.0e-300), (2, 3, 7.0), (3, 3, 0.0)]
        );
        Ok(())
    }

    #[test]
    fn an_inconsistent_view_is_refused_and_nothing_written()
    -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("m.mtx");
        let m = CscView {
            nrows: 1,
            ncols: 1,
            col_ptr: &[0, 1],
            row_idx: &[1],
            val: &[1.0],
        };
        let e = write(&path, m, "").map(|_| ()).unwrap_err();
        assert!(e.to_string().contains("row 1 of a 1-row matrix"), "{e}");
        let m = CscView {
            nrows: 1,
            ncols: 2,
            col_ptr: &[0, 1],
            row_idx: &[0],
            val: &[1.0],
        };
        assert!(write(&path, m, "").is_err());
        assert!(!path.exists());
        Ok(())
    }
}

//! Input validation and the canonical lower-triangular pattern the Cholesky
//! cache works on (crate-internal).

use faer::MatRef;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

use crate::error::{Result, SolverError};

/// Checks that `a` is square and returns its dimension.
pub(crate) fn check_square(nrows: usize, ncols: usize) -> Result<usize> {
    if nrows == ncols {
        Ok(nrows)
    } else {
        Err(SolverError::NotSquare { nrows, ncols })
    }
}

/// Checks that every stored value of `a` is finite.
pub(crate) fn check_finite_matrix(
    a: SparseColMatRef<'_, usize, f64>,
    what: &'static str,
) -> Result<()> {
    for j in 0..a.ncols() {
        for (i, &v) in a.row_idx_of_col(j).zip(a.val_of_col(j)) {
            if !v.is_finite() {
                return Err(SolverError::NonFinite {
                    what,
                    row: i,
                    col: j,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

/// Checks the length of a vector and that its entries are finite.
pub(crate) fn check_vector(v: &[f64], n: usize, what: &'static str) -> Result<()> {
    if v.len() != n {
        return Err(SolverError::SizeMismatch {
            what,
            expected: n,
            found: v.len(),
        });
    }
    if let Some((i, &x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(SolverError::NonFinite {
            what,
            row: i,
            col: 0,
            value: x,
        });
    }
    Ok(())
}

/// Checks a lumped mass: length `n`, finite, strictly positive.
pub(crate) fn check_mass(mass: &[f64], n: usize) -> Result<()> {
    check_vector(mass, n, "mass")?;
    if let Some((i, &m)) = mass.iter().enumerate().find(|(_, m)| **m <= 0.0) {
        return Err(SolverError::NonPositiveMass { index: i, value: m });
    }
    Ok(())
}

/// Checks the row count of a dense block and that its entries are finite.
pub(crate) fn check_block<T: Copy + Into<f64>>(
    b: MatRef<'_, T>,
    n: usize,
    what: &'static str,
) -> Result<()> {
    if b.nrows() != n {
        return Err(SolverError::SizeMismatch {
            what,
            expected: n,
            found: b.nrows(),
        });
    }
    let bad = |i: usize, j: usize| -> Result<()> {
        let v: f64 = b[(i, j)].into();
        if v.is_finite() {
            Ok(())
        } else {
            Err(SolverError::NonFinite {
                what,
                row: i,
                col: j,
                value: v,
            })
        }
    };
    // walk the block in memory order (rows first for a row-major block)
    if b.col_stride() == 1 && b.row_stride() != 1 {
        for i in 0..n {
            for j in 0..b.ncols() {
                bad(i, j)?;
            }
        }
    } else {
        for j in 0..b.ncols() {
            for i in 0..n {
                bad(i, j)?;
            }
        }
    }
    Ok(())
}

/// Checks that a scalar parameter is finite and strictly positive.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SolverError::InvalidParameter {
            name,
            expected: "a finite number > 0",
            value,
        })
    }
}

/// The lower triangle (diagonal included) of a symmetric sparsity pattern in
/// compressed-column form: rows sorted ascending within each column, no
/// duplicates, and the diagonal always stored (first in its column).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct LowerPattern {
    pub(crate) n: usize,
    pub(crate) col_ptr: Vec<usize>,
    pub(crate) row_idx: Vec<usize>,
}

impl LowerPattern {
    /// Pattern of the lower triangle of `a` (entries with `row >= col`), plus
    /// the diagonal. Upper entries are ignored. `O(nnz log(nnz per column))`.
    pub(crate) fn from_matrix(a: SymbolicSparseColMatRef<'_, usize>) -> Self {
        let n = a.ncols();
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(a.compute_nnz() / 2 + n);
        col_ptr.push(0);
        for j in 0..n {
            let start = row_idx.len();
            row_idx.push(j);
            row_idx.extend(a.row_idx_of_col(j).filter(|&i| i > j));
            row_idx[start..].sort_unstable();
            // drop duplicates (an input may list an entry twice; values are summed later)
            let mut w = start;
            for r in start..row_idx.len() {
                if r == start || row_idx[r] != row_idx[w - 1] {
                    row_idx[w] = row_idx[r];
                    w += 1;
                }
            }
            row_idx.truncate(w);
            col_ptr.push(row_idx.len());
        }
        Self {
            n,
            col_ptr,
            row_idx,
        }
    }

    /// Number of stored entries.
    pub(crate) fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Position of the diagonal entry of column `j` in the value array.
    pub(crate) fn diag_pos(&self, j: usize) -> usize {
        self.col_ptr[j]
    }

    /// faer view of the pattern.
    pub(crate) fn symbolic(&self) -> SymbolicSparseColMatRef<'_, usize> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// Values of the lower triangle of `a` laid out on this pattern (entries
    /// of the pattern absent from `a` are zero; duplicates are summed).
    ///
    /// Fails with [`SolverError::PatternMismatch`] when `a` has a lower entry
    /// outside the pattern.
    pub(crate) fn gather_values(&self, a: SparseColMatRef<'_, usize, f64>) -> Result<Vec<f64>> {
        let mut values = vec![0.0; self.nnz()];
        for j in 0..self.n {
            let rows = &self.row_idx[self.col_ptr[j]..self.col_ptr[j + 1]];
            let base = self.col_ptr[j];
            for (i, &v) in a.row_idx_of_col(j).zip(a.val_of_col(j)) {
                if i < j {
                    continue;
                }
                match rows.binary_search(&i) {
                    Ok(p) => values[base + p] += v,
                    Err(_) => return Err(SolverError::PatternMismatch { row: i, col: j }),
                }
            }
        }
        Ok(values)
    }
}
